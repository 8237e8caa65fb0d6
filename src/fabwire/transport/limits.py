"""Bounds for a simulator serving many clients: a connection limit and an idle timeout.

At the limit, a new client takes the place of the connection that has been quiet longest (an abandoned socket must
not lock everyone out); when every connection is busy, the newcomer is told why and closed. A connection that sends
and receives nothing for `idle_timeout` seconds is closed. Each such event is one log line, rate-limited.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
import time

import msgspec

from fabwire.errors import LinkError
from fabwire.transport.base import DEFAULT_READ_SIZE, Transport

log = logging.getLogger("fabwire.sim")

DEFAULT_MAX_CONNECTIONS = 32
DEFAULT_IDLE_TIMEOUT = 600.0
BUSY_FOR = 1.0
"""A connection with traffic in the last second is busy: it is never closed to make room."""


class ConnectionLimits(msgspec.Struct, frozen=True):
    max_connections: int = DEFAULT_MAX_CONNECTIONS
    idle_timeout: float | None = DEFAULT_IDLE_TIMEOUT
    """Seconds without traffic before a connection is closed; None keeps quiet connections open."""
    busy_for: float = BUSY_FOR


_REFUSAL = re.compile(rb"([a-z]+ simulator) busy: all ([0-9]{1,6}) connections are in use")


def refusal(data: bytes, peer: str) -> LinkError | None:
    """The error to raise when `data` (what a peer sent first) is a simulator's refusal line, written by
    `ConnectionPool.admit` below, or None. A client shows it instead of calling the peer the wrong device."""
    found = _REFUSAL.search(data[:256])
    if found is None:
        return None
    what, count = found[1].decode(), found[2].decode()
    return LinkError(f"{peer}: the {what} turned the connection away: all {count} of its connections are in use "
                     "(its --max-connections); try again later")


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

    def __init__(self, limits: ConnectionLimits, what: str = "simulator") -> None:
        self.limits = limits
        self.what = what
        self.open: set[Watched] = set()
        self.log = RateLimitedLog()

    async def admit(self, link: Watched) -> bool:
        """Make room for `link` or refuse it (telling the client why); True when it may be served."""
        if len(self.open) >= self.limits.max_connections:
            quiet = min(self.open, key=lambda c: c.last_active)
            if time.monotonic() - quiet.last_active < self.limits.busy_for:
                self.log.warning("refused", f"{self.what}: refused {link.peer}: all "
                                 f"{self.limits.max_connections} connections are busy (--max-connections)")
                with contextlib.suppress(Exception):
                    await link.write(f"{self.what} busy: all {self.limits.max_connections} connections are in use, "
                                     "try again later\r\n".encode())
                return False
            self.log.warning("evicted", f"{self.what}: closed the quietest connection ({quiet.peer}) to serve "
                             f"{link.peer}: {self.limits.max_connections} connections open (--max-connections)")
            self.open.discard(quiet)
            await quiet.close()
        self.open.add(link)
        return True

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
