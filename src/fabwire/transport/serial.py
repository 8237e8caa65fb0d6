"""Serial links (USB CDC-ACM printers, the MMU's UART, a simulator's pty) through serialx."""

from __future__ import annotations

import errno

import serialx

from fabwire.errors import LinkError
from fabwire.transport.base import StreamTransport


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


async def open_serial(path: str, baudrate: int) -> StreamTransport:
    """Open `path` at `baudrate`, 8N1, no flow control, raw."""
    try:
        reader, writer = await serialx.open_serial_connection(path, baudrate=baudrate)
    except OSError as exc:
        raise LinkError(_explain(path, exc)) from exc
    except serialx.SerialException as exc:
        raise LinkError(f"cannot open serial port {path}: {exc}") from exc
    return StreamTransport(reader, writer, url=f"serial://{path}", peer=path)
