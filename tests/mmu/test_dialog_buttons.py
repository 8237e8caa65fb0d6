"""The printer's error dialog, choice by choice: which button each error's Retry, Continue and Stop send.

DIALOG restates, from the printer firmware's tables (Prusa-Firmware `mmu2_error_converter.cpp` ButtonAvailable and
`mmu2/errors_list.h`, as summarised in the MMU3 protocol reference's error table), what each error's dialog sends:
Retry is the Middle button wherever it is offered, Continue is Middle on most errors but Right on FILAMENT ALREADY
LOADED and Left on the TMC over-temperature warnings, and Stop print is the printer's own (no button). Every row is
checked against `MMU.dialog_button`, and the errors the simulator can raise are answered over the wire: the bytes
the host sends are the button the row names, or none."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import pytest

from fabwire.errors import InputError
from fabwire.mmu import MMU
from fabwire.mmu.errors import MMUError
from fabwire.mmu.sim import MMUSimulator
from fabwire.transport.base import Transport
from fabwire.transport.tap import TO_DEVICE, TapTransport, TraceWriter, replay_bytes

from .test_client import LIMIT, SPEED, over_memory

RETRY_ONLY = {"retry": 1, "continue": None, "stop": None}
RESET_ONLY = {"retry": None, "continue": None, "stop": None}
TMC_WARNING = {"retry": None, "continue": 2, "stop": None}
DIALOG: dict[int, dict[str, int | None]] = {
    0x8001: RETRY_ONLY,  # 04101 FINDA DIDN'T TRIGGER
    0x8002: RETRY_ONLY,  # 04102 FINDA FILAM. STUCK
    0x8003: RETRY_ONLY,  # 04103 FSENSOR DIDN'T TRIGG.
    0x8004: RETRY_ONLY,  # 04104 FSENSOR FIL. STUCK
    0x8005: {"retry": None, "continue": 0, "stop": None},  # 04501 FIL. ALREADY LOADED: Unload Left, Continue Right
    0x8087: RETRY_ONLY,  # 04115 SELECTOR CANNOT HOME
    0x8107: RETRY_ONLY,  # 04125 IDLER CANNOT HOME
    0x8008: RETRY_ONLY,  # 04506 UNLOAD MANUALLY
    0x8009: RETRY_ONLY,  # 04106 FSENSOR TOO EARLY
    0x800A: RETRY_ONLY,  # 04107 INSPECT FINDA
    0x800C: {"retry": None, "continue": 1, "stop": None},  # 04507 FILAMENT EJECTED
    0x800D: RESET_ONLY,  # 04306 MMU MCU ERROR
    0x802F: RESET_ONLY,  # 04505 FW RUNTIME ERROR
    0x8240: RESET_ONLY,  # 04301 TMC DRIVER ERROR (pulley)
    0x9080: RESET_ONLY,  # 04314 TMC SHORTED (selector)
    0xA040: TMC_WARNING,  # 04201 WARNING TMC TOO HOT (pulley)
    0xA080: TMC_WARNING,  # 04211 (selector)
    0xA100: TMC_WARNING,  # 04221 (idler)
    0xC040: RESET_ONLY,  # 04202 TMC OVERHEAT ERROR (pulley)
}
REACHED_BY_T1 = {"finda-didnt-trigger": 0x8001, "fsensor-didnt-trigger": 0x8003, "tmc-overheat-warn-pulley": 0xA040,
                 "tmc-overheat-pulley": 0xC040}
"""Simulator faults whose error a tool change meets, and that error."""


def tapped(trace: Path) -> Callable[[Transport], Transport]:
    """A wrapper recording what crosses the wire to `trace`."""
    return lambda inner: TapTransport(inner, TraceWriter.to_file(trace, url="memory://mmu", peer="sim"))


@pytest.mark.parametrize("word", DIALOG, ids=[f"{w:04x}" for w in DIALOG])
async def test_each_errors_dialog_sends_its_own_button(word: int) -> None:
    async with asyncio.timeout(LIMIT), over_memory(MMUSimulator(speed=SPEED)) as transport, \
            MMU(transport, time_scale=SPEED) as mmu:
        mmu.logic.status = dataclasses.replace(mmu.logic.status, command="T1", kind="E", value=word)
        for choice, button in DIALOG[word].items():
            if button is not None or choice == "stop":
                assert mmu.dialog_button(choice) == button, choice
            else:
                with pytest.raises(InputError, match=f"not {choice}"):
                    mmu.dialog_button(choice)


@contextlib.asynccontextmanager
async def in_error(fault: str, trace: Path) -> AsyncIterator[MMU]:
    """A client whose tool change met `fault`'s error, every byte it sends recorded to `trace`."""
    sim = MMUSimulator(speed=SPEED, faults=[fault])
    async with asyncio.timeout(LIMIT), over_memory(sim, tapped(trace)) as transport, \
            MMU(transport, time_scale=SPEED, auto_retries=0) as mmu:
        with pytest.raises(MMUError):
            await mmu.tool_change(1)
        yield mmu


