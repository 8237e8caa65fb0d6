"""Host ↔ simulator end to end over real links: memory pair, a pty opened as a serial port, TCP, and faults."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable

import pytest

from fabwire.errors import DeviceError, InputError, LinkTimeout
from fabwire.mmu import MMU, SyncMMU
from fabwire.mmu import host as h
from fabwire.mmu.sim import MMUSimulator
from fabwire.transport import (
    FaultPlan,
    FaultyTransport,
    Transport,
    memory_pair,
    open_pty,
)
from fabwire.transport.serial import open_serial
from linktools import loopback_tcp
from robustness.fakeclock import run_on_fake_clock

SPEED = 100.0
LIMIT = 20.0


@contextlib.asynccontextmanager
async def over_memory(sim: MMUSimulator, wrap: Callable[[Transport], Transport] | None = None
                      ) -> AsyncIterator[Transport]:
    host_end, device_end = memory_pair("mmu-test")
    task = asyncio.create_task(sim.serve(device_end))
    try:
        yield wrap(host_end) if wrap else host_end
    finally:
        await host_end.close()
        await device_end.close()
        task.cancel()
        with contextlib.suppress(BaseException):
            await task


@contextlib.asynccontextmanager
async def over_pty(sim: MMUSimulator) -> AsyncIterator[Transport]:
    device = open_pty()
    task = asyncio.create_task(sim.serve(device.transport))
    client = await open_serial(device.path, 115200)
    try:
        yield client
    finally:
        await client.close()
        task.cancel()
        with contextlib.suppress(BaseException):
            await task
        await device.close()


def over_tcp(sim: MMUSimulator) -> contextlib.AbstractAsyncContextManager[Transport]:
    return loopback_tcp(sim.serve)


LINKS = {"memory": over_memory, "pty": over_pty, "tcp": over_tcp}


def _progress(events: list[h.HostEvent]) -> list[str]:
    return [f"P{e.code:x}" for e in events if isinstance(e, h.ProgressChanged)]


def _in_order(seen: list[str], truth: list[str]) -> bool:
    it = iter(truth)
    return all(code in it for code in seen)


@pytest.mark.parametrize("link", sorted(LINKS))
async def test_handshake_and_commands(link: str) -> None:
    sim = MMUSimulator("3.0.4", speed=SPEED)
    async with asyncio.timeout(LIMIT), LINKS[link](sim) as transport, MMU(transport, time_scale=SPEED) as mmu:
        assert str(await mmu.version()) == "3.0.4+936"
        assert (await mmu.status()).command == "X0"
        operations: list[tuple[str, Callable[..., Awaitable[h.CommandFinished]]]] = [
            ("T1", lambda **kw: mmu.tool_change(1, **kw)),
            ("K1", lambda **kw: mmu.cut(1, **kw)),
            ("L2", lambda **kw: mmu.load(2, **kw)),
            ("T2", lambda **kw: mmu.tool_change(2, **kw)),
            ("U0", lambda **kw: mmu.unload(**kw)),
            ("E3", lambda **kw: mmu.eject(3, **kw)),
            ("H0", lambda **kw: mmu.home(**kw)),
        ]
        for name, run in operations:
            events: list[h.HostEvent] = []
            finished = await run(on_event=events.append)
            assert finished == h.CommandFinished(name, 0)
            truth = sim.progress_sequence(name)
            assert truth[-1] == "F0"
            assert _in_order(_progress(events), truth), (name, events, truth)
        assert await mmu.read_register("bowden_length") == 360
        await mmu.write_register(0x22, 500)
        assert await mmu.read_register(0x22) == 500
        status = await mmu.refresh()
        assert status.command == "H0"


async def test_injected_error_resolved_by_retry() -> None:
    sim = MMUSimulator(speed=SPEED, faults=["finda-didnt-trigger:1"])
    async with asyncio.timeout(LIMIT), over_memory(sim) as transport, MMU(transport, time_scale=SPEED) as mmu:
        events: list[h.HostEvent] = []
        assert await mmu.tool_change(3, on_event=events.append) == h.CommandFinished("T3", 0)
        assert [(e.code, e.auto_retry) for e in events if isinstance(e, h.ErrorRaised)] == [(0x8001, True)]


def test_stuck_error_ends_in_a_clear_failure_then_manual_retry_works() -> None:
    """On a fake clock: the error and the retry's outcome cannot depend on how loaded the machine is."""
    run_on_fake_clock(stuck_then_retried())


async def stuck_then_retried() -> None:
    clock = asyncio.get_running_loop().time
    sim = MMUSimulator(speed=SPEED, faults=["fsensor-didnt-trigger:4"], clock=clock)
    async with asyncio.timeout(LIMIT), over_memory(sim) as transport, \
            MMU(transport, time_scale=SPEED, clock=clock) as mmu:
        with pytest.raises(DeviceError) as caught:
            await mmu.tool_change(1)
        assert caught.value.code == "04103 FSENSOR DIDN'T TRIGG. (0x8003)"
        assert "sensor didn't trigger" in str(caught.value)
        assert "then Retry" in str(caught.value)
        assert sim.model.error == 0x8003  # the MMU waits for the user
        finished = asyncio.Event()
        mmu.subscribe(lambda e: finished.set() if isinstance(e, h.CommandFinished) else None)
        assert mmu.dialog_button("retry") == 1  # the dialog's Retry is the Middle button
        await mmu.press("middle")
        await finished.wait()
        assert sim.progress_sequence("T1")[-1] == "F0"


