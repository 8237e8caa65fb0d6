"""One style for numbers, units and codes, shared by every command.

People read durations as `45s`, `3m 12s`, `1h 05m`; filament in metres, millimetres below one (`1.25 m`,
`51.9 mm`); the z-offset in millimetres (`2.45 mm`); temperatures as `210 °C`; an absent value as `—`; an MMU error
as its printer code, title and MMU code (`04101 FINDA DIDN'T TRIGGER (0x8001)`). JSON carries SI values with the
unit in the key: `print_time_s`, `filament_m`, `zoffset_mm`, `extruder_c`, a Line-us pen at `x_mm`, `y_mm`
(`json_key`). A device's own words and numbers as it reports them (firmware letters, the Line-us's machine units)
appear only under `raw`, `fields` or `machine_units`.
"""

from __future__ import annotations

import math
import re

from fabwire.errors import InputError, excerpt

ABSENT = "—"
ZOFFSET_LIMIT_MM = 20.0
"""The firmware's z-offset range is ±20.00 mm (sent in hundredths, ±2000)."""


def duration(seconds: float | None) -> str:
    """`45s`, `3m 12s`, `1h 05m` (seconds rounded); `—` when unknown."""
    if seconds is None or not math.isfinite(seconds):
        return ABSENT
    total = max(0, round(seconds))
    hours, rest = divmod(total, 3600)
    minutes, secs = divmod(rest, 60)
    if hours:
        return f"{hours}h {minutes:02d}m"
    return f"{minutes}m {secs:02d}s" if minutes else f"{secs}s"


def elapsed(seconds: float | None) -> str:
    """A measured time, which is often short: `40ms`, `7.6s`, then as `duration` from 10 s on."""
    if seconds is None or not math.isfinite(seconds):
        return ABSENT
    if round(seconds * 1000) < 1000:
        return f"{max(0, round(seconds * 1000))}ms"
    return f"{seconds:.1f}s" if round(seconds, 1) < 10 else duration(seconds)


def filament(mm: float | None) -> str:
    """A filament length given in mm, as slicers show it: in metres with two decimals from a metre up (`1.25 m`,
    `200.00 m`: PrusaSlicer's "Used Filament (m)", Cura's "1.25m"), in millimetres with one decimal below (`3.0 mm`,
    `51.9 mm`: PrusaSlicer's `filament used [mm]`), so a small amount never shows as `0.00 m`."""
    if mm is None:
        return ABSENT
    return f"{mm:.1f} mm" if round(mm, 1) < 1000 else f"{mm / 1000:.2f} m"


def temperature(celsius: float | None) -> str:
    return ABSENT if celsius is None else f"{celsius:g} °C"


def heating(celsius: float | None, target: float | None) -> str:
    """A temperature and the target it heads to, when there is one: `205 °C → 210 °C`."""
    return temperature(celsius) + ("" if target is None else f" → {temperature(target)}")


def minutes(whole_minutes: int | None) -> str:
    """A time a machine reports in whole minutes, without seconds it never gave: `14 min`, `1h 05m`; `—` when
    unknown."""
    if whole_minutes is None:
        return ABSENT
    return f"{max(0, whole_minutes)} min" if whole_minutes < 60 else duration(whole_minutes * 60)


def count(number: int | None, noun: str) -> str:
    """`1 layer`, `12 layers`, `? layers` when unknown (nouns with a plain plural)."""
    if number is None:
        return f"? {noun}s"
    return f"{number:,} {noun}" + ("" if number == 1 else "s")


def known(value: object, unit: str = "") -> str:
    """Any reported value as text with its unit, `—` when absent."""
    return ABSENT if value is None else f"{value}{unit}"


def zoffset(hundredths: int | None) -> str:
    """The z-offset the firmware reports in 1/100 mm, in mm: `2.45 mm`."""
    return ABSENT if hundredths is None else f"{hundredths / 100:.2f} mm"


_ZOFFSET = re.compile(r"^\s*([+-]?(?:[0-9]{1,6}(?:\.[0-9]{0,6})?|\.[0-9]{1,6}))\s*(mm)?\s*$", re.IGNORECASE)
"""ASCII digits, a few of them: int() of thousands of digits raises, and no z-offset needs more."""


def parse_zoffset(text: str) -> int:
    """A z-offset typed by a person, in the firmware's hundredths: `2.45mm`, `2.45 mm` and `2.45` are mm;
    a whole number without unit (`245`, `-12`) is hundredths, as the firmware and older fabwire take it.

    Raises InputError for anything else or outside ±20 mm.
    """
    match = _ZOFFSET.match(text)
    if not match:
        raise InputError(f"z offset must be millimetres like 2.45mm (or whole hundredths like 245), not "
                         f"{excerpt(text, 40)}")
    number, unit = match.groups()
    if not unit and "." not in number and 0 < abs(int(number)) < 10:
        # 2 is far more likely a typo for 2 mm than a wish for 0.02 mm: too close to the bed to guess
        raise InputError(f"z offset {number} is ambiguous: write {number}mm, or {int(number) / 100:.2f}mm for "
                         "hundredths")
    hundredths = round(float(number) * 100) if unit or "." in number else int(number)
    if abs(hundredths) > ZOFFSET_LIMIT_MM * 100:
        raise InputError(f"z offset {hundredths / 100:.2f} mm is outside ±{ZOFFSET_LIMIT_MM:g} mm")
    return hundredths


def mmu_error(printer_code: int | str | None, title: str, code: int) -> str:
    """An MMU error the way Prusa's printers show it: `04101 FINDA DIDN'T TRIGGER (0x8001)`."""
    prefix = "" if printer_code is None or printer_code == "" else f"{int(printer_code):05d} "
    return f"{prefix}{title.upper()} (0x{code:04X})"


def json_key(name: str, unit: str) -> str:
    """The JSON key for a quantity: its name and SI unit, `print_time` + `s` → `print_time_s`."""
    return f"{name}_{unit}"
