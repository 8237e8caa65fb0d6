"""Every fault the simulator can inject, row by row of its table (`fabwire.mmu.faults.FAULTS`): the cause stays
until the owner's hands remove it (the control plane), Retry without removing it gives the same error, Left and
Right do nothing, errors that only a reset clears ignore every button, and once the cause is gone Retry (or the
reset) lets the machine go on."""

from __future__ import annotations

import pytest

from fabwire.errors import InputError
from fabwire.mmu import host as h
from fabwire.mmu.faults import FAULTS, parse_fault
from fabwire.mmu.protocol import ToolChange, Unload
from fabwire.mmu.sim import Lockstep, MMUSimulator

from .test_fault_model import drive
from .wire import Wire

LOADED_FIRST = {"finda-stuck", "fsensor-stuck"}
"""Causes only an unload meets: load slot 0 first, then unload."""


def at_boot(name: str) -> bool:
    """Checked at power-on with nothing loaded: the self-test, the supply, FINDA vs EEPROM, the boot homing."""
    return name.startswith("selftest-") or name in ("undervoltage", "finda-on-boot", "homing-failed",
                                                   "idler-homing-failed") or (
        name.startswith("tmc-") and not name.endswith("-pulley"))


def reach(name: str) -> tuple[Wire, str]:
    """A machine showing the fault's error, and the command it is reported under."""
    if at_boot(name):
        w = Wire(faults=(name,), booted=False)
        w.t = 4.5
        return w, "X0"
    w = Wire()
    assert drive(w) == "X0 F0"
    if name in LOADED_FIRST:
        w.send("T0")
        assert drive(w) == "T0 F0"
        w.send("f1")
        w.sim.inject(name)
        assert w.send("U0") == "U0 A"
        return w, "U0"
    w.sim.inject(name)
    assert w.send("T1") == "T1 A"
    return w, "T1"


def settled(w: Wire, seconds: float = 5.0) -> str:
    """Q0 after `seconds` of polling, skipping the buttons the MMU hands to the printer during a tool change."""
    reply = ""
    end = w.t + seconds
    while w.t < end:
        reply = w.send("Q0", 0.25)
        while " B" in reply:
            reply = w.send("Q0")
    return reply


@pytest.mark.parametrize("name", sorted(FAULTS))
def test_table_row_names_its_firmware_sources(name: str) -> None:
    kind = FAULTS[name]
    assert kind.check.startswith("MMU:src/")
    assert kind.clears.startswith("MMU:src/")
    assert ":" in kind.cause
    assert len(kind.buttons) == 3
    if kind.recovery == "retry":
        assert kind.buttons[1].startswith("Retry")
    else:
        assert all("reset or power-cycle" in b for b in kind.buttons)
    assert parse_fault(name).count == -1  # a bare name: the cause stays until removed


@pytest.mark.parametrize("name", sorted(FAULTS))
def test_the_cause_persists_until_the_hands_remove_it(name: str) -> None:
    kind = FAULTS[name]
    w, echo = reach(name)
    error = f"{echo} E{kind.word:x}"
    assert drive(w) == error
    for button in (0, 2):  # Left and Right on the MMU and from the printer: nothing happens
        w.sim.hands("press", {0: "right", 2: "left"}[button])
        assert w.send(f"B{button}") == f"B{button} A"
        assert settled(w) == error
    if kind.recovery == "retry":
        for _ in range(4):  # Retry runs the check again: the cause is still there
            assert w.send("B1") == "B1 A"
            assert drive(w) == error
        assert w.sim.hands("remove", name) == {"removed": [name], "causes": {}}
        assert settled(w, 1.0) == error  # removing the cause does not clear the screen: Retry does
        assert w.send("B1") == "B1 A"
        assert drive(w) == f"{echo} F0"
    else:
        assert w.send("B1") == "B1 A"
        w.sim.hands("press", "middle")
        assert settled(w) == error  # no button helps
        w.send("X0")  # a reset with the cause still there: the check fails again where it runs next
        w.t += 4.5
        again = drive(w)
        if echo == "T1":
            assert again == "X0 F0"
            assert w.send("T1") == "T1 A"
            again = drive(w)
        assert again == error
        w.sim.hands("remove", name)
        w.sim.hands("power-cycle")
        w.t += 4.5
        assert drive(w) == "X0 F0"
    assert w.send("T2") == "T2 A" or echo == "U0"
    if echo != "U0":
        assert drive(w) == "T2 F0"


