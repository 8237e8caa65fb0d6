"""The simulator at wire level: dispatch rules, boot, registers, personalities, state machines and faults."""

from __future__ import annotations

import pytest

from fabwire.errors import InputError
from fabwire.mmu.faults import parse_fault
from fabwire.mmu.protocol import Read, encode
from fabwire.mmu.scripts import move_time

from .wire import Wire


def test_boot_silence_then_x0_finished() -> None:
    w = Wire(booted=False)
    assert w.raw(b"S0*c6\n", 1.0) == b""
    assert w.raw(b"S0*c6\n", 2.9) == b""
    assert w.raw(b"S0*c6\n", 0.2) == b"S0 A3*22\n"
    assert w.raw(b"Q0*ea\n") == b"X0 F0*87\n"


@pytest.mark.parametrize(("version", "revision", "build"), [("3.0.2", "S2 A2*65", "S3 A36e*4c"),
                                                           ("3.0.3", "S2 A3*70", "S3 A380*d9"),
                                                           ("3.0.4", "S2 A4*1b", "S3 A3a8*df")])
def test_version_registers(version: str, revision: str, build: str) -> None:
    w = Wire(version)
    assert w.raw(b"S0*c6\n") == b"S0 A3*22\n"
    assert w.raw(b"S1*ad\n") == b"S1 A0*34\n"
    assert w.raw(b"S2*10\n") == revision.encode() + b"\n"
    assert w.raw(b"S3*7b\n") == build.encode() + b"\n"


def test_never_answers_x_f_garbage_or_bad_crc() -> None:
    w = Wire()
    assert w.send("F1") == ""
    assert w.raw(b"x\n") == b""
    assert w.raw(b"C0*00\n") == b""
    assert w.raw(b"T0*aa\n") == b""
    assert w.raw(b"\n") == b""  # resynchronises after the CRC error's swallowed line
    assert w.send("Q0") == "X0 F0"
    assert w.send("X0") == ""
    assert w.send("Q0", 1.0) == ""  # rebooting
    assert w.send("Q0", 4.0) == "X0 F0"


def test_error_state_swallows_the_next_message_on_the_wire() -> None:
    w = Wire()
    assert w.raw(b"T0*aa\nQ0*ea\n") == b""
    assert w.raw(b"Q0*ea\n") == b"X0 F0*87\n"
    assert w.raw(b"T0*aa\n\nQ0*ea\n") == b"X0 F0*87\n"
    assert w.raw(b"Q0*ea\r\nQ0*ea\n") == b"X0 F0*87\n"
    assert w.raw(b"Q0*ea\rQ0*ea\r") == b"X0 F0*87\nX0 F0*87\n"


def test_one_request_per_tick() -> None:
    w = Wire()
    w.sim.receive(b"Q0*ea\nR8*81\n", w.t)
    assert w.sim.pending == 2
    assert w.sim.tick(w.t) == b"X0 F0*87\n"
    assert w.sim.tick(w.t) == b"R8 A0*8d\n"
    assert w.sim.tick(w.t) == b""


def test_busy_rule_and_command_echo() -> None:
    w = Wire()
    assert w.send("T1") == "T1 A"
    assert w.send("Q0") == "T1 P5"
    assert w.send("T2") == "T2 R"
    assert w.send("L3") == "L3 R"
    assert w.send("Q0") == "T1 P5"
    w.run_until("T1 F0")
    assert w.send("Q0", 10) == "T1 F0"


def test_invalid_tool_is_rejected_and_reported() -> None:
    w = Wire()
    assert w.send("T7") == "T7 R"
    assert w.send("Q0") == "T7 E8006"
    assert w.send("L1") == "L1 A"


def test_mode_differs_between_personalities() -> None:
    old = Wire("3.0.3")
    assert old.raw(b"M1*e\n") == b""
    new = Wire("3.0.4")
    assert new.raw(b"M1*e\n") == b"M1 A*c1\n"
    assert new.raw(b"Q0*ea\n") == b"M1 F0*d7\n"
    assert new.send("Ra") == "Ra A1"


