"""The shared formatting: one style for durations, lengths, z-offsets and MMU errors, and z-offsets typed in mm."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fabwire import units
from fabwire.errors import InputError


@pytest.mark.parametrize(("seconds", "text"), [
    (0, "0s"), (45, "45s"), (59.6, "1m 00s"), (192, "3m 12s"), (3600, "1h 00m"), (3_900, "1h 05m"),
    (None, "—"), (float("nan"), "—"), (-3, "0s")])
def test_durations(seconds: float | None, text: str) -> None:
    assert units.duration(seconds) == text


@pytest.mark.parametrize(("seconds", "text"), [
    (0.0004, "0ms"), (0.04, "40ms"), (0.9994, "999ms"), (0.9996, "1.0s"), (1.0, "1.0s"), (9.96, "10s"),
    (7.64, "7.6s"), (10, "10s"), (75, "1m 15s"),
    (None, "—"), (float("inf"), "—"), (-0.5, "0ms")])
def test_measured_times_keep_their_short_digits(seconds: float | None, text: str) -> None:
    assert units.elapsed(seconds) == text


def test_lengths_temperatures_and_codes() -> None:
    assert units.filament(51.92) == "51.9 mm"
    assert units.filament(3) == "3.0 mm"
    assert units.filament(999.94) == "999.9 mm"
    assert units.filament(999.96) == "1.00 m"
    assert units.filament(1254) == "1.25 m"
    assert units.filament(200_000) == "200.00 m"
    assert units.filament(None) == "—"
    assert units.zoffset(245) == "2.45 mm"
    assert units.zoffset(-12) == "-0.12 mm"
    assert units.temperature(210) == "210 °C"
    assert units.heating(205, 210) == "205 °C → 210 °C"
    assert units.heating(None, None) == "—"
    assert units.minutes(14) == "14 min"
    assert units.minutes(65) == "1h 05m"
    assert units.minutes(0) == "0 min"
    assert units.minutes(None) == units.ABSENT
    assert (units.count(1, "layer"), units.count(12_000, "layer"), units.count(None, "layer")) == (
        "1 layer", "12,000 layers", "? layers")
    assert units.minutes(65) == "1h 05m"
    assert units.minutes(None) == "—"
    assert units.known(0.4, " mm") == "0.4 mm"
    assert units.known(None, " mm") == "—"
    assert units.mmu_error(4101, "FINDA didn't trigger", 0x8001) == "04101 FINDA DIDN'T TRIGGER (0x8001)"
    assert units.mmu_error(None, "Communication error", 0x802E) == "COMMUNICATION ERROR (0x802E)"
    assert units.json_key("print_time", "s") == "print_time_s"


@pytest.mark.parametrize(("text", "hundredths"), [
    ("2.45mm", 245), ("2.45 mm", 245), ("2.45", 245), ("-0.12MM", -12), (".5mm", 50), ("245", 245), ("-12", -12),
    ("20mm", 2000), (" 1.006 mm ", 101)])
def test_zoffset_accepts_millimetres_and_hundredths(text: str, hundredths: int) -> None:
    assert units.parse_zoffset(text) == hundredths


@pytest.mark.parametrize("text", ["", "mm", "2,45", "2.45 cm", "1e3", "20.01mm", "-2001", "nan", "up", "٣", "2", "-5",
                                  "+9", "9" * 5000,
                                  "1." + "0" * 5000, "9" * 400 + "mm"])
def test_zoffset_refuses_anything_else(text: str) -> None:
    with pytest.raises(InputError, match="z offset"):
        units.parse_zoffset(text)


@given(st.integers(-2000, 2000))
def test_a_shown_zoffset_reads_back_to_the_same_value(hundredths: int) -> None:
    assert units.parse_zoffset(units.zoffset(hundredths)) == hundredths


@given(st.one_of(st.text(max_size=30), st.text(alphabet="0123456789.-+ m", max_size=6000)))
def test_any_typed_zoffset_is_a_value_or_an_input_error(text: str) -> None:
    try:
        value = units.parse_zoffset(text)
    except InputError:
        return
    assert -2000 <= value <= 2000
