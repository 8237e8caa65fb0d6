"""Line-us fixtures: a simulator on a real loopback TCP port, and a raw-socket peer for byte-level checks."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import Any

import pytest

from fabwire.lineus.sim import LineUsSim, SimOptions, farewell
from fabwire.transport import serve_tcp

TERM = b"\r\n\x00"


@dataclass
class RunningSim:
    sim: LineUsSim
    port: int

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.port}"


class Raw:
    """A raw TCP peer: exact bytes out, replies read up to `\\r\\n\\0`."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer

    async def send(self, data: bytes) -> None:
        self.writer.write(data)
        await self.writer.drain()

    async def reply(self, timeout: float = 5.0) -> bytes:
        async with asyncio.timeout(timeout):
            return await self.reader.readuntil(TERM)

    async def reply_line(self, timeout: float = 5.0) -> bytes:
        """Up to the first `\\r\\n`: a greeting, or a refusal."""
        async with asyncio.timeout(timeout):
            return await self.reader.readuntil(b"\r\n")

    async def ask(self, data: bytes, timeout: float = 5.0) -> bytes:
        await self.send(data)
        return await self.reply(timeout)

    async def nothing_more(self, wait: float = 0.2) -> bytes:
        """Whatever arrives within `wait` seconds (b'' when the device stays quiet)."""
        try:
            async with asyncio.timeout(wait):
                return await self.reader.read(100)
        except TimeoutError:
            return b""

    async def close(self) -> None:
        self.writer.close()
        with contextlib.suppress(OSError):
            await self.writer.wait_closed()


SimStarter = Callable[..., Any]


@pytest.fixture
async def lineus_sim() -> AsyncIterator[SimStarter]:
    """`running = await lineus_sim(speed=..., version=...)` → a simulator on a free loopback port."""
    servers: list[asyncio.Server] = []
    sims: list[LineUsSim] = []

    async def start(files: dict[int, str] | None = None, **options: Any) -> RunningSim:
        options.setdefault("speed", float("inf"))
        sim = LineUsSim(SimOptions(**options), files=files)
        server = await serve_tcp(sim.serve, "127.0.0.1", 0, farewell=farewell)
        servers.append(server)
        sims.append(sim)
        return RunningSim(sim, server.sockets[0].getsockname()[1])

    yield start
    for server in servers:
        server.close()
    for sim in sims:
        await sim.close()


@pytest.fixture
async def raw_peer() -> AsyncIterator[Callable[..., Any]]:
    """`peer = await raw_peer(port, read_hello=True)`."""
    peers: list[Raw] = []

    async def connect(port: int, read_hello: bool = True) -> Raw:
        async with asyncio.timeout(5):
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
        peer = Raw(reader, writer)
        peers.append(peer)
        if read_hello:
            await peer.reply()
        return peer

    yield connect
    for peer in peers:
        await peer.close()
