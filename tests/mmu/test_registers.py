"""Every register of the firmware's table through its units: the boot value as read, what a write stores and
what a read then answers, and whether it can be written at all (`MMU:src/registers.cpp`)."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fabwire.mmu import codes, units

from .wire import Wire

BOOTED = 20.0
"""Seconds after power-on by which the boot homing has ended."""


def booted(version: str = "3.0.4", arithmetic: str = "pc") -> Wire:
    w = Wire(version, arithmetic=arithmetic)
    w.t = BOOTED
    return w


def read(w: Wire, address: int) -> int:
    reply = w.send(f"R{address:x}")
    assert reply.startswith(f"R{address:x} A"), reply
    return int(reply.split(" A")[1] or "0", 16)


@pytest.mark.parametrize("register", codes.REGISTERS, ids=lambda r: f"{r.address:02x}-{r.name}")
def test_boot_value_as_the_firmware_reports_it(register: codes.Register) -> None:
    w = booted()
    expected = {0x02: 4, 0x03: 936}.get(register.address, register.boot)
    assert read(w, register.address) == expected
    if register.default is not None and register.address >= 0x07:
        assert units.boot_value(register, (3, 0, 4), units.FLOAT_FORMATS["pc"]) == register.boot


WRITES: list[tuple[int, int, int]] = [
    # (address, value written, what a read then answers) — each from the firmware's write and read functions
    (0x07, 2, 2), (0x07, 3, 3), (0x07, 0x108, 8),  # any byte of the enum's uint8_t
    (0x09, 1, 1), (0x09, 2, 1), (0x09, 0, 0),  # ProcessMessage(v != 0)
    (0x0B, 5, 5), (0x0B, 300, 44),  # uint8_t fsensorToNozzle_mm
    (0x0C, 0x1FF, 0xFF),
    (0x0D, 65535, 65535), (0x0D, 0, 0),
    (0x0E, 300, 299), (0x0E, 800, 799), (0x0E, 1, 0), (0x0E, 0, 0),  # pulley: 83.5628 steps/mm, truncated twice
    (0x0F, 333, 333), (0x0F, 200, 200),  # selector: 200 steps/mm, exact
    (0x10, 500, 499), (0x10, 9, 8), (0x10, 450, 449),  # idler: 8.888… steps/deg
    (0x11, 120, 120), (0x12, 60, 60), (0x13, 400, 400), (0x14, 20, 20), (0x15, 35, 35), (0x16, 200, 200),
    (0x17, 12, 12), (0x17, 255, 8), (0x17, 0x1FF, 8),  # an EEPROM byte of 0xff reads as the default
    (0x18, 0, 0), (0x18, 255, 3),
    (0x19, 6, 6), (0x19, 255, 7),
    (0x1B, 2, 2), (0x1B, 5, 5),
    (0x1C, 3, 3), (0x1C, 5, 5), (0x1C, 9, 5),  # d >= toolCount: Disengage
    (0x1D, 31, 31), (0x1D, 0x128, 0x28),
    (0x1E, 20, 20), (0x1F, 25, 25), (0x20, 0x120, 0x20),
    (0x22, 420, 420), (0x22, 1000, 1000), (0x22, 341, 341), (0x22, 340, 360), (0x22, 1001, 360),
    (0x23, 12, 12), (0x23, 256, 0),
]


def _written(address: int) -> bool:
    return any(a == address for a, _, _ in WRITES)


@pytest.mark.parametrize("register", codes.REGISTERS, ids=lambda r: f"{r.address:02x}-{r.name}")
def test_every_register_is_writable_exactly_as_the_firmware_says(register: codes.Register) -> None:
    w = booted()
    before = read(w, register.address)
    reply = w.send(f"W{register.address:x} 1")
    if register.writable((3, 0, 4)):
        assert reply == f"W{register.address:x} A"
        assert _written(register.address), "every writable register has write cases"
    else:
        assert register.store == "none"
        assert reply == f"W{register.address:x} R"
        assert read(w, register.address) == before


@pytest.mark.parametrize(("address", "value", "reads"), WRITES)
def test_write_then_read_through_the_firmware_units(address: int, value: int, reads: int) -> None:
    w = booted()
    assert w.send(f"W{address:x} {value:x}") == f"W{address:x} A"
    assert read(w, address) == reads
    assert units.readback(codes.REGISTERS[address], value, units.FLOAT_FORMATS["pc"]) == reads


@pytest.mark.parametrize("address", [0x0E, 0x0F, 0x10])
def test_accelerations_are_read_only_constants_before_3_0_4(address: int) -> None:
    for version in ("3.0.2", "3.0.3"):
        w = booted(version)
        assert read(w, address) == codes.REGISTERS[address].default  # 800 / 200 / 500 as configured
        assert w.send(f"W{address:x} 12c") == f"W{address:x} R"


def test_eeprom_cells_survive_a_reset_and_an_erase_clears_them() -> None:
    w = booted()
    w.send("W17 c")
    w.send("W22 1a4")
    w.send("We 12c")
    w.send("X0")
    w.t += BOOTED
    assert (read(w, 0x17), read(w, 0x22), read(w, 0x0E)) == (12, 420, 799)  # RAM settings back to defaults
    w.send("X2a")
    w.t += BOOTED
    assert (read(w, 0x17), read(w, 0x22)) == (8, 360)


def test_filament_state_write_records_the_slot_as_the_firmware_does() -> None:
    w = booted()
    w.send("W7 8")
    assert w.sim.model.eeprom.slot is not None  # InNozzle: a reboot will not home
    w.send("W7 1")
    assert w.sim.model.eeprom.slot is None


# The board's arithmetic, computed independently with the platform's own IEEE single precision.
def _f32(x: float) -> float:
    return float(struct.unpack("f", struct.pack("f", x))[0])


AVR_SCALES = {0x0E: (1600, 19.147274), 0x0F: (1600, 8.0), 0x10: (3200, 360.0)}


def _avr_readback(address: int, value: int) -> int:
    steps_num, per = AVR_SCALES[address]
    spu = _f32(_f32(steps_num) / _f32(per))
    steps = int(_f32(_f32(value) * spu))
    return int(_f32(_f32(steps) * _f32(1 / spu))) & 0xFFFF


@given(address=st.sampled_from([0x0E, 0x0F, 0x10]), value=st.integers(0, 0xFFFF))
def test_board_arithmetic_matches_32_bit_floats(address: int, value: int) -> None:
    register = codes.REGISTERS[address]
    assert units.readback(register, value, units.FLOAT_FORMATS["avr"]) == _avr_readback(address, value)


@given(address=st.sampled_from([0x0E, 0x0F, 0x10]), value=st.integers(0, 0xFFFF))
def test_pc_arithmetic_loses_at_most_one_unit(address: int, value: int) -> None:
    got = units.readback(codes.REGISTERS[address], value, units.FLOAT_FORMATS["pc"])
    assert value - 1 <= got <= value
    if address == 0x0F:
        assert got == value  # 200 steps/mm is exact


def test_the_two_builds_differ_and_the_simulator_runs_either() -> None:
    pulley = codes.REGISTERS[0x0E]
    assert units.readbacks(pulley, 2500) == {2499, 2500}
    for arithmetic, reads in (("pc", 2499), ("avr", 2500)):
        w = booted(arithmetic=arithmetic)
        w.send("We 9c4")
        assert read(w, 0x0E) == reads


@given(register=st.sampled_from([r for r in codes.REGISTERS if r.store in ("u8", "u16")]),
       value=st.integers(0, 0xFFFF))
def test_plain_settings_keep_the_low_bits(register: codes.Register, value: int) -> None:
    w = booted()
    w.send(f"W{register.address:x} {value:x}")
    assert read(w, register.address) == value & ((1 << register.bits) - 1)


PC_BUILD = Path(__file__).with_name("data") / "accel_pc_build.txt"


def test_pc_arithmetic_matches_the_firmware_compiled_for_a_pc() -> None:
    rows = [line.split() for line in PC_BUILD.read_text().splitlines() if not line.startswith("#")]
    assert len(rows) > 6000
    fmt = units.FLOAT_FORMATS["pc"]
    wrong = [(a, v, r) for a, v, r in rows if units.readback(codes.REGISTERS[int(a, 16)], int(v), fmt) != int(r)]
    assert wrong == []