def test_count_is_the_knob_for_a_cause_that_goes_away() -> None:
    w = Wire(faults=("finda-on-boot:2",))
    assert w.send("Q0") == "X0 E8008"
    w.send("B1")
    assert w.send("Q0") == "X0 E8008"  # the second check fails too
    w.send("B1")
    assert w.send("Q0") == "X0 F0"  # then the filament is gone by itself


def test_hands_refuse_what_is_not_there() -> None:
    sim = MMUSimulator()
    with pytest.raises(InputError, match="nothing to remove: finda-stuck is not present"):
        sim.hands("remove", "finda-stuck")
    with pytest.raises(InputError, match="unknown MMU fault"):
        sim.hands("remove", "gremlins")
    with pytest.raises(InputError, match="left, middle or right"):
        sim.hands("press", "up")
    with pytest.raises(InputError, match="unknown action"):
        sim.hands("kick")
    assert sim.hands("inject", "finda-stuck:2") == {"injected": "finda-stuck", "causes": {"finda-stuck": 2}}
    assert sim.hands("causes") == {"causes": {"finda-stuck": 2}}


RETRY_IN_A_COMMAND = sorted(n for n, k in FAULTS.items() if k.recovery == "retry" and not at_boot(n))


@pytest.mark.parametrize("name", RETRY_IN_A_COMMAND)
def test_the_host_retries_automatically_then_shows_the_error_screen(name: str) -> None:
    """A printer presses Retry itself three times (reference §6.4); with the cause still there each Retry brings
    the same error back, so the fourth report is the error screen; once the owner removes the cause, Retry on
    that screen finishes the command."""
    clock = [0.0]
    sim = MMUSimulator(clock=lambda: clock[0])
    logic = h.HostLogic()
    pair = Lockstep(logic, sim)
    logic.start(0.0)
    pair.run(lambda new: any(isinstance(e, h.LinkUp) for e in new))
    request = ToolChange(1)
    if name in LOADED_FIRST:
        logic.plan_command(ToolChange(0), pair.now)
        assert pair.run(lambda new: any(isinstance(e, h.CommandFinished) for e in new))[-1] == \
            h.CommandFinished("T0", 0)
        request = Unload(0)
    sim.inject(name)
    logic.plan_command(request, pair.now)
    events = pair.run(lambda new: any(isinstance(e, h.ErrorRaised) and not e.auto_retry for e in new))
    errors = [e for e in events if isinstance(e, h.ErrorRaised)]
    assert [(e.code, e.auto_retry) for e in errors] == [(FAULTS[name].word, True)] * 3 + [(FAULTS[name].word, False)]
    sim.remove_cause(name)
    logic.press(1, pair.now)
    done = pair.run(lambda new: any(isinstance(e, h.CommandFinished) for e in new))
    assert done[-1] == h.CommandFinished(str(request), 0)


def test_a_press_on_the_mmu_answers_its_error_through_the_host() -> None:
    """During T the printer is in charge: the MMU hands a press on its own buttons to the printer (`T1 B1`), and a
    printer showing the MMU's error hands it back (MK3 mmu2.cpp CheckUserInput); when nothing is wrong it is
    ignored."""
    clock = [0.0]
    sim = MMUSimulator(clock=lambda: clock[0])
    logic = h.HostLogic(auto_retries=0)
    pair = Lockstep(logic, sim)
    pair.record = True
    logic.start(0.0)
    pair.run(lambda new: any(isinstance(e, h.LinkUp) for e in new))
    logic.plan_command(ToolChange(1), pair.now)
    pair.run(lambda new: any(isinstance(e, h.ProgressChanged) for e in new))
    sim.hands("press", "middle")  # nothing is wrong: the press reaches the printer, which lets it be
    events = pair.run(lambda new: any(isinstance(e, h.ButtonPushed) for e in new))
    assert h.ButtonPushed("T1", 1) in events
    sim.inject("fsensor-didnt-trigger")
    events = pair.run(lambda new: any(isinstance(e, h.ErrorRaised) for e in new))
    assert not any(isinstance(e, h.ButtonSent) for e in events)
    sim.hands("remove", "fsensor-didnt-trigger")
    sim.hands("press", "middle")
    events = pair.run(lambda new: any(isinstance(e, h.CommandFinished) for e in new))
    assert h.ButtonSent(1) in events
    assert events[-1] == h.CommandFinished("T1", 0)
    assert sim.progress_sequence("T1").count("E8003") == 1