def test_register_access_rules() -> None:
    w = Wire("3.0.3")
    assert w.raw(b"R30*00\nR8*81\n") == b""  # wrong CRC: silence, and the next line is swallowed
    assert w.raw(encode(Read(0x30))) == b"R30 R*78\n"
    assert w.send("R24") == "R24 R"
    assert w.send("R23") == "R23 A8"
    assert w.send("W0 5") == "W0 R"
    assert w.send("W4 1") == "W4 R"
    assert w.send("We 64") == "We R"  # acceleration: read-only before 3.0.4
    assert w.send("W22 190") == "W22 A"
    assert w.send("R22") == "R22 A190"
    assert w.send("W22 14") == "W22 A"  # out of range: stored, but reads back the default
    assert w.send("R22") == "R22 A168"
    assert w.send("W30 1") == "W30 R"
    assert w.send("Wb 1ff") == "Wb A"  # 8-bit register: truncated
    assert w.send("Rb") == "Rb Aff"
    new = Wire("3.0.4")
    assert new.send("We 64") == "We A"
    assert new.send("Re") == "Re A63"  # kept in motor steps: 100 mm/s² reads back 99 (registers.cpp 0x0e)


def test_fsensor_from_f_and_register() -> None:
    w = Wire()
    assert w.send("f3") == "f3 A"
    assert w.send("R9") == "R9 A1"
    assert w.send("W9 0") == "W9 A"
    assert w.send("R9") == "R9 A0"
    assert w.send("P0") == "P0 A0"


def test_tool_change_from_empty_progress_in_order() -> None:
    w = Wire()
    assert w.send("T1") == "T1 A"
    start = w.t
    w.run_until("T1 F0", step=0.05)
    assert w.sim.progress_sequence("T1") == ["P5", "P6", "P1c", "P7", "P6", "P2", "F0"]
    assert 6.0 < w.t - start < 20.0
    assert w.send("R7") == "R7 A8"
    assert w.send("R8") == "R8 A1"
    assert w.send("R1c") == "R1c A5"
    assert w.send("T1") == "T1 A"  # same slot already in the nozzle: finishes at once
    assert w.send("Q0") == "T1 F0"


@pytest.mark.parametrize(("version", "sequence"), [
    ("3.0.4", ["P3", "P19", "P5", "P6", "P1c", "P7", "P6", "P2", "F0"]),
    ("3.0.3", ["P3", "P19", "P2", "P5", "P6", "P1c", "P7", "P6", "P2", "F0"]),
])
def test_tool_change_with_unload_per_personality(version: str, sequence: list[str]) -> None:
    w = Wire(version)
    w.send("T0")
    w.run_until("T0 F0")
    w.send("T2")
    w.run_until("T2 F0", step=0.02)
    assert w.sim.progress_sequence("T2") == sequence


def test_unload_waits_for_fsensor_off_on_304() -> None:
    w = Wire("3.0.4")
    w.send("T0")
    w.run_until("T0 F0")
    assert w.send("U0") == "U0 A"
    replies = w.run_until("U0 E8004", fsensor_follow=False)
    assert "U0 Pa" in replies
    assert w.send("f0") == "f0 A"
    assert w.send("B1") == "B1 A"
    w.run_until("U0 F0")
    assert w.send("R7") == "R7 A1"


@pytest.mark.parametrize(("command", "sequence"), [
    ("L2", ["P5", "P19", "P5", "P19", "P2", "F0"]),
    ("K1", ["P12", "P5", "P19", "P13", "P14", "P2", "P15", "P1a", "P16", "F0"]),
    ("E3", ["P17", "P1", "P18", "Pa", "E800c", "F0"]),
    ("H0", ["P1a", "F0"]),
    ("M0", ["F0"]),
    ("U0", ["F0"]),
])
def test_commands_step_through_their_states(command: str, sequence: list[str]) -> None:
    w = Wire()
    assert w.send(command) == f"{command} A"
    if command.startswith("E"):
        w.run_until(f"{command} E800c")
        assert w.send("B1") == "B1 A"
    w.run_until(f"{command} F0", step=0.02)
    assert w.sim.progress_sequence(command) == sequence


