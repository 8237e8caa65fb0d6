"""An in-memory connected pair, for tests and in-process simulators."""

from __future__ import annotations

import asyncio

from fabwire.errors import LinkClosed
from fabwire.transport.base import DEFAULT_READ_SIZE, Transport


class _Pipe:
    """One direction of the pair."""

    def __init__(self) -> None:
        self.buffer = bytearray()
        self.eof = False
        self.ready = asyncio.Event()


class MemoryTransport(Transport):
    def __init__(self, inbound: _Pipe, outbound: _Pipe, *, url: str, peer: str) -> None:
        self._in = inbound
        self._out = outbound
        self._closed = False
        self.url = url
        self.peer = peer

    @property
    def closed(self) -> bool:
        return self._closed

    async def read(self, max_bytes: int = DEFAULT_READ_SIZE) -> bytes:
        while True:
            if self._closed:
                raise LinkClosed(f"link to {self.peer} is closed")
            if self._in.buffer:
                data = bytes(self._in.buffer[:max_bytes])
                del self._in.buffer[:max_bytes]
                if not self._in.buffer and not self._in.eof:
                    self._in.ready.clear()
                return data
            if self._in.eof:
                raise LinkClosed(f"{self.peer} closed the link")
            self._in.ready.clear()
            await self._in.ready.wait()

    async def write(self, data: bytes) -> None:
        if self._closed:
            raise LinkClosed(f"link to {self.peer} is closed")
        if self._out.eof:
            raise LinkClosed(f"{self.peer} closed the link")
        self._out.buffer += data
        self._out.ready.set()
        await asyncio.sleep(0)  # let the reader run, as a socket would

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for pipe in (self._in, self._out):
            pipe.eof = True
            pipe.ready.set()


def memory_pair(name: str = "memory") -> tuple[MemoryTransport, MemoryTransport]:
    """Two connected transports: what one writes, the other reads. Closing either ends both."""
    a_to_b, b_to_a = _Pipe(), _Pipe()
    host = MemoryTransport(b_to_a, a_to_b, url=f"memory://{name}", peer=f"{name} (device end)")
    device = MemoryTransport(a_to_b, b_to_a, url=f"memory://{name}", peer=f"{name} (host end)")
    return host, device
