"""The table of slicer wordings: every row read from a line as its slicer writes it, at the head or the tail of a
file of any size; the number formats; figures that are not believed."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.xyz.gcodeinfo import header_metadata
from fabwire.xyz.slicerfigures import UNREADABLE, WORDINGS, read_value, stated_figures

EXAMPLES: list[tuple[bytes, float]] = [
    (b"; print_time = 2351", 2351),
    (b"; total_filament = 1164.85", 1164.85),
    (b"; total_layers = 90", 90),
    (b"; estimated printing time (normal mode) = 1d 2h 3m 4s", 93784),
    (b"; filament used [mm] = 2031.25, 10.00", 2041.25),
    (b"; total layers count = 99", 99),
    (b"; model printing time: 1h 2m 3s; total estimated time: 1h 10m 3s", 4203),
    (b"; total filament length [mm] : 4521.07", 4521.07),
    (b"; total layer number: 120", 120),
    (b";TIME:4025", 4025),
    (b";PRINT.TIME:1834", 1834),
    (b";Filament used: 1.23456m", 1234.56),
    (b";LAYER_COUNT:50", 50),
    (b";Print time: 1 hour 23 minutes", 4980),
    (b";Layer count: 240", 240),
    (b";NUM_LAYERS: 100", 100),
    (b";   Build time: 2 hours 5 minutes", 7500),
    (b";   Filament length: 2392.5 mm (2.39 m)", 2392.5),
    (b";Print Time: 5025", 5025),
    (b";Material#1 Used: 3521.5\n;Material#2 Used: 100.5", 3622.0),
    (b"; Calculated-during-export Build Time: 12.5 minutes", 750),
    (b"; Total estimated (pre-cool) minutes: 33.25", 1995),
    (b";    Ext #1 = 1234.56 mm\n;    Ext #2 = 10.00 mm", 1244.56),
    (b"; filament used = 1234.5mm (3.0cm3)", 1234.5),
    (b"; filament_length_m = 1.75", 1750),
    (b"; filament_used = 12.5", 12.5),
    (b"; --- print time: 3600s", 3600),
    (b"; --- filament used: 1530.23 mm", 1530.23),
    (b"; estimated_print_time_s : 2710", 2710),
    (b"; filament_used_mm : 998.4", 998.4),
    (b"; layer_count : 77", 77),
]
"""One line per row of WORDINGS, in the same order, as that slicer writes it, and the figure it states."""

FIELD = {"time": "time_s", "filament": "filament_mm", "layers": "layers"}


def test_every_row_has_an_example() -> None:
    assert len(EXAMPLES) == len(WORDINGS)
    assert all(row.source for row in WORDINGS)


@pytest.mark.parametrize(("row", "example"), list(zip(WORDINGS, EXAMPLES, strict=True)),
                         ids=[f"{w.slicer}-{w.figure}-{i}" for i, w in enumerate(WORDINGS)])
@pytest.mark.parametrize("where", ["head", "tail"])
def test_each_wording_is_read_by_its_row(row: object, example: tuple[bytes, float], where: str) -> None:
    text, value = example
    windows = (text + b"\nG28\n", b"") if where == "head" else (b"G28\n", b"M84\n" + text + b"\n")
    stated = stated_figures(windows)
    assert (row.figure, row) in stated.wordings  # type: ignore[attr-defined]
    assert getattr(stated, FIELD[row.figure]) == pytest.approx(round(value) if row.figure != "filament"  # type: ignore[attr-defined]
                                                               else value)


@pytest.mark.parametrize(("text", "unit", "value"), [
    (b"1h 2m 3s", "duration", 3723), (b"2h", "duration", 7200), (b"45m 0s", "duration", 2700),
    (b"1d 0h 0m 5s", "duration", 86405), (b"2.5 hours", "duration", 9000), (b"90 minutes", "duration", 5400),
    (b"1 hour 23 minutes", "duration", 4980), (b"12 minutes 30 seconds", "duration", 750),
    (b"1:02:03", "duration", 3723), (b"3600", "duration", 3600), (b"12.5", "minutes", 750),
    (b"1.5m", "metres", 1500), (b"1m, 0.5m", "metres", 1500), (b"1.23m 3.5g", "metres", 1230),
    (b"2392.5 mm (2.39 m)", "mm", 2392.5), (b"12.3 g", "metres", None), (b"", "mm", None),
])
def test_number_formats(text: bytes, unit: str, value: float | None) -> None:
    assert read_value(text, unit) == (None if value is None else pytest.approx(value))  # type: ignore[arg-type]


@settings(max_examples=200, deadline=None)
@given(d=st.integers(0, 3), h=st.integers(0, 23), m=st.integers(0, 59), s=st.integers(0, 59),
       style=st.sampled_from(["prusa", "words", "clock", "seconds"]))
def test_durations_in_every_style(d: int, h: int, m: int, s: int, style: str) -> None:
    total = d * 86400 + h * 3600 + m * 60 + s
    text = {
        "prusa": " ".join(f"{v}{u}" for v, u in ((d, "d"), (h, "h"), (m, "m"), (s, "s")) if v) or "0s",
        "words": f"{d * 24 + h} hours {m} minutes {s} seconds",
        "clock": f"{d * 24 + h}:{m:02d}:{s:02d}",
        "seconds": str(total),
    }[style]
    assert read_value(text.encode(), "duration") == total


@settings(max_examples=200, deadline=None)
@given(mm=st.floats(0.01, 1e6, allow_nan=False).map(lambda v: round(v, 2)), metres=st.booleans(),
       minutes=st.floats(0.1, 10000).map(lambda v: round(v, 2)))
def test_lengths_in_metres_or_millimetres_and_minutes_with_decimals(mm: float, metres: bool, minutes: float) -> None:
    text = f";Filament used: {mm / 1000:.5f}m" if metres else f"; filament used [mm] = {mm:.2f}"
    got = header_metadata(text.encode() + f"\n; Calculated-during-export Build Time: {minutes} minutes\n".encode())
    assert got.filament_mm == pytest.approx(mm, abs=0.01)
    assert got.print_time_s == round(minutes * 60)


def test_grams_only_is_no_length() -> None:
    meta = header_metadata(b"; filament used [g] = 4.44\n;   Plastic weight: 12.3 g\n")
    assert meta.filament_mm is None


@pytest.mark.parametrize(("text", "figure"), [
    pytest.param(b";FLAVOR:Marlin\n;TIME:6666\n;Filament used: 0m\n;MINX:2.14748e+06\n;MAXX:-2.14748e+06\n",
                 "print time", id="curaengine-placeholders"),
    pytest.param(b";TIME:0\n", "print time", id="zero-time"),
    pytest.param(b"; filament used [mm] = 0.00\n", "filament", id="zero-filament"),
    pytest.param(b"; estimated printing time (normal mode) = 400d 1h\n", "print time", id="a-year"),
    pytest.param(b";LAYER_COUNT:0\n", "layer count", id="no-layers"),
    pytest.param(b"; total_filament = 99999999999\n", "filament", id="a-hundred-thousand-km"),
])
def test_figures_that_are_not_figures_are_set_aside(text: bytes, figure: str) -> None:
    meta = header_metadata(text + b"G28\n")
    assert None in (meta.print_time_s, meta.filament_mm, meta.layers)
    assert any(note.startswith(f"the stated {figure} is not believed") for note in meta.notes)


def _prusaslicer_file(path: Path, size: int) -> None:
    """A PrusaSlicer-style file of about `size` bytes whose figures are in its end block."""
    layer = "".join(f"G1 X{10 + i % 50}.5 Y{20 + i % 7}.25 E0.0372\n" for i in range(200))
    body, z = [], 0.2
    while sum(map(len, body)) < size:
        body.append(f";LAYER_CHANGE\n;Z:{z:.1f}\nG1 Z{z:.1f} F720\n" + layer)
        z += 0.2
    path.write_text("; generated by PrusaSlicer 2.8.1+linux-x64-GTK3 on 2024-10-05 at 14:02:11 UTC\nG28\nM83\n"
                    + "".join(body) + "M84\n; filament used [mm] = 1489.20\n; filament used [g] = 4.44\n"
                    "; estimated printing time (normal mode) = 1h 2m 3s\n\n; prusaslicer_config = begin\n"
                    "; bed_shape = 0x0,150x0,150x150,0x150\n; prusaslicer_config = end\n")


@pytest.mark.parametrize("size", [1_000, 100_000, 300_000, 1_000_000, 5_000_000])
def test_figures_at_the_end_are_read_at_every_size(tmp_path: Path, size: int) -> None:
    path = tmp_path / "part.gcode"
    _prusaslicer_file(path, size)
    done = run_cli("--json", "xyz", "info", str(path), env=cli_env())
    assert done.returncode == 0, done.stderr
    info = json.loads(done.stdout)
    assert (info["print_time_s"], info["filament_mm"]) == (3723, 1489.2)
    assert info["sources"]["print_time_s"] == info["sources"]["filament_mm"] == "stated"


def test_info_says_why_a_figure_was_computed(tmp_path: Path) -> None:
    path = tmp_path / "cli.gcode"
    path.write_bytes(b";FLAVOR:Marlin\n;TIME:6666\n;Filament used: 0m\n;MINX:2.14748e+06\n\n"
                     b";Generated with Cura_SteamEngine 5.7.1\nG28\nG1 Z0.3 F600\nG1 X10 Y10 F3000\n"
                     b"G1 X50 Y10 E2 F1200\n")
    done = run_cli("--json", "xyz", "info", str(path), env=cli_env())
    info = json.loads(done.stdout)
    assert info["sources"]["print_time_s"] == "computed"
    assert info["print_time_s"] < 100
    assert info["filament_mm"] == pytest.approx(2.0)
    assert any("placeholder" in note for note in info["notes"])
    text = run_cli("xyz", "info", str(path), env=cli_env())
    assert "CuraEngine's placeholder" in text.stdout


@pytest.mark.parametrize(("row", "example"), list(zip(WORDINGS, EXAMPLES, strict=True)),
                         ids=[f"{w.slicer}-{w.figure}-{i}" for i, w in enumerate(WORDINGS)])
@pytest.mark.parametrize("exponent", [b"e1", b"E+3", b"e-2"])
def test_each_wording_with_an_exponent_is_not_believed(row: object, example: tuple[bytes, float],
                                                        exponent: bytes) -> None:
    text = example[0].split(b"\n")[0]
    found = row.pattern.search(text)  # type: ignore[attr-defined]
    assert found is not None
    number = re.search(rb"[0-9.]+", text[found.start(1):])
    assert number is not None
    at = found.start(1) + number.end()
    meta = header_metadata(text[:at] + exponent + text[at:] + b"\nG28\n")
    figure = {"time": "print time", "filament": "filament", "layers": "layer count"}[row.figure]  # type: ignore[attr-defined]
    assert getattr(meta, {"time": "print_time_s", "filament": "filament_mm", "layers": "layers"}[
        row.figure]) is None  # type: ignore[attr-defined]
    notes = [note for note in meta.notes if note.startswith(f"the stated {figure} is not believed")]
    assert len(notes) <= 1
    assert all("exponent" in note for note in notes)


@pytest.mark.parametrize("text", [b";Filament used: 1e5m", b"; filament used [mm] = 1e5", b";TIME:1e5",
                                  b";Filament used: 2.5e1m", b";LAYER_COUNT:1e3", b";Filament used: 1e309m"])
def test_info_computes_figures_written_with_exponents(tmp_path: Path, text: bytes) -> None:
    src = tmp_path / "fh.gcode"
    src.write_bytes(text + b"\nG28\nG1 Z0.2 F1200\nG1 X10 Y10 E1 F1500\nG1 X20 Y20 E2\n")
    shown = run_cli("xyz", "info", str(src), env=cli_env())
    assert shown.returncode == 0, shown.stderr
    assert "(stated)" not in shown.stdout
    assert "exponent" in shown.stdout + shown.stderr


UNREADABLE_FORMS = {"a placeholder": [b"{print_time}", b"[used_filament]", b"%TIME%", b"<TIME>", b"$time"],
                    "a negative figure": [b"-5", b"- 12.5", b"-0.5"],
                    "digits grouped": [b"1,234", b"12,345.5", "1\u00a0234".encode(), "2\u202f500".encode(), b"1'234"],
                    "no number": [b"", b"unknown", b"n/a"]}


def test_every_unreadable_form_has_examples() -> None:
    assert {why.split(" (")[0].split(",")[0] for _form, why, _source in UNREADABLE} >= {
        "a placeholder the slicer never filled in", "a negative figure", "digits grouped by a separator",
        "a number with an exponent"}
    assert all(source for _form, _why, source in UNREADABLE)


@pytest.mark.parametrize(("row", "example"), list(zip(WORDINGS, EXAMPLES, strict=True)),
                         ids=[f"{w.slicer}-{w.figure}-{i}" for i, w in enumerate(WORDINGS)])
@pytest.mark.parametrize(("form", "value"), [(form, value) for form, values in UNREADABLE_FORMS.items()
                                             for value in values], ids=repr)
def test_each_wording_with_a_value_that_is_no_figure_is_set_aside_with_a_note(
        row: object, example: tuple[bytes, float], form: str, value: bytes) -> None:
    """Placeholders, negative figures, grouped digits and empty values are not read as figures: a wording that
    still matches says why it is set aside; one that does not (its words need a number) states nothing."""
    text = example[0].split(b"\n")[0]
    found = row.pattern.search(text)  # type: ignore[attr-defined]
    assert found is not None
    changed = text[:found.start(1)] + value  # the whole value: `2h 3m 4s` is one figure
    meta = header_metadata(changed + b"\nG28\n")
    field = {"time": "print_time_s", "filament": "filament_mm", "layers": "layers"}[row.figure]  # type: ignore[attr-defined]
    assert getattr(meta, field) is None
    figure = {"time": "print time", "filament": "filament", "layers": "layer count"}[row.figure]  # type: ignore[attr-defined]
    notes = [note for note in meta.notes if note.startswith(f"the stated {figure} is not believed")]
    if row.pattern.search(changed) is not None:  # type: ignore[attr-defined]
        assert len(notes) == 1, (changed, meta.notes)
        reason = {"a placeholder": "a placeholder the slicer never filled in", "a negative figure": "a negative figure",
                  "digits grouped": "digits grouped by a separator", "no number": "states no number"}
        assert reason[form] in notes[0], notes
    else:
        assert notes == []
