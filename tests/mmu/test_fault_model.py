"""Every fault × {at boot, idle, inside each command} × {Retry, Continue, Stop, reset}, against the reference's rules.

The expectations are written here from the reference (§4.2 buttons, §5.4 recovery, §5.5 where each check runs),
not read from the simulator's own tables: mechanical and sensor errors recover on Middle, which runs the failed
check again (so a cause still present brings the same error back); driver errors, the self-test and the supply
panic wait for a reset; Right (Stop) never clears an MMU error; a reset clears every error, and a cause still
present fails again wherever it is next checked.
"""

from __future__ import annotations

import pytest

from fabwire.mmu.faults import FAULTS

from .wire import Wire

AXIS_BIT = {"pulley": 0x40, "selector": 0x80, "idler": 0x100}
TMC_FLAG = {"ioin": 0x8200, "reset": 0x8400, "undervoltage": 0x8800, "short": 0x9000, "overheat-warn": 0xA000,
            "overheat": 0xC000}
COMMANDS = ("T", "L", "U", "E", "K", "H")
ALL = set(COMMANDS)


def expected(name: str) -> tuple[int, bool, set[str]]:
    """(error word, recovers on Middle, commands that run the check) for a fault name."""
    table: dict[str, tuple[int, bool, set[str]]] = {
        "finda-didnt-trigger": (0x8001, True, {"T", "K"}),  # L's first feed is unlimited: it never fails
        "finda-stuck": (0x8002, True, {"T", "L", "U", "E", "K"}),
        "fsensor-didnt-trigger": (0x8003, True, {"T"}),
        "fsensor-stuck": (0x8004, True, {"T", "U", "E", "K"}),
        "fsensor-too-early": (0x8009, True, {"T"}),
        "homing-failed": (0x8087, True, {"T", "L", "E", "K", "H"}),  # U never moves the selector
        "idler-homing-failed": (0x8107, True, ALL),
        "finda-on-boot": (0x8008, True, set()),
        "undervoltage": (0x800D, False, ALL),
    }
    if name in table:
        return table[name]
    if name.startswith("selftest-"):
        return 0xC200 | AXIS_BIT[name.removeprefix("selftest-")], False, set()
    kind, axis = name.removeprefix("tmc-").rsplit("-", 1)
    moves = {"pulley": {"T", "L", "U", "E", "K"}, "selector": {"T", "L", "E", "K", "H"}, "idler": ALL}[axis]
    return TMC_FLAG[kind] | AXIS_BIT[axis], False, moves


def checked_at_boot(name: str, loaded: bool) -> bool:
    """Self-test and supply always; FINDA vs EEPROM and the homing of selector/idler only with nothing loaded."""
    if name.startswith("selftest-") or name == "undervoltage":
        return True
    if loaded:
        return False
    return name in ("finda-on-boot", "homing-failed", "idler-homing-failed") or (
        name.startswith("tmc-") and not name.endswith("-pulley"))


def drive(w: Wire, limit: float = 200.0) -> str:
    """Poll like a printer, jumping the fake clock from one model event to the next, until the MMU reports an
    error, finishes, or waits for nothing but a person. Presses Continue on the eject's 'filament ejected'."""
    end = w.t + limit
    while w.t < end:
        reply = w.send("Q0")
        if reply.endswith(" P1c"):
            w.send("f1")
        elif reply.endswith(" P3"):
            w.send("f0")
        if reply.endswith(" E800c"):
            w.send("B1")
            continue
        settled = reply != "X0 F0" or w.sim.model.next_deadline() is None  # X0 F0 also while the axes home
        if (" E" in reply or " F" in reply) and settled:
            return reply
        deadline = w.sim.model.next_deadline()
        if deadline is None:
            return reply
        w.t = max(w.t + 0.05, deadline + 0.01)
    return w.send("Q0")


def prepared(phase: str) -> tuple[Wire, str]:
    """A booted MMU in a known state for `phase`; returns it and the command to send (or '')."""
    w = Wire()
    assert drive(w) == "X0 F0"
    if phase in ("T", "U", "E", "K"):
        w.send("T0")
        assert drive(w) == "T0 F0"  # loaded, so unload checks run too
    return w, {"T": "T1", "L": "L1", "U": "U0", "E": "E1", "K": "K0", "H": "H0"}.get(phase, "")


def press(w: Wire, button: str, word: int) -> str:
    if button == "reset":
        w.send("X0")
        w.t += 4.5
    elif button == "stop":
        w.send("B0")
    elif button == "continue":
        w.send("B2" if word & 0xA000 == 0xA000 and word & 0x4000 == 0 else "B1")  # the printer's Continue
    else:
        w.send("B1")
    return drive(w)


