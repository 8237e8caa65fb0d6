"""A cause that is still there brings its error back on every Retry, as the firmware re-runs the failed check; only
clearing the cause (or, for driver faults, a reset with the cause gone) lets the command go on."""

from __future__ import annotations

import pytest

from .wire import Wire

RETRIES = 4


def _error(w: Wire, command: str, code: str, limit: float = 120.0) -> None:
    """Poll (answering f like the printer) until `command` reports E`code`; fail on any other error or an end."""
    end = w.t + limit
    while w.t < end:
        reply = w.send("Q0", 0.1)
        if reply == f"{command} E{code}":
            return
        assert not reply.startswith((f"{command} F", f"{command} E")), f"{reply} while waiting for E{code}"
        if reply.endswith(" P1c"):
            w.send("f1")
        if reply.endswith(" P3"):
            w.send("f0")
    raise AssertionError(f"{command} never reported E{code}")


# (fault, command that reaches its check, error code, whether the filament must be loaded first)
CHECKS = [
    ("finda-didnt-trigger", "T1", "8001", False),
    ("finda-didnt-trigger", "K2", "8001", False),
    ("finda-stuck", "U0", "8002", True),
    ("finda-stuck", "T3", "8002", True),
    ("fsensor-didnt-trigger", "T1", "8003", False),
    ("fsensor-stuck", "U0", "8004", True),
    ("fsensor-stuck", "E2", "8004", True),
    ("fsensor-too-early", "T4", "8009", False),
    ("homing-failed", "H0", "8087", False),
    ("homing-failed", "T2", "8087", False),
    ("idler-homing-failed", "L1", "8107", False),
    ("idler-homing-failed", "H0", "8107", False),
]


@pytest.mark.parametrize(("fault", "command", "code", "loaded"), CHECKS,
                         ids=[f"{c[0]}-{c[1]}" for c in CHECKS])
def test_a_lasting_cause_fails_every_retry_until_it_is_cleared(fault: str, command: str, code: str,
                                                               loaded: bool) -> None:
    w = Wire()
    if loaded:
        w.send("T0")
        w.run_until("T0 F0")
        w.send("f1")  # the filament is in the printer's sensor
    w.sim.inject(f"{fault}:always")
    assert w.send(command) == f"{command} A"
    _error(w, command, code)
    for _ in range(RETRIES):
        assert w.send("B1", 1.0) == "B1 A"
        _error(w, command, code)  # the check ran again and failed again
    w.sim.clear_faults(fault)
    assert w.send("Q0", 1.0) == f"{command} E{code}"  # clearing the cause is not an answer: the error waits
    assert w.send("B1") == "B1 A"
    if command.startswith("E"):
        _error(w, command, "800c")
        w.send("B1")
    w.run_until(f"{command} F0")


def test_a_lasting_boot_discrepancy_stays_until_the_filament_is_pulled() -> None:
    w = Wire(faults=("finda-on-boot:always",))
    assert w.send("Q0") == "X0 E8008"
    for _ in range(RETRIES):
        w.send("B1")
        assert w.send("Q0", 1.0) == "X0 E8008"
    w.sim.clear_faults()
    w.send("B1")
    w.run_until("X0 F0")


@pytest.mark.parametrize("fault", ["tmc-short-idler", "undervoltage", "selftest-selector"])
def test_a_lasting_driver_or_supply_fault_survives_every_reset(fault: str) -> None:
    w = Wire(faults=(f"{fault}:always",))
    if not fault.startswith("selftest"):
        w.send("T0")
    for _ in range(3):
        reply = w.send("Q0", 0.5)
        for _ in range(60):  # the boot homing or the first move runs the check
            if " E" in reply:
                break
            reply = w.send("Q0", 0.5)
        assert " E" in reply, reply
        assert w.send("B1") == "B1 A"
        assert w.send("Q0", 2.0) == reply  # Retry does not help a driver, a supply or a soldering fault
        w.send("X0")
        w.t += 4.5
        if not fault.startswith("selftest"):
            w.send("T0")
    w.sim.clear_faults()
    w.send("X0")
    assert w.send("Q0", 4.5).startswith("X0 ")
    assert w.send("T0", 5.0) == "T0 A"
    w.run_until("T0 F0")
