"""Success means the MMU shows it (an `F0` its registers contradict is an error), and a failure is reported as soon
as it is known: a command already running is followed, an error already shown or a dead driver ends the wait."""

from __future__ import annotations

import asyncio
import contextlib
import subprocess
import sys
from collections.abc import Awaitable, Callable
from pathlib import Path

import pytest
import serialx

from clitools import cli_env, run_cli
from fabwire.errors import DeviceError, LinkClosed, LinkTimeout
from fabwire.mmu import MMU, scripts
from fabwire.mmu import host as h
from fabwire.mmu.errors import MMUError
from fabwire.mmu.protocol import ToolChange
from fabwire.mmu.sim import MMUSimulator
from fabwire.transport import Transport, open_pty
from fabwire.transport.serial import SerialTransport, open_serial
from linktools import loopback_tcp

from .lying_mmu import lying_simulator

SPEED = 100.0
LIMIT = 30.0

Command = Callable[[MMU], Awaitable[h.CommandFinished]]
COMMANDS: dict[str, Command] = {
    "tool-change": lambda m: m.tool_change(1),
    "load": lambda m: m.load(2),
    "cut": lambda m: m.cut(3),
    "eject": lambda m: m.eject(1),
    "home": lambda m: m.home(),
    "stealth-mode": lambda m: m.set_mode(True),
}


@pytest.mark.parametrize("name", sorted(COMMANDS))
async def test_an_mmu_that_reports_finished_without_moving_is_no_success(name: str) -> None:
    sim = lying_simulator("idle", SPEED)
    sim.model.advance(100.0)  # booted, idle, nothing loaded; its axes parked
    sim.model.selector = sim.model.idler = 0xFF if name == "home" else 5
    async with asyncio.timeout(LIMIT), loopback_tcp(sim.serve) as link, MMU(link, time_scale=SPEED) as mmu:
        with pytest.raises(DeviceError, match=r"reported .* finished, but it shows") as caught:
            await COMMANDS[name](mmu)
    assert caught.value.code == "not done"


async def test_an_unload_reported_done_with_the_filament_still_in_is_no_success() -> None:
    sim = MMUSimulator(speed=SPEED)
    async with asyncio.timeout(LIMIT), loopback_tcp(sim.serve) as link, MMU(link, time_scale=SPEED) as mmu:
        await mmu.tool_change(2)  # really loaded
        sim.model.__class__ = lying_simulator("idle", SPEED).model.__class__  # now it starts lying
        with pytest.raises(DeviceError, match=r"U0 finished, but it shows FINDA on, filament in nozzle"):
            await mmu.unload()


@pytest.mark.parametrize("name", ["tool-change", "load", "cut"])
async def test_an_mmu_that_serves_another_slot_is_caught(name: str) -> None:
    sim = lying_simulator("other-slot", SPEED)
    async with asyncio.timeout(LIMIT), loopback_tcp(sim.serve) as link, MMU(link, time_scale=SPEED) as mmu:
        with pytest.raises(DeviceError, match=r"selector at slot [0-4] \(a finished [TLK][0-9] leaves selector at"):
            await COMMANDS[name](mmu)


@pytest.mark.parametrize("name", sorted(COMMANDS))
async def test_an_honest_mmu_passes_every_check(name: str) -> None:
    sim = MMUSimulator(speed=SPEED)
    async with asyncio.timeout(LIMIT), loopback_tcp(sim.serve) as link, MMU(link, time_scale=SPEED) as mmu:
        finished = await COMMANDS[name](mmu)
    assert finished.result == 0
    assert sim.progress_sequence(finished.command)[-1] == "F0"


async def test_a_tool_change_to_the_slot_loaded_before_a_reboot_is_success() -> None:
    """After a reboot with filament recorded, T to that slot finishes at once and the selector reads 'unknown'."""
    sim = MMUSimulator(speed=SPEED)
    async with asyncio.timeout(LIMIT), loopback_tcp(sim.serve) as link, MMU(link, time_scale=SPEED) as mmu:
        await mmu.tool_change(3)
        await mmu.reset()
        assert await mmu.read_register("selector_slot") == 0xFF
        assert await mmu.tool_change(3) == h.CommandFinished("T3", 0)