def after_button(name: str, always: bool, button: str, echo: str, loaded: bool) -> str:
    word, middle_recovers, _ = expected(name)
    if button == "reset":
        return f"X0 E{word:x}" if always and checked_at_boot(name, loaded) else "X0 F0"
    if button in ("retry", "continue") and middle_recovers and not always:
        return f"{echo} F0"
    return f"{echo} E{word:x}"


CASES = [(name, phase) for name in sorted(FAULTS) for phase in ("boot", "idle", *COMMANDS)]


@pytest.mark.parametrize(("name", "phase"), CASES)
def test_fault_in_every_phase_with_every_answer(name: str, phase: str) -> None:
    word, _, commands = expected(name)
    for always in (False, True):
        fault = name if always else f"{name}:1"  # a bare name stays until removed; :1 fails one check
        for button in ("retry", "continue", "stop", "reset"):
            if phase == "boot":
                w = Wire(faults=(fault,), booted=False)
                w.t = 4.5
                first = drive(w)
                manifests = checked_at_boot(name, loaded=False)
                echo = "X0"
            else:
                w, command = prepared(phase)
                supply = name == "undervoltage" and command  # checked before the command could start: arm after
                if not supply:
                    w.sim.inject(fault)
                if command:
                    assert w.send(command) == f"{command} A"
                if supply:
                    w.sim.inject(fault)
                first = drive(w)
                manifests = (phase == "idle" and name == "undervoltage") or phase in commands
                echo = command or "X0"
            where = f"{fault} at {phase}, then {button}"
            if not manifests:
                assert " E" not in first, where
                if phase == "L" and name == "finda-didnt-trigger":
                    assert first == "L1 P5", where  # the unlimited feed waits for a button, as the firmware's
                break
            assert first == f"{echo} E{word:x}", where
            loaded = w.sim.model.eeprom.slot is not None  # filament recorded: the reboot will not home
            assert press(w, button, word) == after_button(name, always, button, echo, loaded), where


def test_a_cleared_cause_lets_retry_succeed() -> None:
    w = Wire(faults=("homing-failed:always",), booted=False)
    w.t = 4.5
    assert drive(w) == "X0 E8087"
    w.send("B1")
    assert drive(w) == "X0 E8087"  # still stalled: the re-home fails again
    w.sim.clear_faults("homing-failed")
    w.send("B1")
    assert drive(w) == "X0 F0"
    assert (w.send("R1b"), w.send("R1c")) == ("R1b A5", "R1c A5")


def test_a_driver_error_is_checked_again_after_reset_at_the_next_move() -> None:
    w = Wire(faults=("tmc-short-pulley:always",))
    assert drive(w) == "X0 F0"  # boot moves no pulley
    w.send("L2")
    assert drive(w) == "L2 E9040"
    w.send("X0")
    w.t += 4.5
    assert drive(w) == "X0 F0"
    w.send("L2")
    assert drive(w) == "L2 E9040"


def _idler_after_retry(w: Wire, fault: str, command: str) -> tuple[str, str, str]:
    """(the error, the idler register just after Retry, the end) for `command` failing once on `fault`."""
    w.sim.inject(fault)
    assert w.send(command) == f"{command} A"
    error = drive(w)
    w.sim.clear_faults()
    assert w.send("B1") == "B1 A"
    w.t += 0.1
    idler = w.send("R1c")
    return error, idler, drive(w)


@pytest.mark.parametrize(("fault", "phase", "error", "idler"), [
    ("finda-didnt-trigger", "T", "T1 E8001", "R1c Aff"), ("fsensor-didnt-trigger", "T", "T1 E8003", "R1c Aff"),
    ("fsensor-stuck", "U", "U0 E8004", "R1c A5"),  # filament still reaches the sensor: the idler may not home
])
def test_retry_in_a_tool_change_or_unload_invalidates_homing(fault: str, phase: str, error: str, idler: str) -> None:
    w, command = prepared(phase)
    failed, after_retry, end = _idler_after_retry(w, fault, command)
    assert failed == error
    assert after_retry == idler  # Aff: position unknown, the idler homes again before it moves
    assert end == f"{command} F0"
    assert w.send("R1c") == "R1c A5"


def test_retry_in_a_load_keeps_the_homing() -> None:
    w, command = prepared("L")
    w.send("T0")  # a loaded slot: L1 then finds FINDA stuck on its retract
    assert drive(w) == "T0 F0"
    w.send("U0")
    assert drive(w) == "U0 F0"
    failed, idler, _ = _idler_after_retry(w, "finda-stuck", command)
    assert failed == "L1 E8002"
    assert idler == "R1c A5"  # load's recovery does not invalidate homing (reference §5.5)
