"""Bounds for a simulator serving many clients: a connection limit and an idle timeout.

At the limit, a new client takes the place of the connection that has been quiet longest (an abandoned socket must
not lock everyone out); when every connection is busy, the newcomer is closed instead. Either client closed is
first told why, in its protocol's own form (a `Farewell`): a Line-us error reply, a plain text line for the XYZv3
and MMU protocols, which have no message a client would show. A connection that sends and receives nothing for
`idle_timeout` seconds is closed. Each such event is one log line, rate-limited.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
import time
from collections.abc import Callable

import msgspec

from fabwire.errors import LinkClosed, LinkError
from fabwire.simoptions import DEFAULT_IDLE_TIMEOUT, DEFAULT_MAX_CONNECTIONS
from fabwire.transport.base import DEFAULT_READ_SIZE, Transport

log = logging.getLogger("fabwire.sim")

BUSY_FOR = 1.0
"""A connection with traffic in the last second is busy: it is never closed to make room."""


class ConnectionLimits(msgspec.Struct, frozen=True):
    max_connections: int = DEFAULT_MAX_CONNECTIONS
    idle_timeout: float | None = DEFAULT_IDLE_TIMEOUT
    """Seconds without traffic before a connection is closed; None keeps quiet connections open."""
    busy_for: float = BUSY_FOR


FAREWELL_TIMEOUT = 1.0
"""Seconds a farewell may take to write: a client that reads nothing must not hold the server up."""

Farewell = Callable[[str], bytes]
"""How a protocol words the last thing a server says before it closes a connection, from the reason's text."""


def plain_line(text: str) -> bytes:
    """The farewell of protocols with no error message a client would show: the reason as a text line."""
    return text.encode("ascii", "replace") + b"\r\n"


def _busy(what: str, count: int) -> str:
    return f"{what} busy: all {count} connections are in use, try again later"


def _replaced(what: str, count: int) -> str:
    return f"{what} replaced this quiet connection: all {count} connections were in use"


_GOODBYE = re.compile(rb"((?:[a-z]+ )?simulator) (busy|replaced this quiet connection): all ([0-9]{1,6}) connections")


def refusal(data: bytes | bytearray, peer: str) -> LinkError | None:
    """The error to raise when `data` (what a peer sent) holds a simulator's farewell, written by
    `ConnectionPool.admit` below, or None: a client shows it instead of calling the peer the wrong device or the
    link broken. LinkError for a newcomer turned away, LinkClosed for a quiet connection closed to make room."""
    found = _GOODBYE.search(data[:512])
    if found is None:
        return None
    what, count = found[1].decode(), found[3].decode()
    if found[2] == b"busy":
        return LinkError(f"{peer}: the {what} turned the connection away: all {count} of its connections are in "
                         "use (its --max-connections); try again later")
    return LinkClosed(f"{peer}: the {what} closed this connection, quiet the longest of its {count}, to serve a "
                      "new client (its --max-connections); connect again to go on")


class RateLimitedLog:
    """At most one line per `interval` seconds per message kind; the lines held back are counted in the next."""

    def __init__(self, interval: float = 1.0) -> None:
        self._interval = interval
        self._last: dict[str, float] = {}
        self._held: dict[str, int] = {}

    def warning(self, kind: str, message: str) -> None:
        now = time.monotonic()
        if now - self._last.get(kind, -self._interval) < self._interval:
            self._held[kind] = self._held.get(kind, 0) + 1
            return
        self._last[kind] = now
        held = self._held.pop(kind, 0)
        log.warning("%s%s", message, f" ({held} more like this)" if held else "")


class Watched(Transport):
    """A served connection that notes when it last moved bytes, so it can be judged idle."""

    def __init__(self, inner: Transport) -> None:
        self.inner = inner
        self.url = inner.url
        self.peer = inner.peer
        self.last_active = time.monotonic()

    @property
    def closed(self) -> bool:
        return self.inner.closed

    async def read(self, max_bytes: int = DEFAULT_READ_SIZE) -> bytes:
        data = await self.inner.read(max_bytes)
        self.last_active = time.monotonic()
        return data

    async def write(self, data: bytes) -> None:
        await self.inner.write(data)
        self.last_active = time.monotonic()

    async def close(self) -> None:
        await self.inner.close()


class ConnectionPool:
    """The connections one listener serves, with the limits applied."""

    def __init__(self, limits: ConnectionLimits, what: str = "simulator", farewell: Farewell = plain_line) -> None:
        self.limits = limits
        self.what = what
        self.farewell = farewell
        self.open: set[Watched] = set()
        self.log = RateLimitedLog()

    async def admit(self, link: Watched) -> bool:
        """Make room for `link` or refuse it, telling the client closed why; True when `link` may be served."""
        count = self.limits.max_connections
        if len(self.open) >= count:
            quiet = min(self.open, key=lambda c: c.last_active)
            if time.monotonic() - quiet.last_active < self.limits.busy_for:
                self.log.warning("refused", f"{self.what}: refused {link.peer}: all {count} connections are busy "
                                 "(--max-connections)")
                await self._say(link, _busy(self.what, count))
                return False
            self.log.warning("evicted", f"{self.what}: closed the quietest connection ({quiet.peer}) to serve "
                             f"{link.peer}: {count} connections open (--max-connections)")
            self.open.discard(quiet)
            await self._say(quiet, _replaced(self.what, count))
            await quiet.close()
        self.open.add(link)
        return True

    async def _say(self, link: Watched, reason: str) -> None:
        """Write the farewell in one piece (a client reading one chunk gets all of it); a peer that does not read
        or is gone is not waited for."""
        with contextlib.suppress(Exception):
            async with asyncio.timeout(FAREWELL_TIMEOUT):
                await link.inner.write(self.farewell(reason))

    async def serve(self, link: Watched, handler: asyncio.Future[None]) -> None:
        """Wait for the handler, closing the link if it stays idle too long."""
        timeout = self.limits.idle_timeout
        try:
            while not handler.done():
                wait = None if timeout is None else max(0.05, link.last_active + timeout - time.monotonic())
                done, _ = await asyncio.wait({handler}, timeout=wait)
                if not done and timeout is not None and time.monotonic() - link.last_active >= timeout:
                    self.log.warning("idle", f"{self.what}: closed {link.peer} after {timeout:g} s without traffic "
                                     "(--idle-timeout)")
                    await link.close()
                    await asyncio.wait({handler}, timeout=5)
                    break
        finally:
            self.open.discard(link)
