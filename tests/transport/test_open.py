"""Opening links fails with messages that say what to check."""

from __future__ import annotations

import asyncio
import socket
from pathlib import Path

import pytest

from fabwire.devices import MMU, XYZ
from fabwire.errors import InputError, LinkError, LinkTimeout
from fabwire.transport import open_transport


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


async def test_refused_connection_names_host_and_port() -> None:
    port = free_port()
    with pytest.raises(LinkError, match=f"connection refused by 127.0.0.1:{port}"):
        await open_transport(f"127.0.0.1:{port}", XYZ)


async def test_missing_serial_port_says_so() -> None:
    with pytest.raises(LinkError, match="does not exist: check the cable"):
        await open_transport("/dev/ttyNO-SUCH-PORT", MMU)


async def test_a_file_that_is_not_a_tty_is_not_a_serial_port(tmp_path: Path) -> None:
    path = tmp_path / "plain-file"
    path.write_bytes(b"x")
    with pytest.raises(LinkError, match="plain-file is not a serial port"):
        await open_transport(str(path), MMU)


async def test_a_host_that_never_accepts_times_out() -> None:
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(0)
    port = listener.getsockname()[1]
    fillers = []
    try:
        for _ in range(4):  # fill the accept queue so further SYNs go unanswered
            filler = socket.socket()
            filler.setblocking(False)
            filler.connect_ex(("127.0.0.1", port))
            fillers.append(filler)
        await asyncio.sleep(0.05)
        with pytest.raises(LinkTimeout, match="no answer from"):
            await open_transport(f"127.0.0.1:{port}", XYZ, connect_timeout=0.3)
    finally:
        for filler in fillers:
            filler.close()
        listener.close()


async def test_unknown_simulator_lists_the_known_ones() -> None:
    with pytest.raises(InputError, match="no simulator called 'toaster'"):
        await open_transport("sim://toaster", XYZ)