async def test_bad_input_is_refused_before_sending() -> None:
    sim = MMUSimulator(speed=SPEED)
    async with asyncio.timeout(LIMIT), over_memory(sim) as transport, MMU(transport, time_scale=SPEED) as mmu:
        seen = sim.model.requests_seen
        with pytest.raises(InputError):
            await mmu.tool_change(5)
        with pytest.raises(InputError):
            await mmu.read_register("nope")
        with pytest.raises(InputError):
            await mmu.write_register("vcc", 1)
        with pytest.raises(InputError):
            await mmu.write_register("cut_length", 300)
        with pytest.raises(InputError):
            await mmu.press("jump")
        assert sim.model.requests_seen - seen < 8  # only heartbeat traffic went out


async def test_version_mismatch_is_a_device_error() -> None:
    sim = MMUSimulator("3.0.2", speed=SPEED)
    async with asyncio.timeout(LIMIT), over_memory(sim) as transport:
        with pytest.raises(DeviceError) as caught:
            async with MMU(transport, time_scale=SPEED, accepted={(3, 0, 4)}):
                pass
        assert caught.value.code == "04504 MMU FW UPDATE NEEDED (0x802C)"


async def test_reset_brings_the_link_back() -> None:
    sim = MMUSimulator(speed=SPEED)
    async with asyncio.timeout(LIMIT), over_memory(sim) as transport, MMU(transport, time_scale=SPEED) as mmu:
        version = await mmu.reset()
        assert str(version) == "3.0.4+936"
        assert sim.model.command == ("X", 0)


@pytest.mark.parametrize("plan", [
    FaultPlan(chunk=1, side="both"),
    FaultPlan(chunk=3, side="write", seed=2),
    FaultPlan(corrupt=0.004, seed=5),
    FaultPlan(drop=0.03, side="read", seed=11),
], ids=["split-both", "split-writes", "corrupt", "drop-replies"])
async def test_recovers_over_a_faulty_link(plan: FaultPlan) -> None:
    sim = MMUSimulator(speed=SPEED)
    faulty: list[FaultyTransport] = []

    def wrap(inner: Transport) -> Transport:
        faulty.append(FaultyTransport(inner, plan))
        return faulty[0]

    async with asyncio.timeout(LIMIT), over_memory(sim, wrap) as transport, \
            MMU(transport, time_scale=SPEED) as mmu:
        losses: list[h.HostEvent] = []
        mmu.subscribe(lambda e: losses.append(e) if isinstance(e, h.LinkLost) else None)
        for slot in (1, 2):
            events: list[h.HostEvent] = []
            await mmu.tool_change(slot, on_event=events.append)
        assert sim.model.active_slot == 2
        if plan.corrupt or plan.drop:
            assert faulty[0].corrupted + faulty[0].dropped > 0
            assert losses, "the faults should have cost at least one restart"


async def test_mmu_going_silent_mid_command_is_reported_not_hung() -> None:
    sim = MMUSimulator(speed=SPEED)
    plan = FaultPlan(silent_after=250, side="read")
    async with asyncio.timeout(LIMIT), over_memory(sim, lambda t: FaultyTransport(t, plan)) as transport, \
            MMU(transport, time_scale=SPEED) as mmu:
        with pytest.raises(LinkTimeout) as caught:
            await mmu.tool_change(1)
        assert "does not answer" in str(caught.value)


async def test_silent_mmu_at_connect_is_a_link_timeout() -> None:
    host_end, device_end = memory_pair("silent")
    async with asyncio.timeout(LIMIT):
        with pytest.raises(LinkTimeout) as caught:
            async with MMU(host_end, time_scale=SPEED):
                pass
        assert "MMU" in str(caught.value)
    await host_end.close()
    await device_end.close()


async def test_monitor_stream_yields_events() -> None:
    sim = MMUSimulator(speed=SPEED)
    async with asyncio.timeout(LIMIT), over_memory(sim) as transport, MMU(transport, time_scale=SPEED) as mmu:
        stream = mmu.events()
        first = await anext(stream)
        assert isinstance(first, h.StatusUpdated | h.RegisterRead)
        await stream.aclose()


def test_sync_facade() -> None:
    with SyncMMU(f"sim://mmu?speed={SPEED:g}", speed=SPEED) as mmu:
        assert mmu.tool_change(4).command == "T4"
        assert mmu.read_register("filament_state") == 8
        mmu.write_register("cut_length", 9)
        assert mmu.read_register(0x23) == 9
        assert mmu.unload().command == "U0"
        assert mmu.status().command in ("U0", "T4")
        assert str(mmu.version()) == "3.0.4+936"


async def test_a_write_the_mmu_accepts_but_does_not_carry_out_is_no_success() -> None:
    """`W1b` with FINDA pressed: the firmware refuses the selector move silently and still answers `A`."""
    sim = MMUSimulator(speed=SPEED)
    async with asyncio.timeout(LIMIT), over_memory(sim) as transport, MMU(transport, time_scale=SPEED) as mmu:
        assert await mmu.tool_change(1) == h.CommandFinished("T1", 0)  # loaded: FINDA is pressed
        with pytest.raises(DeviceError, match=r"accepted 3 for register 0x1b \(selector_slot\) but it reads 1"):
            await mmu.write_register("selector_slot", 3)
        assert await mmu.write_register(0x07, 3) == 3  # any byte: the firmware casts it to its enum unchecked
        assert await mmu.write_register(0x07, 8) == 8
        await mmu.unload()
        await mmu.write_register("selector_slot", 3)  # FINDA off: the selector moves, and reads 3
        assert await mmu.read_register("selector_slot") == 3
