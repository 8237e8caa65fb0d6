"""The host on a noisy line and across link restarts, on a fake clock: changes complete, commands are adopted."""

from __future__ import annotations

import asyncio
import contextlib

from fabwire.mmu import MMU
from fabwire.mmu.errors import MMUError
from fabwire.mmu.events import CommandFinished, ErrorRaised
from fabwire.mmu.sim import MMUSimulator
from fabwire.transport import memory_pair
from robustness.fakeclock import run_on_fake_clock
from robustness.noisy_mmu import noisy_tool_changes


def test_fifty_tool_changes_through_two_percent_corruption_all_complete() -> None:
    report = run_on_fake_clock(noisy_tool_changes(50, corrupt=0.02, seed=5))
    assert report.corrupted > 100
    assert (report.completed, report.failures) == (50, [])


def test_the_fake_clock_really_runs_the_firmwares_timing() -> None:
    report = run_on_fake_clock(noisy_tool_changes(5, corrupt=0.0, seed=0))
    assert report.completed == 5
    assert report.model_seconds > 5 * 15  # a real tool change takes ≈20 s of MMU time


def test_a_client_that_reconnects_mid_command_adopts_it_and_sees_its_error() -> None:
    """The link to a running tool change is lost; a new host on the same MMU learns from Q0 that T1 runs and
    gets its error instead of waiting out a timeout."""

    async def main() -> tuple[str, float]:
        loop = asyncio.get_running_loop()
        sim = MMUSimulator(clock=loop.time, faults=["fsensor-didnt-trigger:always"])
        first_host, first_device = memory_pair("first")
        first = asyncio.create_task(sim.serve(first_device))
        async with MMU(first_host, clock=loop.time, connect_timeout=60) as mmu:
            change = asyncio.create_task(mmu.tool_change(1, timeout=600))
            await asyncio.sleep(3.0)
            change.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await change
        await first_host.close()
        first.cancel()
        host, device = memory_pair("second")
        serving = asyncio.create_task(sim.serve(device))
        seen: list[object] = []
        try:
            async with MMU(host, clock=loop.time, connect_timeout=60, auto_retries=0) as mmu:
                started = loop.time()
                mmu.subscribe(seen.append)
                while not any(isinstance(e, ErrorRaised) for e in seen):
                    await mmu.refresh(timeout=60)
                    assert loop.time() - started < 60, "the error of the adopted command never came"
                assert mmu.logic.busy
                assert mmu.logic.command is not None
                return str(mmu.logic.command), loop.time() - started
        finally:
            await host.close()
            serving.cancel()

    command, waited = run_on_fake_clock(main())
    assert command == "T1"
    assert waited < 60


def test_an_error_after_auto_retries_names_the_printer_code() -> None:
    async def main() -> str:
        loop = asyncio.get_running_loop()
        sim = MMUSimulator(clock=loop.time, faults=["finda-didnt-trigger:always"])
        host, device = memory_pair("err")
        serving = asyncio.create_task(sim.serve(device))
        seen: list[object] = []
        try:
            async with MMU(host, clock=loop.time) as mmu:
                try:
                    await mmu.tool_change(2, timeout=600, on_event=seen.append)
                except MMUError as exc:
                    assert not any(isinstance(e, CommandFinished) for e in seen)
                    assert sum(isinstance(e, ErrorRaised) and e.auto_retry for e in seen) == 3
                    return str(exc)
                raise AssertionError("the tool change should have failed")
        finally:
            await host.close()
            serving.cancel()

    assert run_on_fake_clock(main()).startswith("04101 FINDA DIDN'T TRIGGER (0x8001) during T2")
