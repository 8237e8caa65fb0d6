"""Success means the MMU shows it: an `F0` from an MMU whose registers contradict the command is an error."""

from __future__ import annotations

import asyncio
import subprocess
import sys
from collections.abc import Awaitable, Callable
from pathlib import Path

import pytest

from clitools import cli_env, run_cli
from fabwire.errors import DeviceError
from fabwire.mmu import MMU
from fabwire.mmu import host as h
from fabwire.mmu.sim import MMUSimulator
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
        done = run_cli("mmu", "-d", url, "--speed", "50", "tool-change", "2", timeout=60, env=cli_env(tmp_path))
    finally:
        liar.kill()
        liar.wait()
    assert done.returncode == 7, done.stderr
    assert done.stdout == ""
    assert done.stderr.strip().splitlines()[-1] == (
        "fabwire: error: device error not done: the MMU reported T2 finished, but it shows FINDA off, filament at "
        "pulley, selector parked (a finished T2 leaves FINDA on, filament in the nozzle, selector at slot 2) — the "
        "command did not take effect: check the MMU with `fabwire mmu status`")


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
        assert mmu.status.command == "X0"
