"""Raw pseudo-terminals: how a simulator looks like a USB serial device to any program."""

from __future__ import annotations

import os
import pty
import tty
from dataclasses import dataclass
from pathlib import Path

from fabwire.errors import LinkError
from fabwire.transport.fd import FdTransport


@dataclass
class PtyDevice:
    """The device end of a pty; clients open `path` (or `link`) as if it were a serial port."""

    transport: FdTransport
    path: str
    link: Path | None

    async def close(self) -> None:
        await self.transport.close()
        if self.link is not None and self.link.is_symlink():
            self.link.unlink()


def _make_link(link: Path, target: str) -> None:
    if link.is_symlink():
        link.unlink()
    elif link.exists():
        raise LinkError(f"cannot create link {link}: a file that is not a symlink is already there")
    try:
        link.symlink_to(target)
    except OSError as exc:
        raise LinkError(f"cannot create link {link} -> {target}: {exc.strerror}") from exc


def open_pty(link: str | os.PathLike[str] | None = None) -> PtyDevice:
    """Open a raw pty (no echo, no CR/LF translation, no flow control: every byte passes as is).

    The device end keeps its own handle on the client side open, so clients may come and go
    without the device seeing a hang-up, as with a real USB serial adapter.
    """
    master, slave = pty.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    link_path = Path(link) if link is not None else None
    if link_path is not None:
        try:
            _make_link(link_path, path)
        except LinkError:
            os.close(master)
            os.close(slave)
            raise
    transport = FdTransport(master, url=f"serial://{path}", peer=f"pty {path}", owned=(master, slave))
    return PtyDevice(transport, path, link_path)
