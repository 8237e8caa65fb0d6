"""TCP links: the client connection and the listener simulators serve on."""

from __future__ import annotations

import asyncio
import contextlib
import errno
import socket
from collections.abc import Awaitable, Callable

from fabwire.errors import FabwireError, InputError, LinkError, LinkTimeout
from fabwire.transport.base import StreamTransport, Transport
from fabwire.transport.limits import ConnectionLimits, ConnectionPool, Farewell, Watched, plain_line

ConnectionHandler = Callable[[Transport], Awaitable[None]]

DEFAULT_CONNECT_TIMEOUT = 5.0


def _nodelay(writer: asyncio.StreamWriter) -> None:
    sock = writer.get_extra_info("socket")
    if sock is not None and sock.family in (socket.AF_INET, socket.AF_INET6):
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)


def host_port(host: str, port: int) -> str:
    """`host:port`, an IPv6 address in brackets (RFC 3986 §3.2.2), as an address is written everywhere."""
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def _describe(writer: asyncio.StreamWriter) -> str:
    peer = writer.get_extra_info("peername")
    if isinstance(peer, tuple) and len(peer) >= 2:
        host = f"[{peer[0]}]" if ":" in str(peer[0]) else peer[0]
        return f"{host}:{peer[1]}"
    return str(peer)


def connect_failure(exc: BaseException, host: str, port: int, timeout: float | None = None, *,
                    peer: str = "the device is powered on and on this network") -> LinkError | LinkTimeout:
    """A failed TCP connection (a TimeoutError or an OSError; anything else in its words) as the error that
    says what to check: the one wording for every TCP peer, devices and MQTT brokers alike (`peer` says what
    to check of it when nothing answers)."""
    where = host_port(host, port)
    if isinstance(exc, TimeoutError):
        within = f" within {timeout:g} s" if timeout is not None else ""
        return LinkTimeout(f"no answer from {where}{within}: check {peer}")
    if isinstance(exc, socket.gaierror):
        return LinkError(f"cannot resolve host {host!r}: {exc.strerror}; check the name or use the IP address")
    if isinstance(exc, ConnectionRefusedError):
        return LinkError(f"connection refused by {where}: the host is up but nothing listens on port {port}; "
                         "check the address and port")
    if isinstance(exc, OSError) and exc.errno in (errno.EHOSTUNREACH, errno.ENETUNREACH):
        return LinkError(f"{where} is unreachable: check the network and the device's IP address")
    return LinkError(f"cannot connect to {where}: {getattr(exc, 'strerror', None) or exc}")


async def open_tcp(host: str, port: int, *, timeout: float = DEFAULT_CONNECT_TIMEOUT) -> StreamTransport:
    """Connect, turning every way a connection fails into a message that says what to check."""
    where = host_port(host, port)
    try:
        async with asyncio.timeout(timeout):
            reader, writer = await asyncio.open_connection(host, port)
    except (TimeoutError, OSError) as exc:
        raise connect_failure(exc, host, port, timeout) from (None if isinstance(exc, TimeoutError) else exc)
    _nodelay(writer)
    return StreamTransport(reader, writer, url=f"tcp://{where}", peer=where)


async def serve_tcp(handler: ConnectionHandler, host: str, port: int, *, limits: ConnectionLimits | None = None,
                    what: str = "simulator", farewell: Farewell = plain_line) -> asyncio.Server:
    """Listen on host:port and run `handler` for each connection, within `limits` (see `transport.limits`);
    a client the limits close is told why in the form `farewell` gives.

    The transport is closed after the handler; a handler's failure ends its connection with one log line.
    """
    pool = ConnectionPool(limits or ConnectionLimits(), what, farewell)

    async def on_connect(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        _nodelay(writer)
        link = Watched(StreamTransport(reader, writer, url=f"tcp://{host}:{port}", peer=_describe(writer)))
        try:
            if not await pool.admit(link):
                return
            task = asyncio.ensure_future(handler(link))
            try:
                await pool.serve(link, task)
            finally:
                task.cancel()
                try:
                    await task
                except (asyncio.CancelledError, LinkError, ConnectionError):
                    pass  # the client went, or the limits closed it (logged there)
                except Exception as exc:
                    pool.log.warning("failed", f"{what}: the connection from {link.peer} failed: {exc!r}")
        except asyncio.CancelledError:
            pass  # the server is shutting down; ending quietly spares asyncio's stream callback a traceback
        finally:
            with contextlib.suppress(asyncio.CancelledError):  # shut down while closing: as quiet (the socket is
                await link.close()  # closed at once; only the wait for the peer's last bytes is cut short)

    try:
        return await asyncio.start_server(on_connect, host, port, reuse_address=True)
    except OSError as exc:
        raise listen_failure(exc, host, port) from exc


BIND_FAILURES: dict[int, tuple[str, type[FabwireError]]] = {
    errno.EADDRINUSE: ("the address is already in use", LinkError),
    errno.EADDRNOTAVAIL: ("no such local address", LinkError),
    errno.EACCES: ("permission denied (ports below 1024 need root)", LinkError),
    errno.EAFNOSUPPORT: ("this computer has no IPv6", LinkError),
    socket.EAI_NONAME: ("no such address or host name", InputError),
}
"""Why a listening socket could not be made, by `errno` (POSIX bind(2), socket(2); getaddrinfo(3) for a name), in
words, and the error it is: a link failure (exit code 8), so a service manager restarts a listener whose port
another program still holds; an address that is no address at all is bad input (exit code 4)."""


def listen_failure(exc: OSError, host: str, port: int) -> FabwireError:
    """One error for every listener (`sim --listen`, `serve --listen`) that cannot bind, in `BIND_FAILURES`' words,
    else in the system's."""
    where = host_port(host, port)
    words, error = BIND_FAILURES.get(exc.errno or 0, (None, LinkError))
    reason = words or (exc.strerror or str(exc)).split(" (while attempting to bind")[0]
    return error(f"cannot listen on {where}: {reason}")
