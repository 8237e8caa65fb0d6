"""Every transport carries every byte value intact, both ways, and reports the end of the link."""

from __future__ import annotations

import asyncio
import os
import random
from collections.abc import AsyncIterator

import pytest

from fabwire.errors import LinkClosed
from fabwire.transport import Transport, memory_pair, open_pty, open_tcp, serve_tcp
from fabwire.transport.serial import open_serial

PAYLOAD_SIZE = 1 << 20


def payload(seed: int) -> bytes:
    data = bytearray(random.Random(seed).randbytes(PAYLOAD_SIZE))
    data[:256] = bytes(range(256))  # every byte value, including \r \n \0 XON XOFF, right at the start
    return bytes(data)


async def read_exactly(link: Transport, size: int) -> bytes:
    buffer = bytearray()
    while len(buffer) < size:
        buffer += await link.read()
    return bytes(buffer)


async def exchange(a: Transport, b: Transport) -> None:
    """Send 1 MiB each way at once and check both arrive byte for byte."""
    to_b, to_a = payload(1), payload(2)
    async with asyncio.timeout(60):
        results = await asyncio.gather(
            a.write(to_b), b.write(to_a), read_exactly(b, len(to_b)), read_exactly(a, len(to_a))
        )
    assert results[2] == to_b
    assert results[3] == to_a


@pytest.fixture
async def tcp_pair() -> AsyncIterator[tuple[Transport, Transport]]:
    accepted: asyncio.Queue[Transport] = asyncio.Queue()
    done = asyncio.Event()

    async def handler(link: Transport) -> None:
        await accepted.put(link)
        await done.wait()

    server = await serve_tcp(handler, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    client = await open_tcp("127.0.0.1", port)
    device = await accepted.get()
    yield client, device
    await client.close()
    done.set()
    server.close()
    await server.wait_closed()


async def test_tcp_carries_every_byte_both_ways(tcp_pair: tuple[Transport, Transport]) -> None:
    await exchange(*tcp_pair)


async def test_pty_carries_every_byte_both_ways_through_serialx() -> None:
    device = open_pty()
    client = await open_serial(device.path, 115200)
    try:
        await exchange(client, device.transport)
    finally:
        await client.close()
        await device.close()


async def test_memory_pair_carries_every_byte_both_ways() -> None:
    a, b = memory_pair()
    await exchange(a, b)
    await a.close()


async def test_tcp_eof_is_reported_to_the_client() -> None:
    async def handler(link: Transport) -> None:
        await link.write(b"bye")

    server = await serve_tcp(handler, "127.0.0.1", 0)
    client = await open_tcp("127.0.0.1", server.sockets[0].getsockname()[1])
    async with asyncio.timeout(5):
        assert await read_exactly(client, 3) == b"bye"
        with pytest.raises(LinkClosed, match="closed the link"):
            await client.read()
    await client.close()
    server.close()
    await server.wait_closed()


async def test_tcp_client_disconnect_is_reported_to_the_device() -> None:
    seen: asyncio.Future[BaseException] = asyncio.get_running_loop().create_future()

    async def handler(link: Transport) -> None:
        try:
            await link.read()
        except LinkClosed as exc:
            seen.set_result(exc)

    server = await serve_tcp(handler, "127.0.0.1", 0)
    client = await open_tcp("127.0.0.1", server.sockets[0].getsockname()[1])
    await client.close()
    async with asyncio.timeout(5):
        assert isinstance(await seen, LinkClosed)
    server.close()
    await server.wait_closed()


async def test_pty_device_close_is_reported_to_the_serial_client() -> None:
    device = open_pty()
    client = await open_serial(device.path, 115200)
    await device.transport.write(b"last words")
    async with asyncio.timeout(5):
        assert await read_exactly(client, 10) == b"last words"
        await device.close()
        with pytest.raises(LinkClosed):
            await client.read()
    await client.close()


async def test_pty_survives_clients_coming_and_going() -> None:
    """Like a USB serial device: one client closing does not end the device's link."""
    device = open_pty()
    try:
        for word in (b"first", b"second"):
            client = await open_serial(device.path, 115200)
            await client.write(word)
            async with asyncio.timeout(5):
                assert await read_exactly(device.transport, len(word)) == word
            await client.close()
        assert not device.transport.closed
    finally:
        await device.close()


async def test_pty_link_symlink_is_made_and_removed(tmp_path: pytest.TempPathFactory) -> None:
    link = tmp_path / "printer"  # type: ignore[operator]
    device = open_pty(link)
    assert os.readlink(link) == device.path
    await device.close()
    assert not link.exists()


async def test_read_after_local_close_raises_instead_of_hanging() -> None:
    a, b = memory_pair()
    await a.close()
    with pytest.raises(LinkClosed):
        await a.read()
    with pytest.raises(LinkClosed):
        await b.read()
    with pytest.raises(LinkClosed):
        await b.write(b"x")


def open_fds() -> set[str]:
    return set(os.listdir("/proc/self/fd"))


async def test_no_descriptor_or_task_leaks_after_close() -> None:
    before_fds = open_fds()
    before_tasks = asyncio.all_tasks()
    for _ in range(5):
        async def handler(link: Transport) -> None:
            await link.write(await link.read())

        server = await serve_tcp(handler, "127.0.0.1", 0)
        client = await open_tcp("127.0.0.1", server.sockets[0].getsockname()[1])
        await client.write(b"ping")
        async with asyncio.timeout(5):
            assert await client.read() == b"ping"
        await client.close()
        server.close()
        await server.wait_closed()

        device = open_pty()
        serial = await open_serial(device.path, 115200)
        await serial.write(b"x")
        async with asyncio.timeout(5):
            assert await device.transport.read() == b"x"
        await serial.close()
        await device.close()
    await asyncio.sleep(0.05)  # let connection handler tasks finish their close
    assert open_fds() == before_fds
    assert asyncio.all_tasks() == before_tasks