def test_the_cli_exits_non_zero_when_the_mmu_only_says_finished(tmp_path: Path) -> None:
    liar = subprocess.Popen([sys.executable, str(Path(__file__).with_name("lying_mmu.py")), "idle", "50"],
                            stdout=subprocess.PIPE, text=True, env=cli_env())
    try:
        assert liar.stdout is not None
        url = liar.stdout.readline().strip()
        for _ in range(100):  # the boot homing first: until it ends the selector's position is unknown
            read = run_cli("mmu", "-d", url, "--speed", "50", "read", "0x1b", timeout=60, env=cli_env(tmp_path))
            if read.stdout.strip().endswith("= 5"):
                break
        done = run_cli("mmu", "-d", url, "--speed", "50", "tool-change", "2", timeout=60, env=cli_env(tmp_path))
    finally:
        liar.kill()
        liar.wait()
    assert done.returncode == 7, done.stderr
    assert done.stdout == ""
    assert done.stderr.strip().splitlines()[-1] == (
        "fabwire: error: device error not done: the MMU reported T2 finished, but it shows FINDA off, filament at "
        "pulley, selector parked (a finished T2 leaves FINDA on, filament in the nozzle, selector at slot 2) — the "
        f"command did not take effect: check the MMU with `fabwire mmu -d {url} --speed 50 status`")


async def test_an_mmu_that_ignores_the_reset_is_not_reported_reset() -> None:
    sim = lying_simulator("no-reset", SPEED)
    async with asyncio.timeout(LIMIT), loopback_tcp(sim.serve) as link, MMU(link, time_scale=SPEED) as mmu:
        await mmu.tool_change(1)  # really done: the liar only ignores X
        with pytest.raises(DeviceError, match="still reports T1 finished, not the start-up command X0"):
            await mmu.reset()


async def test_a_real_reset_reports_the_start_up_command() -> None:
    sim = MMUSimulator(speed=SPEED)
    async with asyncio.timeout(LIMIT), loopback_tcp(sim.serve) as link, MMU(link, time_scale=SPEED) as mmu:
        await mmu.tool_change(1)
        assert (await mmu.reset()).triple == (3, 0, 4)
        assert (await mmu.status()).command == "X0"


async def test_the_same_command_again_follows_the_one_the_mmu_is_running() -> None:
    """A client that lost its link mid-command (or a new one) asks for the same tool change: it follows the one
    the MMU runs to its end instead of refusing it as busy or sending it twice."""
    sim = MMUSimulator(speed=SPEED)
    async with loopback_tcp(sim.serve) as first, MMU(first, time_scale=SPEED) as mmu:
        moving = asyncio.Event()
        change = asyncio.create_task(mmu.tool_change(3, on_event=lambda e: isinstance(e, h.ProgressChanged)
                                                     and moving.set()))
        async with asyncio.timeout(LIMIT):
            await moving.wait()
        change.cancel()  # the link goes, the MMU goes on
        with contextlib.suppress(asyncio.CancelledError):
            await change
    async with asyncio.timeout(LIMIT), loopback_tcp(sim.serve) as again, MMU(again, time_scale=SPEED) as mmu:
        assert mmu.logic.command == ToolChange(3)  # adopted from the MMU's Q0 answer
        assert await mmu.tool_change(3) == h.CommandFinished("T3", 0)
    assert [x.kind for x in sim.history if x.command == "T3"].count("F") == 1  # it ran once


