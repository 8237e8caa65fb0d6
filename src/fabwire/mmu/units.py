"""The MMU firmware's register conversions, bit for bit: what a write stores and what a read then answers.

Most registers keep the number written, cut to the width of the variable behind them. The axis accelerations
(0x0e-0x10, writable from 3.0.4) are kept in motor steps/s²: a write multiplies by the axis' steps per unit and
truncates to whole steps (`MMU:src/modules/axisunit.h` `unitToSteps`), a read multiplies the steps by the reciprocal
and truncates again (`axisUnitToTruncatedUnit`, called from the read lambdas in `MMU:src/registers.cpp`), so 300
mm/s² on the pulley reads back 299, and the power-on 800 mm/s² reads 799.

The arithmetic is the compiler's `long double`. On the MMU's ATmega32U4 (avr-gcc 7.3) that is a 32-bit float; a
build of the same firmware for a PC (its unit tests, the printer firmwares' host runs) uses the 80-bit x87 format.
They agree on most values and differ on some (pulley 2500 reads 2499 on a PC build, 2500 on the board), so both
are modelled (`FLOAT_FORMATS`); the simulator runs the PC build's arithmetic unless told otherwise, and a host
that checks a write accepts the answer of either.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

from fabwire.mmu.codes import Register, Store


@dataclass(frozen=True, slots=True)
class FloatFormat:
    name: str
    literal_bits: int
    """Significand bits of `double` (the literals and the steps-per-unit quotients in `config.h`)."""
    long_double_bits: int
    """Significand bits of `long double` (the run-time products)."""
    where: str


FLOAT_FORMATS = {
    "pc": FloatFormat("pc", 53, 64, "the firmware built for a PC (x86-64 gcc: double 53 bits, long double 64)"),
    "avr": FloatFormat("avr", 24, 24, "the firmware on the MMU's ATmega32U4 (avr-gcc 7.3: double = long double = "
                                      "32-bit float)"),
}
DEFAULT_FLOAT = "pc"


@dataclass(frozen=True, slots=True)
class AxisScale:
    """`MMU:src/config/config.h`: `stepsPerUnit = (full steps × microsteps / travel per turn)`."""

    steps: int
    per: str
    """The divisor as the source writes it (a `double` literal)."""


AXIS_SCALES = {
    0x0E: AxisScale(200 * 8, "19.147274"),  # pulley: MRes_8, 19.147274 mm per turn
    0x0F: AxisScale(200 * 8, "8"),  # selector: MRes_8, 8 mm lead screw
    0x10: AxisScale(200 * 16, "360"),  # idler: MRes_16, degrees
}


def round_to(x: Fraction, bits: int) -> Fraction:
    """`x` (≥ 0) rounded to the nearest number with a `bits`-bit significand, ties to even (IEEE 754)."""
    if x == 0:
        return x
    n, d = x.numerator, x.denominator
    shift = bits - n.bit_length() + d.bit_length()
    while True:
        num, den = (n << shift, d) if shift >= 0 else (n, d << -shift)
        q, r = divmod(num, den)
        if q >= 1 << bits:
            shift -= 1
        elif q < 1 << (bits - 1):
            shift += 1
        else:
            break
    if 2 * r > den or (2 * r == den and q & 1):
        q += 1
    return Fraction(q, 1 << shift) if shift >= 0 else Fraction(q << -shift)


def _scale(address: int, fmt: FloatFormat) -> tuple[Fraction, Fraction]:
    """(steps per unit, its reciprocal) as the compiler folds them for `fmt`."""
    axis = AXIS_SCALES[address]
    per = round_to(Fraction(axis.per), fmt.literal_bits)
    steps_per_unit = round_to(Fraction(axis.steps) / per, fmt.literal_bits)
    return steps_per_unit, round_to(1 / steps_per_unit, fmt.literal_bits)


def to_steps(address: int, value: int, fmt: FloatFormat) -> int:
    """`unitToSteps`: units → steps_t (uint32), truncated."""
    steps_per_unit, _ = _scale(address, fmt)
    return int(round_to(Fraction(value) * steps_per_unit, fmt.long_double_bits)) & 0xFFFF_FFFF


def from_steps(address: int, steps: int, fmt: FloatFormat) -> int:
    """`axisUnitToTruncatedUnit`: steps → int32 units, truncated, returned as the register's uint16."""
    _, reciprocal = _scale(address, fmt)
    return int(round_to(Fraction(steps) * reciprocal, fmt.long_double_bits)) & 0xFFFF


def store(register: Register, value: int, fmt: FloatFormat) -> int:
    """What the firmware keeps when `value` (uint16 from the wire) is written to `register`."""
    value &= 0xFFFF
    kind = register.store
    if kind == "accel":
        return to_steps(register.address, value, fmt)
    if kind in ("u8", "eeprom-u8", "filament", "selector"):
        return value & 0xFF
    if kind == "fsensor":
        return int(value != 0)
    if kind == "idler":
        return 5 if value >= 5 else value
    return value


def report(register: Register, kept: int, fmt: FloatFormat) -> int:
    """What a read of `register` answers while the firmware keeps `kept`."""
    kind = register.store
    if kind == "accel":
        return from_steps(register.address, kept, fmt)
    if kind == "eeprom-u8":  # `EEPROM::ReadByte(addr, default)`: an erased cell (0xff) reads as the default
        return register.default if kept == 0xFF and register.default is not None else kept
    if kind == "bowden":  # `BowdenLength::Get`: outside 341..1000 mm the default 360
        return kept if 341 <= kept <= 1000 else 360
    return kept & 0xFFFF


def readback(register: Register, value: int, fmt: FloatFormat) -> int:
    """What a read answers right after `value` was written (and any move it plans has ended)."""
    return report(register, store(register, value, fmt), fmt)


def readbacks(register: Register, value: int) -> frozenset[int]:
    """Every answer a firmware build may give after `value` was written: the host's check of a write."""
    return frozenset(readback(register, value, fmt) for fmt in FLOAT_FORMATS.values())


def boot_value(register: Register, version: tuple[int, int, int], fmt: FloatFormat) -> int | None:
    """What a read answers after power-on with an erased EEPROM (None for registers that follow the machine)."""
    if register.default is None:
        return None
    if register.store == "accel" and not register.writable(version):
        return register.default  # up to 3.0.3 the read lambda returns `config::…Limits.accel.v` as is
    return readback(register, register.default, fmt)


__all__ = ["AXIS_SCALES", "DEFAULT_FLOAT", "FLOAT_FORMATS", "FloatFormat", "Store", "boot_value", "from_steps",
           "readback", "readbacks", "report", "round_to", "store", "to_steps"]
