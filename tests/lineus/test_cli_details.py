"""Details of daily use: a 3D printer's G-code told apart, stored drawings not overwritten unasked, one serial in
`info`, the robot body named in the preview legend."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from clitools import RunningSimulator, cli_env, run_cli, start_simulator
from fabwire.errors import InputError
from fabwire.lineus.plot.gcode import PRINTER_MARKERS, parse_gcode_text

# (a line only a 3D printer's G-code holds, where such files come from); one per row of PRINTER_MARKERS
PRINTER_LINES = [
    ("G1 X103.2 Y98.1 E0.0421", "PrusaSlicer / Cura perimeter move"),
    ("M104 S215 ; set temperature", "PrusaSlicer start G-code"),
    ("M140 S60", "Cura start G-code"),
    ("M83 ; extruder relative mode", "PrusaSlicer"),
    ("M106 S255", "part-cooling fan after the first layer"),
    (";FLAVOR:Marlin", "Cura's header"),
]


def test_every_marker_has_a_sample() -> None:
    assert len(PRINTER_LINES) == len(PRINTER_MARKERS)
    for pattern, _, _ in PRINTER_MARKERS:
        assert any(pattern.search(line) for line, _ in PRINTER_LINES), pattern.pattern


@pytest.mark.parametrize(("line", "source"), PRINTER_LINES, ids=[s for _, s in PRINTER_LINES])
def test_a_3d_printers_gcode_is_named_as_such(line: str, source: str) -> None:
    text = f"G28\nG1 Z0.2 F3000\n{line}\nG1 X20 Y20\n"
    with pytest.raises(InputError, match=r"is G-code for a 3D printer .*line 3.*export the design as SVG"):
        parse_gcode_text(text, name="part.gcode")


def test_line_us_gcode_with_comments_is_still_read() -> None:
    text = "; drawn by hand, no extruder here\nG28\nG01 X1000 Y0 Z0\nG01 X1200 Y0\n(E is not a move here)\n"
    assert len(parse_gcode_text(text)) == 1


def test_cli_names_a_printers_gcode_in_one_line(tmp_path: Path) -> None:
    part = tmp_path / "benchy.gcode"
    part.write_text(";FLAVOR:Marlin\nM104 S200\nG28\nG1 X10 Y10 E1\n", encoding="utf-8")
    done = run_cli("lineus", "draw", str(part), "--dry-run", env=cli_env(tmp_path))
    assert done.returncode == 4
    assert done.stderr.splitlines() == [f"fabwire: error: {part} is G-code for a 3D printer (line 1: ';FLAVOR:Marlin' "
                                        "is a 3D-printer slicer's header), not a Line-us drawing: the Line-us draws "
                                        "SVG files and its own G-code (G01 X… Y… Z…); export the design as SVG"]


@pytest.fixture(scope="module")
def sim() -> Iterator[RunningSimulator]:
    running = start_simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    yield running
    running.stop()


def test_files_save_asks_before_overwriting(sim: RunningSimulator, tmp_path: Path) -> None:
    gcode = tmp_path / "square.gcode"
    gcode.write_text("G28\nG01 X1000 Y0 Z0\nG01 X1200 Y0\n", encoding="utf-8")
    env = cli_env(tmp_path)
    where = sim.url.removeprefix("tcp://")
    first = run_cli("lineus", "-d", where, "files", "save", str(gcode), "11", env=env)  # an empty slot: no question
    assert first.returncode == 0, first.stderr
    again = run_cli("lineus", "-d", where, "files", "save", str(gcode), "11", env=env)
    assert again.returncode == 4
    assert "overwrite drawing 11 stored on the Line-us" in again.stderr
    assert "--yes" in again.stderr
    forced = run_cli("lineus", "-d", where, "files", "save", str(gcode), "11", "--yes", env=env)
    assert forced.returncode == 0, forced.stderr


def test_info_shows_one_serial(sim: RunningSimulator, tmp_path: Path) -> None:
    done = run_cli("lineus", "-d", sim.url.removeprefix("tcp://"), "info", env=cli_env(tmp_path))
    assert done.returncode == 0, done.stderr
    assert done.stdout.count("123456") == 1  # the hello's SERIAL, which M122 repeats as ChipID
    assert "serial 123456" in done.stdout.splitlines()[0]
    assert "not the serial number" in done.stdout  # M122's own 'Serial' field, named for what it is


def test_preview_legend_names_the_robot_body(tmp_path: Path) -> None:
    out = tmp_path / "preview.svg"
    done = run_cli("lineus", "text", "Hi", "--dry-run", "--preview", str(out), env=cli_env(tmp_path))
    assert done.returncode == 0, done.stderr
    assert "grey block: Line-us body" in out.read_text(encoding="utf-8")