async def test_following_a_command_that_waits_in_an_error_ends_at_once_with_the_error() -> None:
    sim = MMUSimulator(speed=SPEED, faults=["fsensor-didnt-trigger:always"])
    async with loopback_tcp(sim.serve) as first, MMU(first, time_scale=SPEED, auto_retries=0) as mmu:
        with pytest.raises(MMUError, match=r"\(0x8003\)"):
            await mmu.tool_change(1, timeout=LIMIT)
    async with loopback_tcp(sim.serve) as again, MMU(again, time_scale=SPEED, auto_retries=0) as mmu:
        assert (await mmu.status()).kind == "E"
        async with asyncio.timeout(5):  # not the caller's whole timeout: the error is already known
            with pytest.raises(MMUError, match=r"\(0x8003\)"):
                await mmu.follow(timeout=LIMIT)
            with pytest.raises(MMUError, match=r"\(0x8003\)"):
                await mmu.tool_change(1, timeout=LIMIT)


class _DriverFails(Transport):
    """A real TCP link whose writes start failing the way a serial driver fails (not an OSError)."""

    def __init__(self, inner: Transport) -> None:
        self.inner, self.url, self.peer = inner, inner.url, inner.peer
        self.broken = False

    @property
    def closed(self) -> bool:
        return self.inner.closed

    async def read(self, max_bytes: int = 4096) -> bytes:
        return await self.inner.read(max_bytes)

    async def write(self, data: bytes) -> None:
        if self.broken:
            raise serialx.SerialException("write failed: device reports readiness but returned no data")
        await self.inner.write(data)

    async def close(self) -> None:
        await self.inner.close()


async def test_a_link_that_fails_with_a_driver_error_ends_the_command_at_once() -> None:
    sim = MMUSimulator(speed=SPEED)
    async with loopback_tcp(sim.serve) as tcp:
        link = _DriverFails(tcp)
        async with MMU(link, time_scale=SPEED) as mmu:
            link.broken = True
            async with asyncio.timeout(5):  # not the command's own 600 s
                with pytest.raises(LinkClosed, match="SerialException"):
                    await mmu.refresh(timeout=600)


async def test_a_serial_driver_error_is_a_lost_link() -> None:
    device = open_pty()
    link = await open_serial(device.path, 115200)
    try:
        assert isinstance(link, SerialTransport)
        await device.close()  # the adapter is unplugged
        with pytest.raises(LinkClosed):
            async with asyncio.timeout(5):
                await link.read()
    finally:
        await link.close()


@pytest.mark.parametrize("operation", ["read", "refresh", "press"])
async def test_every_operation_ends_when_the_link_has_failed(operation: str) -> None:
    """Ten drop-outs in a row end a register read, a status wait or a button press as they end a command, not
    after the caller's whole timeout."""
    sim = MMUSimulator(speed=SPEED)
    async with loopback_tcp(sim.serve) as link, MMU(link, time_scale=SPEED) as mmu:
        sim.model.booted_at = float("inf")  # its UART goes deaf, for good
        calls = {"read": lambda: mmu.read_register(0x22, timeout=600), "refresh": lambda: mmu.refresh(timeout=600),
                 "press": lambda: mmu.press(1, timeout=600)}
        async with asyncio.timeout(10):
            with pytest.raises(LinkTimeout, match="MMU NOT RESPONDING"):
                await calls[operation]()


async def test_answering_an_error_whose_recovery_never_ends_gives_up_at_the_timeout(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Retry on a boot homing failure: the MMU re-homes under X0, which a host cannot adopt; when that homing never
    ends, answering gives up after its timeout instead of watching for ever."""
    sim = MMUSimulator(speed=SPEED, faults=["homing-failed"])
    async with loopback_tcp(sim.serve) as link, MMU(link, time_scale=SPEED, auto_retries=0) as mmu:
        async with asyncio.timeout(LIMIT):
            while ((await mmu.status()).command, (await mmu.status()).kind) != ("X0", "E"):
                await mmu.refresh()
        monkeypatch.setattr(scripts, "HOMING_SECONDS", 1e9)  # the selector now homes for ever
        async with asyncio.timeout(LIMIT):
            with pytest.raises(LinkTimeout, match=r"still reports X0 .* 2 s after the retry press"):
                await mmu.answer("retry", timeout=2)
