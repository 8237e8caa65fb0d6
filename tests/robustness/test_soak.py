"""Long runs (only with --soak): many moves, many tool changes on a lossy line, one big upload over a real pty."""

from __future__ import annotations

import asyncio
import contextlib
import zlib

import numpy as np
import pytest

from fabwire.errors import FabwireError
from fabwire.lineus.client import LineUs
from fabwire.lineus.sim import LineUsSim, SimOptions
from fabwire.mmu import MMU
from fabwire.mmu.codes import FilamentState
from fabwire.mmu.sim import MMUSimulator
from fabwire.transport import FaultPlan, FaultyTransport, memory_pair, open_pty
from fabwire.transport.serial import open_serial
from fabwire.xyz.client import XYZPrinter
from fabwire.xyz.protocol import Link
from fabwire.xyz.sim import XYZSimulator

pytestmark = [pytest.mark.soak, pytest.mark.timeout(1800)]


async def test_ten_thousand_lineus_moves_land_where_sent() -> None:
    sim = LineUsSim(SimOptions(speed=float("inf")))
    host, device = memory_pair("soak-lineus")
    task = asyncio.create_task(sim.serve(device))
    rng = np.random.default_rng(7)
    targets = [(float(x), float(y)) for x, y in zip(rng.integers(900, 1600, 10_000), rng.integers(-300, 600, 10_000),
                                                    strict=True)]
    try:
        async with asyncio.timeout(600):
            arm = await LineUs.connect(host, hello_timeout=5)
            for x, y in targets:
                position = await arm.move(x, y)
                assert (position.x, position.y) == (x, y)
            await arm.close()
        assert [m.end[:2] for m in sim.arm.moves if m.command.startswith("G01")][-10_000:] == targets
    finally:
        await host.close()
        task.cancel()
        with contextlib.suppress(BaseException):
            await task


async def test_thousand_mmu_tool_changes_on_a_line_with_one_percent_corrupted_bytes() -> None:
    sim = MMUSimulator(speed=100)
    changes = 1000
    failures: list[str] = []
    async with asyncio.timeout(1500):
        host, device = memory_pair("soak-mmu")
        task = asyncio.create_task(sim.serve(device))
        faulty = FaultyTransport(host, FaultPlan(corrupt=0.01, seed=99))
        try:
            async with MMU(faulty, time_scale=100, connect_timeout=30) as mmu:
                for n in range(changes):
                    slot = n % 5
                    try:
                        await mmu.tool_change(slot, timeout=60)
                    except FabwireError as exc:
                        failures.append(f"{type(exc).__name__}: {exc}")
                        continue
                    sim.model.advance(sim.now())
                    assert sim.model.active_slot == slot
                    assert sim.model.filament == FilamentState.IN_NOZZLE
        finally:
            await host.close()
            task.cancel()
            with contextlib.suppress(BaseException):
                await task
    assert faulty.corrupted > 0
    assert len(failures) < changes // 10, failures[:5]


async def test_fifty_megabyte_upload_over_a_real_pty_arrives_identical() -> None:
    sim = XYZSimulator(speed=1000, gap=0.01, strict=True)
    device = open_pty()
    task = asyncio.create_task(sim.serve(device.transport))
    data = np.random.default_rng(5).integers(0, 256, 50 * 1024 * 1024, dtype=np.uint8).tobytes()
    printer = XYZPrinter(await open_serial(device.path, 115200), link=Link.SERIAL, timeout=10)
    try:
        async with asyncio.timeout(1500):
            result = await printer.upload(data, "soak.3w")
        assert result.size == len(data)
        stored = sim.received("soak.3w")
        assert stored is not None
        assert zlib.crc32(stored) == zlib.crc32(data)
        assert stored == data
    finally:
        await printer.close()
        task.cancel()
        with contextlib.suppress(BaseException):
            await task
        await device.close()
