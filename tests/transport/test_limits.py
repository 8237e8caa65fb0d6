"""Simulator listeners stay open to new clients: a connection limit that makes room, and an idle timeout."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator

import pytest

from fabwire.errors import LinkClosed, LinkError
from fabwire.transport import Transport, open_tcp, serve_tcp
from fabwire.transport.limits import ConnectionLimits, RateLimitedLog, refusal

LIMIT = 10


async def echo(link: Transport) -> None:
    while True:
        await link.write(await link.read())


@contextlib.asynccontextmanager
async def listening(limits: ConnectionLimits, handler: object = echo) -> AsyncIterator[int]:
    server = await serve_tcp(handler, "127.0.0.1", 0, limits=limits)  # type: ignore[arg-type]
    try:
        yield int(server.sockets[0].getsockname()[1])
    finally:
        server.close()


async def ask(link: Transport, data: bytes = b"ping") -> bytes:
    await link.write(data)
    return await link.read()


async def closed_by_peer(link: Transport) -> bytes:
    """Everything the peer sends until it closes the link."""
    got = b""
    with contextlib.suppress(LinkClosed):
        while True:
            got += await link.read()
    return got


async def test_at_the_limit_the_quietest_connection_makes_room() -> None:
    async with asyncio.timeout(LIMIT), listening(ConnectionLimits(max_connections=2, busy_for=0)) as port:
        quiet = await open_tcp("127.0.0.1", port)
        talking = await open_tcp("127.0.0.1", port)
        assert await ask(talking) == b"ping"
        newcomer = await open_tcp("127.0.0.1", port)
        assert await ask(newcomer) == b"ping"
        farewell = await closed_by_peer(quiet)
        assert farewell == b"simulator replaced this quiet connection: all 2 connections were in use\r\n"
        assert await ask(talking, b"still here") == b"still here"
        for link in (quiet, talking, newcomer):
            await link.close()
    reason = refusal(farewell, "127.0.0.1:1337")
    assert isinstance(reason, LinkClosed)
    assert str(reason) == ("127.0.0.1:1337: the simulator closed this connection, quiet the longest of its 2, to "
                           "serve a new client (its --max-connections); connect again to go on")


async def test_each_protocol_words_the_farewell_in_its_own_form() -> None:
    def framed(text: str) -> bytes:
        return b"<" + text.encode() + b">"

    async with asyncio.timeout(LIMIT):
        server = await serve_tcp(echo, "127.0.0.1", 0, limits=ConnectionLimits(max_connections=1, busy_for=3600),
                                 farewell=framed)
        port = int(server.sockets[0].getsockname()[1])
        try:
            first = await open_tcp("127.0.0.1", port)
            assert await ask(first) == b"ping"
            refused = await open_tcp("127.0.0.1", port)
            assert await closed_by_peer(refused) == (
                b"<simulator busy: all 1 connections are in use, try again later>")
            await first.close()
            await refused.close()
        finally:
            server.close()


def test_a_farewell_is_recognised_whatever_surrounds_it() -> None:
    busy = refusal(b'error INFO:"xyz simulator busy: all 3 connections are in use, try again later"\r\n\0', "p")
    assert type(busy) is LinkError
    assert "turned the connection away: all 3 of its connections" in str(busy)
    assert refusal(b"ok X:1000 Y:1000 Z:1000\r\n\0", "p") is None
    assert refusal(b"simulator busy: all many connections", "p") is None


async def test_when_every_connection_is_busy_a_newcomer_is_told_why() -> None:
    async with asyncio.timeout(LIMIT), listening(ConnectionLimits(max_connections=1, busy_for=3600)) as port:
        first = await open_tcp("127.0.0.1", port)
        assert await ask(first) == b"ping"
        refused = await open_tcp("127.0.0.1", port)
        assert b"busy: all 1 connections are in use" in await closed_by_peer(refused)
        assert await ask(first, b"served") == b"served"
        await first.close()


async def test_an_idle_connection_is_closed_and_an_active_one_is_not() -> None:
    async with asyncio.timeout(LIMIT), listening(ConnectionLimits(idle_timeout=1.0)) as port:
        idle = await open_tcp("127.0.0.1", port)
        active = await open_tcp("127.0.0.1", port)
        waiting = asyncio.ensure_future(closed_by_peer(idle))
        while not waiting.done():
            assert await ask(active) == b"ping"
            await asyncio.sleep(0.05)
        assert waiting.result() == b""
        assert await ask(active, b"alive") == b"alive"
        await active.close()
        await idle.close()


async def test_a_failing_handler_is_one_log_line(caplog: pytest.LogCaptureFixture) -> None:
    async def broken(link: Transport) -> None:
        await link.read()
        raise RecursionError("maximum recursion depth exceeded")

    with caplog.at_level(logging.WARNING, logger="fabwire.sim"):
        async with asyncio.timeout(LIMIT), listening(ConnectionLimits(), broken) as port:
            for _ in range(3):
                link = await open_tcp("127.0.0.1", port)
                await link.write(b"[[[[")
                assert await closed_by_peer(link) == b""
                await link.close()
    lines = [r.getMessage() for r in caplog.records]
    assert lines
    assert all("failed: RecursionError" in line and "\n" not in line for line in lines)
    assert len(lines) <= 3


def test_log_lines_are_rate_limited_per_kind(caplog: pytest.LogCaptureFixture) -> None:
    limited = RateLimitedLog(interval=3600)
    with caplog.at_level(logging.WARNING, logger="fabwire.sim"):
        for n in range(5):
            limited.warning("refused", f"refused client {n}")
        limited.warning("idle", "closed an idle client")
    assert [r.getMessage() for r in caplog.records] == ["refused client 0", "closed an idle client"]
