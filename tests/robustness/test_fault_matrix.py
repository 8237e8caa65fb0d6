"""Each device's client against its simulator over clean and faulty links: the outcome is success with the right
result on the device, or a specific error within a bounded time — never a hang, never silent damage."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine
from typing import Any

import numpy as np
import pytest

from fabwire.errors import FabwireError
from fabwire.lineus.client import LineUs
from fabwire.lineus.draw_cli import send_plan
from fabwire.lineus.plot.plan import Plan
from fabwire.lineus.sim import LineUsSim, SimOptions
from fabwire.mmu import MMU
from fabwire.mmu.codes import FilamentState
from fabwire.mmu.sim import MMUSimulator
from fabwire.transport import FaultPlan, FaultyTransport, Transport, memory_pair
from fabwire.xyz.client import XYZPrinter
from fabwire.xyz.protocol import Link
from fabwire.xyz.sim import XYZSimulator
from linktools import loopback_tcp
from robustness.fakeclock import run_on_fake_clock

LIMIT = 20.0
SEEDS = [1, 2, 3]


def plans(seed: int, *, reply_corruption: bool) -> dict[str, FaultPlan | None]:
    """The faults, seeded. Corruption goes where the protocol can notice it (see each device's notes)."""
    return {
        "clean": None,
        "split": FaultPlan(chunk=1, seed=seed),
        "delay": FaultPlan(chunk=16, delay=0.002, seed=seed),
        "drop": FaultPlan(drop=0.02, seed=seed),
        "corrupt": FaultPlan(corrupt=0.003, seed=seed, side="read" if reply_corruption else "both"),
        "disconnect": FaultPlan(disconnect_after=200 + 150 * seed, seed=seed),
    }


FAULTS = list(plans(0, reply_corruption=False))


async def settle(work: Callable[[], Awaitable[None]], limit: float = LIMIT) -> BaseException | None:
    """Run `work` under a hard time limit; return its specific error (None on success). A hang fails."""
    timer = asyncio.timeout(limit)
    try:
        async with timer:
            await work()
    except (FabwireError, TimeoutError, ConnectionError) as exc:
        error: BaseException | None = exc
    else:
        error = None
    assert not timer.expired(), f"hung: nothing happened within {limit} s"
    if error is not None:
        assert str(error).strip(), f"{type(error).__name__} without a message"
    return error


@contextlib.asynccontextmanager
async def link(serve: Callable[[Transport], Coroutine[Any, Any, None]], plan: FaultPlan | None, seed: int
               ) -> AsyncIterator[Transport]:
    """Odd seeds: a memory pair with the faults on the host end; even seeds: real TCP, faults on the device end."""
    if seed % 2:
        host, device = memory_pair("robust")
        task = asyncio.create_task(serve(device))
        try:
            yield FaultyTransport(host, plan) if plan else host
        finally:
            await host.close()
            await device.close()
            task.cancel()
            with contextlib.suppress(BaseException):
                await task
        return

    async def faulty_serve(transport: Transport) -> None:
        await serve(FaultyTransport(transport, plan) if plan else transport)

    async with loopback_tcp(faulty_serve) as client:
        yield client


# ------------------------------------------------------------------------------------------------- MMU3


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("fault", FAULTS)
def test_mmu_tool_change_completes_or_fails_specifically(fault: str, seed: int) -> None:
    """Every MMU message carries a CRC-8, so corruption is applied both ways. Over the memory pair (odd seeds) the
    simulator, the client and their time limits run on a fake clock: the outcome and its order are the protocol's,
    however loaded the machine is."""
    plan = plans(seed, reply_corruption=False)[fault]
    slots = [seed % 5, (seed + 2) % 5]
    done: list[int] = []

    async def main() -> BaseException | None:
        clock = asyncio.get_running_loop().time
        sim = MMUSimulator(speed=100, clock=clock)

        async def work() -> None:
            async with link(sim.serve, plan, seed) as transport, \
                    MMU(transport, time_scale=100, connect_timeout=5, clock=clock) as mmu:
                for slot in slots:
                    await mmu.tool_change(slot, timeout=15)
                    done.append(slot)
                    sim.model.advance(sim.now())
                    assert sim.model.active_slot == slot
                    assert sim.model.filament == FilamentState.IN_NOZZLE

        return await settle(work)

    error = run_on_fake_clock(main()) if seed % 2 else asyncio.run(main())
    if fault == "clean" or (fault in ("split", "delay") and seed % 2):
        assert error is None
    if error is None:
        assert done == slots


# ------------------------------------------------------------------------------------------------ Line-us

STROKES = (
    np.array([[1100.0, -200.0], [1500.0, -200.0], [1500.0, 200.0]]),
    np.array([[1100.0, 200.0], [1300.0, 0.0]]),
    np.array([[1200.0, 400.0], [1400.0, 400.0], [1400.0, 600.0], [1200.0, 600.0]]),
)
TOLERANCE = 1.0
"""Machine units: replies carry coordinates rounded to hundredths (firmware 3)."""


def segments(lines: list[list[tuple[float, float]]] | tuple[np.ndarray, ...]) -> list[tuple[tuple[float, float], ...]]:
    out: list[tuple[tuple[float, float], ...]] = []
    for line in lines:
        points = [(float(x), float(y)) for x, y in line]
        out += [(a, b) for a, b in itertools.pairwise(points) if a != b]
    return out


def covered(segment: tuple[tuple[float, float], ...], by: list[tuple[tuple[float, float], ...]]) -> bool:
    (ax, ay), (bx, by_) = segment
    for (cx, cy), (dx, dy) in by:
        for p, q in (((cx, cy), (dx, dy)), ((dx, dy), (cx, cy))):
            if max(abs(ax - p[0]), abs(ay - p[1]), abs(bx - q[0]), abs(by_ - q[1])) <= TOLERANCE:
                return True
    return False


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("fault", FAULTS)
async def test_lineus_drawing_completes_or_resumes_to_the_plan(fault: str, seed: int) -> None:
    """The Line-us protocol has no checksum: a flipped digit in a command is a different, valid move that no
    one can tell apart, so corruption is applied to the replies only."""
    sim = LineUsSim(SimOptions(speed=float("inf")))
    plan = Plan(STROKES)
    drawn = 0

    def progress(index: int) -> None:
        nonlocal drawn
        drawn = index + 1

    async def draw(start: int, faults: FaultPlan | None, link_seed: int) -> None:
        async with link(sim.serve, faults, link_seed) as transport:
            arm = await LineUs.connect(transport, hello_timeout=3, reply_timeout=2)
            try:
                await send_plan(arm, plan, start=start, on_stroke=progress)
            finally:
                await arm.detach()

    error = await settle(lambda: draw(0, plans(seed, reply_corruption=True)[fault], seed))
    if fault == "clean":
        assert error is None
    if error is not None:
        assert 0 <= drawn <= len(STROKES)
        assert await settle(lambda: draw(drawn, None, 1)) is None, "resuming on a clean link must finish"
    assert drawn == len(STROKES)
    ink = segments(sim.arm.strokes)
    wanted = segments(plan.strokes)
    assert all(covered(s, ink) for s in wanted), "part of the plan was never drawn"
    assert all(covered(s, wanted) for s in ink), "ink where the plan has none"


# ------------------------------------------------------------------------------------------------- XYZ


def source_file(seed: int) -> bytes:
    rng = np.random.default_rng(seed)
    return bytes(rng.integers(0, 256, 20_000 + 3_000 * seed, dtype=np.uint8))


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("fault", FAULTS)
async def test_xyz_upload_arrives_identical_or_fails_loudly(fault: str, seed: int) -> None:
    """A printer that checks the block CRC (strict); corruption hits the printer's replies, because the command
    line itself (file name and size) has no checksum in XYZv3."""
    sim = XYZSimulator(speed=1000, gap=0.01, strict=True)
    data = source_file(seed)
    name = f"robust-{fault}-{seed}.3w"

    async def work() -> None:
        async with link(sim.serve, plans(seed, reply_corruption=True)[fault], seed) as transport:
            printer = XYZPrinter(transport, link=Link.WIFI if seed % 2 == 0 else Link.SERIAL, timeout=1.5)
            try:
                await printer.upload(data, name)
            finally:
                await printer.close()

    error = await settle(work)
    if fault == "clean":
        assert error is None
    if error is None:
        assert sim.received(name) == data
    else:
        stored = sim.received(name)
        assert stored is None or stored == data
