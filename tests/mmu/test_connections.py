"""One MMU, several TCP clients: each connection has its own request decoder, so no client can corrupt, erase or
complete another's requests — while all of them see the same machine."""

from __future__ import annotations

import asyncio

import pytest

from fabwire.mmu import MMU
from fabwire.mmu.sim import MMUSimulator
from fabwire.transport import open_tcp, serve_tcp

SPEED = 50


@pytest.mark.parametrize("noise", [b"x", b"T", b"\n", b"Q0*e", b"X0*4"])
async def test_another_clients_stray_bytes_never_touch_this_clients_requests(noise: bytes) -> None:
    sim = MMUSimulator(speed=SPEED)
    server = await serve_tcp(sim.serve, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    stray = await open_tcp("127.0.0.1", port)
    stop = asyncio.Event()

    async def pester() -> int:
        sent = 0
        while not stop.is_set():
            await stray.write(noise)  # half requests, lone newlines, a reset without its CRC's last digit
            sent += 1
            await asyncio.sleep(0.005)
        return sent

    pesterer = asyncio.create_task(pester())
    client = await open_tcp("127.0.0.1", port)
    try:
        async with asyncio.timeout(60):
            async with MMU(client, time_scale=SPEED) as mmu:
                for slot in (1, 3):
                    finished = await mmu.tool_change(slot, timeout=30)
                    assert finished.command == f"T{slot}"
                assert mmu.logic.drop_outs == 0
                assert (await mmu.status()).kind != "E"
    finally:
        stop.set()
        sent = await pesterer
        await client.close()
        await stray.close()
        server.close()
    assert sent > 50
    assert sim.model.active_slot == 3


async def test_a_client_connecting_mid_request_does_not_erase_it() -> None:
    sim = MMUSimulator(speed=SPEED)
    sim.model.advance(10.0 * SPEED)  # booted and homed
    server = await serve_tcp(sim.serve, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    first = await open_tcp("127.0.0.1", port)
    try:
        await first.write(b"S0*")
        second = await open_tcp("127.0.0.1", port)  # connects while S0 is half received
        await second.write(b"S1*ad\n")
        async with asyncio.timeout(5):
            assert await second.read(64) == b"S1 A0*34\n"
        await first.write(b"c6\n")
        async with asyncio.timeout(5):
            assert await first.read(64) == b"S0 A3*22\n"  # the first client's request survived
        await second.close()
    finally:
        await first.close()
        server.close()
