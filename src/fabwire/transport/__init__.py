"""Links to devices: one small interface over TCP, serial, pty, memory and in-process simulators.

Each name is imported from its submodule when first used: a command that only parses an address or reads a trace
does not load the event loop, a TCP status query does not pay for serial ports (serialx) or ptys (termios, POSIX
only), and `import fabwire.transport` works where `termios` does not exist (Windows).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from fabwire.devices import DeviceKind
    from fabwire.transport.base import StreamTransport, Transport
    from fabwire.transport.faults import FaultPlan, FaultyTransport
    from fabwire.transport.memory import memory_pair
    from fabwire.transport.pty import PtyDevice, open_pty
    from fabwire.transport.registry import register_simulator, spawn_in_process
    from fabwire.transport.serial import open_serial
    from fabwire.transport.tap import TapTransport
    from fabwire.transport.tcp import open_tcp, serve_tcp
    from fabwire.transport.urls import Endpoint, parse_url

__all__ = [
    "Endpoint",
    "FaultPlan",
    "FaultyTransport",
    "PtyDevice",
    "StreamTransport",
    "TapTransport",
    "Transport",
    "memory_pair",
    "open_pty",
    "open_serial",
    "open_tcp",
    "open_transport",
    "parse_url",
    "register_simulator",
    "serve_tcp",
    "spawn_in_process",
]

_LAZY = {
    "Endpoint": "fabwire.transport.urls",
    "FaultPlan": "fabwire.transport.faults",
    "FaultyTransport": "fabwire.transport.faults",
    "PtyDevice": "fabwire.transport.pty",
    "StreamTransport": "fabwire.transport.base",
    "TapTransport": "fabwire.transport.tap",
    "Transport": "fabwire.transport.base",
    "memory_pair": "fabwire.transport.memory",
    "open_pty": "fabwire.transport.pty",
    "open_serial": "fabwire.transport.serial",
    "open_tcp": "fabwire.transport.tcp",
    "parse_url": "fabwire.transport.urls",
    "register_simulator": "fabwire.transport.registry",
    "serve_tcp": "fabwire.transport.tcp",
    "spawn_in_process": "fabwire.transport.registry",
}
"""Where each name above lives: a submodule is imported when one of its names is first used."""


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value  # looked up once
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


async def open_transport(
    address: str | Endpoint, kind: DeviceKind | None = None, *, connect_timeout: float = 5.0
) -> Transport:
    """Open the link an address names; `kind` supplies default port and baud rate."""
    from fabwire.errors import InputError
    from fabwire.transport.tcp import open_tcp
    from fabwire.transport.urls import Endpoint, parse_url

    endpoint = address if isinstance(address, Endpoint) else parse_url(address, kind)
    if endpoint.scheme == "tcp":
        return await open_tcp(endpoint.host, endpoint.port, timeout=connect_timeout)
    if endpoint.scheme == "serial":
        from fabwire.transport.serial import open_serial

        return await open_serial(endpoint.path, kind.baudrate if kind else 115200)
    if endpoint.scheme == "sim":
        from fabwire.transport.registry import open_simulator

        return await open_simulator(endpoint.host, endpoint.options)
    raise InputError(f"cannot open {endpoint.url}")
