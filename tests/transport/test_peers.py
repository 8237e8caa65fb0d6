"""A client pointed at another kind of machine or server names what it found, from what that peer said, instead of
waiting out its reply timeout: every row of `FOREIGN`, each client kind, over real TCP through the real CLI."""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator

import pytest
from hypothesis import given
from hypothesis import strategies as st

from clitools import run_cli
from fabwire.transport.peers import FOREIGN, identify

SAID: dict[str, bytes] = {
    "a Line-us drawing robot": b'hello VERSION:"3.2.0 Nov 17 2019 17:54:57" NAME:line-us SERIAL:354003\r\n\0',
    "an SSH server": b"SSH-2.0-OpenSSH_9.2p1 Debian-2+deb12u3\r\n",
    "a web server": b"HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain\r\nContent-Length: 11\r\n\r\nBad Request",
    "an FTP or mail server": b"220 (vsFTPd 3.0.3)\r\n",
    "a Telnet server": b"\xff\xfd\x18\xff\xfd\x20\xff\xfd\x23\xff\xfd\x27",
    "a Marlin or Prusa-firmware 3D printer": b"start\necho:Marlin 2.1.2.1\necho: Last Updated: 2023-05-30\n",
}
"""What each kind of peer says, as captured from one of its kind (a Line-us 3.2.0, OpenSSH, an HTTP server's
answer to a line that is no request, vsftpd, a Telnet server's opening negotiation, a Marlin board's reset)."""

OWN: dict[str, list[bytes]] = {
    "xyz": [b"j:9511,0\n", b"ok\n", b"$\n", b"E4$\n", b"b:20\n", b"t:1,180,200\n"],
    "mmu": [b"S0 A1*3f\n", b"X0 A0*a1\n", b"Q0 E8008*1c\n"],
    "lineus": [SAID["a Line-us drawing robot"], b"ok X:1000 Y:1000 Z:1000\r\n\0"],
}
"""What each machine of ours says itself: never taken for another peer by its own client."""

CLIENTS = {"xyz": ("xyz", "status"), "mmu": ("mmu", "status"), "lineus": ("lineus", "info")}
EXPECTED = {"xyz": "an XYZv3 printer", "mmu": "a Prusa MMU3", "lineus": "a Line-us"}


def test_every_row_has_what_its_peer_says() -> None:
    assert {row.what for row in FOREIGN} == set(SAID)
    for row in FOREIGN:
        assert row.source
        assert identify(SAID[row.what], "mmu") is row


@pytest.mark.parametrize("kind", OWN)
def test_a_machine_of_ours_is_not_taken_for_another(kind: str) -> None:
    for said in OWN[kind]:
        assert identify(said, kind) is None, said


@given(st.binary(max_size=300))
def test_identify_takes_any_bytes(data: bytes) -> None:
    found = identify(data, "xyz")
    assert found is None or found.said.match(data[:256])


@pytest.fixture
def peer(request: pytest.FixtureRequest) -> Iterator[int]:
    """A TCP server that says its words on connect and again after every line it is sent."""
    said: bytes = request.param
    server = socket.create_server(("127.0.0.1", 0))
    stop = threading.Event()

    def serve(conn: socket.socket) -> None:
        with conn:
            try:
                conn.sendall(said)
                while not stop.is_set() and conn.recv(4096):
                    conn.sendall(said)
            except OSError:
                pass

    def accept() -> None:
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except OSError:
                return
            threading.Thread(target=serve, args=(conn,), daemon=True).start()

    threading.Thread(target=accept, daemon=True).start()
    yield server.getsockname()[1]
    stop.set()
    server.close()


CASES = [(kind, row.what) for kind in CLIENTS for row in FOREIGN if row.kind != kind]


@pytest.mark.parametrize(("kind", "what", "peer"), [(k, w, SAID[w]) for k, w in CASES], indirect=["peer"],
                         ids=[f"{k}-{w}" for k, w in CASES])
def test_a_client_names_the_peer_it_reached(kind: str, what: str, peer: int) -> None:
    result = run_cli(*CLIENTS[kind][:1], "-d", f"127.0.0.1:{peer}", *CLIENTS[kind][1:])
    assert result.returncode == 6, result.stderr  # a protocol error, not a link timeout (exit 9)
    line = result.stderr.strip()
    assert line == line.splitlines()[0]
    assert f"127.0.0.1:{peer} is not {EXPECTED[kind]}: it is {what} (it said " in line, line
