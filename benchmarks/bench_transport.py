"""Raw link throughput of each transport: the ceiling every device protocol runs under."""

from __future__ import annotations

import asyncio
import time

from common import Figure
from fabwire.transport import Transport, memory_pair, open_pty, open_tcp, serve_tcp
from fabwire.transport.serial import open_serial

SIZE = 32 << 20


async def pump(sender: Transport, receiver: Transport, size: int) -> float:
    block = bytes(range(256)) * 256

    async def send() -> None:
        for _ in range(size // len(block)):
            await sender.write(block)

    async def receive() -> None:
        got = 0
        while got < size:
            got += len(await receiver.read())

    start = time.perf_counter()
    await asyncio.gather(send(), receive())
    return size / (time.perf_counter() - start) / 1e6


async def measure() -> list[Figure]:
    figures = []
    a, b = memory_pair()
    figures.append(Figure("memory pair throughput", await pump(a, b, SIZE), "MB/s"))
    await a.close()

    accepted: asyncio.Queue[Transport] = asyncio.Queue()
    done = asyncio.Event()

    async def handler(link: Transport) -> None:
        await accepted.put(link)
        await done.wait()

    server = await serve_tcp(handler, "127.0.0.1", 0)
    client = await open_tcp("127.0.0.1", server.sockets[0].getsockname()[1])
    device = await accepted.get()
    figures.append(Figure("TCP loopback throughput", await pump(client, device, SIZE), "MB/s"))
    await client.close()
    done.set()
    server.close()

    pty = open_pty()
    serial = await open_serial(pty.path, 115200)
    figures.append(Figure("pty (serialx client) throughput", await pump(serial, pty.transport, SIZE // 8), "MB/s"))
    await serial.close()
    await pty.close()
    return figures


def run() -> list[Figure]:
    return asyncio.run(measure())