def test_eject_and_cut_unload_first() -> None:
    w = Wire()
    w.send("T4")
    w.run_until("T4 F0")
    w.send("K4")
    w.run_until("K4 F0", step=0.02)
    assert w.sim.progress_sequence("K4")[:3] == ["P3", "P19", "P12"]


def test_load_is_cancelled_by_a_button_during_unlimited_feed() -> None:
    w = Wire(faults=("finda-didnt-trigger",))
    w.send("L1")
    assert w.send("Q0", 3.0) == "L1 P5"
    assert w.send("Q0", 30.0) == "L1 P5"  # the unlimited feed never gives up
    w.send("B0")
    w.run_until("L1 F1")


def test_injected_error_then_middle_recovers() -> None:
    w = Wire(faults=("finda-didnt-trigger",))
    w.send("T1")
    replies = w.run_until("T1 E8001", step=0.05)
    assert replies[-2:] == ["T1 Pa", "T1 E8001"]
    assert w.send("T2") == "T2 R"  # busy while waiting for the user
    assert w.send("R4") == "R4 A1"
    assert w.send("B0") == "B0 A"  # only Middle helps
    assert w.send("Q0", 1.0) == "T1 E8001"
    assert w.sim.remove_cause("finda-didnt-trigger") == ["finda-didnt-trigger"]  # the owner untangles the spool
    assert w.send("B1") == "B1 A"
    assert w.send("Q0") == "T1 P5"
    w.run_until("T1 F0")


@pytest.mark.parametrize(("fault", "code"), [("fsensor-didnt-trigger", "8003"), ("fsensor-too-early", "8009")])
def test_fsensor_faults(fault: str, code: str) -> None:
    w = Wire(faults=(fault,))
    w.send("T0")
    w.run_until(f"T0 E{code}")
    w.sim.remove_cause(fault)
    w.send("B1")
    w.run_until("T0 F0")
    assert "P3" in w.sim.progress_sequence("T0")  # recovery restarts the change, unloading first


def test_homing_failure_rehomes_after_middle() -> None:
    w = Wire(faults=("homing-failed",))
    w.send("T2")
    w.run_until("T2 E8087")
    assert w.send("R4") == "R4 A0"  # axis failures do not count as drive errors
    w.sim.remove_cause("homing-failed")
    w.send("B1")
    assert w.send("Q0") == "T2 P1a"
    w.run_until("T2 F0")


def test_tmc_fault_needs_a_reset() -> None:
    w = Wire(faults=("tmc-short-idler",))
    w.send("T0")
    w.run_until("T0 E9100")
    w.send("B1")
    assert w.send("Q0", 5.0) == "T0 E9100"
    assert w.send("T1") == "T1 R"
    assert w.send("X0") == ""
    w.run_until("X0 E9100")  # the driver still fails: the boot homing moves the idler
    w.sim.remove_cause("tmc-short-idler")
    assert w.send("X0") == ""
    assert w.send("Q0", 4.1) == "X0 F0"
    w.send("T1")
    w.run_until("T1 F0")


def test_finda_on_boot_discrepancy() -> None:
    w = Wire(faults=("finda-on-boot",))
    assert w.send("Q0") == "X0 E8008"
    w.send("B1")
    assert w.send("Q0") == "X0 E8008"  # Retry looks at FINDA again: the filament is still there
    assert w.send("R8") == "R8 A1"
    w.sim.remove_cause("finda-on-boot")  # the owner pulls it out
    assert w.send("R8") == "R8 A0"
    assert w.send("Q0") == "X0 E8008"  # until Retry re-runs the check
    w.send("B1")
    assert w.send("Q0") == "X0 F0"


def test_physical_button_during_tool_change_goes_to_the_printer() -> None:
    w = Wire()
    w.send("T1")
    w.sim.press(1)
    assert w.send("Q0") == "T1 B1"
    assert w.send("Q0") == "T1 P5"


def test_reset_42_erases_eeprom_counters() -> None:
    w = Wire(faults=("finda-didnt-trigger",))
    w.send("T1")
    w.run_until("T1 E8001")
    assert w.send("R4") == "R4 A1"
    w.send("X0")
    assert w.send("R4", 4.5) == "R4 A1"
    w.send("X2a")
    assert w.send("R4", 4.5) == "R4 A0"


