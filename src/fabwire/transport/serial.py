"""Serial links (USB CDC-ACM printers, the MMU's UART, a simulator's pty) through serialx."""

from __future__ import annotations

import errno

import serialx

from fabwire.errors import LinkClosed, LinkError
from fabwire.transport.base import DEFAULT_READ_SIZE, StreamTransport


class SerialTransport(StreamTransport):
    """A serial stream whose driver errors (serialx raises its own SerialException, not an OSError) end the link
    like any other loss: LinkClosed with the reason."""

    async def read(self, max_bytes: int = DEFAULT_READ_SIZE) -> bytes:
        try:
            return await super().read(max_bytes)
        except serialx.SerialException as exc:
            raise LinkClosed(f"link to {self.peer} lost: {exc}") from exc

    async def write(self, data: bytes) -> None:
        try:
            await super().write(data)
        except serialx.SerialException as exc:
            raise LinkClosed(f"link to {self.peer} lost while writing: {exc}") from exc


def _explain(path: str, exc: OSError) -> str:
    if exc.errno == errno.ENOENT:
        return f"serial port {path} does not exist: check the cable and the device path (ls /dev/tty*)"
    if exc.errno == errno.EACCES:
        return (
            f"permission denied opening {path}: add yourself to the port's group "
            "(often 'dialout': sudo usermod -aG dialout $USER, then log in again)"
        )
    if exc.errno == errno.EBUSY:
        return f"serial port {path} is busy: another program has it open"
    if exc.errno == errno.ENOTTY:
        return f"{path} is not a serial port"
    return f"cannot open serial port {path}: {exc.strerror or exc}"


async def open_serial(path: str, baudrate: int) -> SerialTransport:
    """Open `path` at `baudrate`, 8N1, no flow control, raw."""
    try:
        reader, writer = await serialx.open_serial_connection(path, baudrate=baudrate)
    except OSError as exc:
        raise LinkError(_explain(path, exc)) from exc
    except serialx.SerialException as exc:
        raise LinkError(f"cannot open serial port {path}: {exc}") from exc
    return SerialTransport(reader, writer, url=f"serial://{path}", peer=path)