def buttons_sent(trace: Path, before: int) -> list[bytes]:
    sent = replay_bytes(trace, TO_DEVICE)[before:]
    return [line[:2] for line in sent.split(b"\n") if line.startswith(b"B")]


@pytest.mark.parametrize("fault", REACHED_BY_T1)
@pytest.mark.parametrize("choice", ["retry", "continue", "stop"])
async def test_an_answer_puts_the_dialogs_button_on_the_wire(fault: str, choice: str, tmp_path: Path) -> None:
    trace = tmp_path / "wire.jsonl"
    expected = DIALOG[REACHED_BY_T1[fault]][choice]
    async with in_error(fault, trace) as mmu:
        before = len(replay_bytes(trace, TO_DEVICE))
        if expected is None and choice != "stop":
            with pytest.raises(InputError, match=f"offers .*, not {choice}"):
                await mmu.answer(choice, timeout=5)
        else:
            with contextlib.suppress(MMUError):  # the cause stays until hands remove it: the same error again
                await mmu.answer(choice, timeout=5)
    assert buttons_sent(trace, before) == ([] if expected is None else [b"B%d" % expected])


@pytest.mark.parametrize("fault", REACHED_BY_T1)
@pytest.mark.parametrize("choice", ["retry", "continue", "stop"])
async def test_the_agents_answer_is_the_dialogs(fault: str, choice: str, tmp_path: Path) -> None:
    """The agent's retry/continue/stop actions (and the actions it offers) follow the same dialog."""
    from fabwire.agent.core import DeviceSpec
    from fabwire.agent.drivers.mmu import MMUDriver

    trace = tmp_path / "wire.jsonl"
    expected = DIALOG[REACHED_BY_T1[fault]][choice]
    async with in_error(fault, trace) as mmu:
        driver = MMUDriver(DeviceSpec("m", "mmu", "sim://mmu"), lambda event: None)
        driver.mmu = mmu
        _, summary = await driver.poll()
        assert (choice in summary["actions"]) == (expected is not None or choice == "stop"), summary["actions"]
        before = len(replay_bytes(trace, TO_DEVICE))
        if expected is None and choice != "stop":
            with pytest.raises(InputError, match=f"not {choice}"):
                await driver.act(choice, {})
        else:
            assert (await driver.act(choice, {}))["ok"]
            await mmu.refresh(timeout=5)
    assert buttons_sent(trace, before) == ([] if expected is None else [b"B%d" % expected])


async def test_the_agents_stop_leaves_the_error_shown_with_its_choices(tmp_path: Path) -> None:
    """Stop sends nothing, so the machine is not shown busy afterwards: its error and the dialog's choices stay."""
    from fabwire.agent.core import DeviceSpec
    from fabwire.agent.drivers.mmu import MMUDriver

    async with in_error("finda-didnt-trigger", tmp_path / "wire.jsonl") as mmu:
        driver = MMUDriver(DeviceSpec("m", "mmu", "sim://mmu"), lambda event: None)
        driver.mmu = mmu
        await driver.poll()
        assert (await driver.act("stop", {}))["ok"]
        _, summary = await driver.poll()
        assert summary["state"] == "error"
        assert summary["actions"] == ["retry", "stop"]
