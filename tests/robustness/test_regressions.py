"""Giving up on one MMU command (its own timeout) leaves the client usable for the next."""

from __future__ import annotations

import asyncio
import contextlib

from fabwire.errors import DeviceError, LinkTimeout
from fabwire.mmu import MMU
from fabwire.mmu.codes import FilamentState
from fabwire.mmu.sim import MMUSimulator
from fabwire.transport import memory_pair

from .fakeclock import run_on_fake_clock


def test_mmu_command_given_up_by_its_timeout_does_not_block_the_next_one() -> None:
    """On a fake clock: the outcome (T1 given up, T2 accepted once the MMU is free) cannot depend on load."""
    run_on_fake_clock(given_up_then_next())


async def given_up_then_next() -> None:
    clock = asyncio.get_running_loop().time
    sim = MMUSimulator(speed=100, clock=clock)
    host, device = memory_pair("mmu-timeout")
    task = asyncio.create_task(sim.serve(device))
    try:
        async with asyncio.timeout(20), MMU(host, time_scale=100, clock=clock) as mmu:
            timed_out = False
            try:
                await mmu.tool_change(1, timeout=0.01)
            except LinkTimeout:
                timed_out = True
            assert timed_out
            rejected: list[DeviceError] = []
            for _ in range(20):
                try:
                    finished = await mmu.tool_change(2, timeout=10)
                    break
                except DeviceError as exc:  # the MMU may still be busy with the abandoned T1
                    rejected.append(exc)
                    await asyncio.sleep(0.2)
            else:
                raise AssertionError(f"the MMU never accepted T2: {rejected[-1] if rejected else None}")
            assert finished.command == "T2"
            sim.model.advance(sim.now())
            assert sim.model.active_slot == 2
            assert sim.model.filament == FilamentState.IN_NOZZLE
    finally:
        await host.close()
        task.cancel()
        with contextlib.suppress(BaseException):
            await task
