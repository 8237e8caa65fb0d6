"""Long runs (only with --soak): many moves, many tool changes on a lossy line, one big upload over a real pty."""

from __future__ import annotations

import asyncio
import contextlib
import zlib

import numpy as np
import pytest

from fabwire.lineus.client import LineUs
from fabwire.lineus.sim import LineUsSim, SimOptions
from fabwire.transport import memory_pair, open_pty
from fabwire.transport.serial import open_serial
from fabwire.xyz.client import XYZPrinter
from fabwire.xyz.protocol import Link
from fabwire.xyz.sim import XYZSimulator

from .fakeclock import run_on_fake_clock
from .noisy_mmu import noisy_tool_changes

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


def test_thousand_mmu_tool_changes_on_a_line_with_one_percent_corrupted_bytes() -> None:
    """1 % of the bytes flipped both ways, MMU timing at 1×, on a fake clock (no real waits): ≥ 99 % of the changes
    complete, and any other ends with the MMU's own error, never with the caller's timeout."""
    report = run_on_fake_clock(noisy_tool_changes(1000, corrupt=0.01, seed=99))
    assert report.corrupted > 10_000 * 0.5  # the line really was noisy (≈9 000 flipped bytes)
    assert report.completed >= 990, report.failures[:5]
    assert all("did not finish" not in failure for failure in report.failures), report.failures[:5]


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