def test_idle_middle_starts_a_load_under_the_old_command() -> None:
    w = Wire()
    w.send("H0")
    assert w.send("Q0") == "H0 P1a"
    w.run_until("H0 F0")
    w.send("B1", 2.0)
    assert w.send("Q0") == "H0 P5"


def test_move_time_matches_reference_figures() -> None:
    assert move_time(14, 45, 200) == pytest.approx(0.54, abs=0.01)
    assert move_time(200, 300, 500) == pytest.approx(1.27, abs=0.01)
    assert move_time(40, 300, 500) == pytest.approx(0.57, abs=0.01)
    assert move_time(360, 95, 800) == pytest.approx(3.9, abs=0.05)


def test_a_skipped_fault_hits_a_later_command() -> None:
    w = Wire(faults=("finda-didnt-trigger@1:1",))
    w.send("T0")
    w.run_until("T0 F0", step=0.05)  # the tool change's one feed to FINDA is let through
    w.send("T1")
    replies = w.run_until("T1 E8001", step=0.05)
    assert replies[-2:] == ["T1 Pa", "T1 E8001"]


def test_fault_skip_is_parsed_and_checked() -> None:
    fault = parse_fault("finda-didnt-trigger@2:always")
    assert (fault.name, fault.skip, fault.count) == ("finda-didnt-trigger", 2, -1)
    with pytest.raises(InputError, match="whole number"):
        parse_fault("finda-stuck@x")


def test_fault_names_are_checked() -> None:
    assert parse_fault("tmc-short").name == "tmc-short-pulley"
    assert parse_fault("finda-stuck:always").count == -1
    with pytest.raises(InputError):
        parse_fault("no-such-fault")
    with pytest.raises(InputError):
        parse_fault("finda-stuck:0")


@pytest.mark.parametrize(("fault", "code"), [("finda-stuck", "8002"), ("fsensor-stuck", "8004")])
def test_unload_faults_recover_with_middle(fault: str, code: str) -> None:
    w = Wire()
    w.send("T0")
    w.run_until("T0 F0")
    w.sim.inject(fault)
    w.send("U0")
    w.run_until(f"U0 E{code}")
    w.sim.remove_cause(fault)
    assert w.send("B1") == "B1 A"
    w.run_until("U0 F0")
    assert w.send("R7") == "R7 A1"
    assert w.send("R8") == "R8 A0"


def test_idler_homing_failure() -> None:
    w = Wire(faults=("idler-homing-failed",))
    w.send("L1")
    w.run_until("L1 E8107")
    w.sim.remove_cause("idler-homing-failed")
    w.send("B1")
    w.run_until("L1 F0")


def test_undervoltage_panics_until_reset() -> None:
    w = Wire()
    w.send("T0")
    assert w.send("Q0", 1.0) == "T0 P5"
    w.sim.inject("undervoltage")
    assert w.send("Q0") == "T0 E800d"  # the supply is checked on every main-loop pass
    assert w.send("R5") == "R5 Ad"
    assert w.send("T1") == "T1 R"
    assert w.send("B1") == "B1 A"
    assert w.send("Q0", 5.0) == "T0 E800d"
    w.send("X0")
    assert w.send("Q0", 4.5) == "X0 E800d"  # the supply is still low: the first check after the reset panics
    w.sim.remove_cause("undervoltage")
    w.send("X0")
    assert w.send("Q0", 4.5) == "X0 F0"


def test_a_failed_load_verification_starts_over_with_the_unlimited_feed() -> None:
    """L's verification feed fails (E8001, FINDA off): Middle restarts the whole load, not a retract of filament
    that never reached FINDA (reference §5.5 LoadFilament)."""
    w = Wire(faults=("finda-didnt-trigger@1:1",))  # the unlimited feed passes, the verification feed fails
    w.send("L1")
    assert w.run_until("L1 E8001", step=0.05)[-3:] == ["L1 P5", "L1 Pa", "L1 E8001"]
    assert w.send("R8") == "R8 A0"
    w.send("B1")
    assert w.run_until("L1 F0", step=0.05) == ["L1 P5", "L1 P19", "L1 P5", "L1 P19", "L1 P2", "L1 F0"]
