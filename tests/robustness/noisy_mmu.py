"""Tool changes through a line that flips bytes both ways, on whatever clock the running loop has."""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import dataclass, field

from fabwire.errors import FabwireError
from fabwire.mmu import MMU
from fabwire.mmu.codes import FilamentState
from fabwire.mmu.errors import MMUError
from fabwire.mmu.sim import MMUSimulator
from fabwire.transport import FaultPlan, FaultyTransport, memory_pair


@dataclass
class NoisyReport:
    completed: int = 0
    failures: list[str] = field(default_factory=list)
    corrupted: int = 0
    restarts: int = 0
    model_seconds: float = 0.0


async def noisy_tool_changes(changes: int, *, corrupt: float, seed: int) -> NoisyReport:
    """`changes` tool changes (slots 0-4 in turn) with the MMU at real speed; after an MMU error the MMU is reset,
    as a person at the printer would. Each finished change is checked against the simulator's machine."""
    loop = asyncio.get_running_loop()
    sim = MMUSimulator(clock=loop.time)
    host, device = memory_pair("noisy-mmu")
    task = asyncio.create_task(sim.serve(device))
    faulty = FaultyTransport(host, FaultPlan(corrupt=corrupt, seed=seed))
    report = NoisyReport()
    try:
        async with MMU(faulty, connect_timeout=120, clock=loop.time) as mmu:
            mmu.subscribe(lambda e: setattr(report, "restarts", report.restarts + (type(e).__name__ == "LinkUp")))
            for n in range(changes):
                slot = n % 5
                try:
                    await mmu.tool_change(slot, timeout=600)
                except FabwireError as exc:
                    report.failures.append(f"#{n}: {type(exc).__name__}: {exc}")
                    if isinstance(exc, MMUError):
                        await mmu.reset(timeout=120)
                    continue
                sim.model.advance(sim.now())
                assert (sim.model.active_slot, sim.model.filament) == (slot, FilamentState.IN_NOZZLE)
                report.completed += 1
    finally:
        await host.close()
        task.cancel()
        with contextlib.suppress(BaseException):
            await task
    report.corrupted = faulty.corrupted
    report.model_seconds = loop.time()
    return report
