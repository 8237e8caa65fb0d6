"""Serving a device on a real loopback TCP port and connecting to it, for client ↔ simulator tests."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator

from fabwire.transport import Transport, open_tcp, serve_tcp
from fabwire.transport.registry import DeviceServer


@contextlib.asynccontextmanager
async def loopback_tcp(serve: DeviceServer) -> AsyncIterator[Transport]:
    """Yield a client link to `serve` on 127.0.0.1 (a free port); close both ends afterwards."""
    server = await serve_tcp(serve, "127.0.0.1", 0)
    client = await open_tcp("127.0.0.1", server.sockets[0].getsockname()[1])
    try:
        yield client
    finally:
        await client.close()
        server.close()
        with contextlib.suppress(BaseException):
            async with asyncio.timeout(2):
                await server.wait_closed()
