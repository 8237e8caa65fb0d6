"""The build volume check counts every move the machine makes: travel, Z-only and E-only extrusion, and whole G2/G3
arcs (`gcodeinfo.REACH`), in the array reader and in the line-by-line reader alike."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.errors import InputError
from fabwire.xyz.arcwork import segments
from fabwire.xyz.gcodearrays import Ambiguous
from fabwire.xyz.gcodeinfo import REACH, MoveAnalyzer, arc_box
from fabwire.xyz.threew import convert_gcode_file

BASE = b"G28\nG1 Z0.2 F1200\nG1 X10 Y10 E1 F1500\n"

# construct -> (lines after BASE that go beyond a 150 mm machine, lines of the same kind that stay inside it)
EXAMPLES: dict[str, tuple[bytes, bytes]] = {
    "G0/G1 with X, Y or Z, extruding or not": (b"G1 X1000 Y10\n", b"G1 X140 Y10\n"),
    "G1 with Z only and E (extruding while it rises)": (b"G1 Z1000 E5\n", b"G1 Z100 E5\n"),
    "G1 with E only (extruding where the nozzle stands)": (b"G92 X1000\nG1 E5\n", b"G92 X100\nG1 E5\n"),
    "G2/G3 with I and J (centre offsets)": (b"G2 X10 Y10 I500 J0 E5\n", b"G2 X10 Y10 I20 J20 E5\n"),
    "G2/G3 with R (radius; negative for the longer way round)": (b"G2 X60 Y10 R-400 E5\n",
                                                                  b"G2 X60 Y10 R-30 E5\n"),
    "G2/G3 without I, J or R": (b"G2 X1000 Y10 E5\n", b"G2 X100 Y10 E5\n"),
    "G92 (set position)": (b"G92 X-1000\nG1 X10 E5\n", b"G92 X0\nG1 X10 E5\n"),
}


def _write(tmp_path: Path, code: bytes, indented: bool) -> Path:
    if indented:  # lines only the line-by-line reader reads
        code = b"".join(b"  " + line + b"\n" for line in code.splitlines())
    src = tmp_path / "in.gcode"
    src.write_bytes(code)
    return src


def test_every_row_has_an_example() -> None:
    assert {rule.construct for rule in REACH} == set(EXAMPLES)
    assert all(rule.source and rule.counted for rule in REACH)


@pytest.mark.parametrize("indented", [False, True], ids=["arrays", "lines"])
@pytest.mark.parametrize("rule", REACH, ids=lambda rule: rule.construct)
def test_each_construct_is_counted(tmp_path: Path, rule: object, indented: bool) -> None:
    beyond, inside = EXAMPLES[rule.construct]  # type: ignore[attr-defined]
    with pytest.raises(InputError, match=r"moves beyond the da Vinci mini w's build volume .*--force"):
        convert_gcode_file(_write(tmp_path, BASE + beyond, indented), tmp_path / "o.3w", "mini w")
    assert not (tmp_path / "o.3w").exists()
    convert_gcode_file(_write(tmp_path, BASE + inside, indented), tmp_path / "o.3w", "mini w")
    forced = convert_gcode_file(_write(tmp_path, BASE + beyond, indented), tmp_path / "f.3w", "mini w", force=True)
    assert any("converted anyway (--force)" in note for note in forced.notes)


@pytest.mark.parametrize("added", [
    b"G2 X10 Y10 I500 J0 E5\n", b"G1 X10 Y10\nG2 X60 Y10 R-400 E5\n", b"G1 Z1000 E5\n", b"G1 X1000 Y10\nG1 E5\n",
    b"G1 X1000 Y10\n", b"G3 X10 Y10 I0 J-300\n",
])
def test_the_cli_refuses_in_one_line_naming_the_extent(tmp_path: Path, added: bytes) -> None:
    src = tmp_path / "bv.gcode"
    src.write_bytes(BASE + added)
    refused = run_cli("xyz", "convert", str(src), str(tmp_path / "o.3w"), "-m", "mini w", env=cli_env())
    assert refused.returncode == 4
    assert len(refused.stderr.strip().splitlines()) == 1
    assert "150 × 150 × 150 mm" in refused.stderr
    assert "--force" in refused.stderr
    assert not (tmp_path / "o.3w").exists()


def test_a_full_circle_reaches_its_whole_diameter() -> None:
    analyzer = MoveAnalyzer()
    analyzer.feed_chunk(BASE + b"G2 X10 Y10 I500 J0 E5\n")
    (low_x, high_x), (low_y, high_y), _z = analyzer.result().extent or ()
    assert (low_x, high_x, low_y, high_y) == pytest.approx((0.0, 1010.0, -490.0, 510.0))


TINY_CHORDS = [
    # (x0, y0, x1, y1): chords so short that R over the chord is beyond a float (the centre is still R away)
    (0.0, 0.0, 0.0, 2.2250738585072014e-308), (0.0, 0.0, 5e-324, 0.0), (10.0, 10.0, 10.0, 10.000000000000002),
    (0.0, 0.0, -1e-300, 1e-300), (-50.0, 3.0, -50.0, 3.0000000000000004), (0.0, 0.0, 1e-320, -1e-320),
]


@pytest.mark.parametrize("clockwise", [False, True])
@pytest.mark.parametrize("r", [4.0, -4.0, 150.0, -0.5])
@pytest.mark.parametrize("ends", TINY_CHORDS)
def test_an_r_arc_with_a_tiny_chord_has_a_finite_box(ends: tuple[float, float, float, float], r: float,
                                                     clockwise: bool) -> None:
    x0, y0, x1, y1 = ends
    box = [float(v[0]) for v in arc_box(*(np.array([v]) for v in (x0, y0, x1, y1, math.nan, math.nan, r)),
                                        np.array([clockwise]))]
    assert all(math.isfinite(v) for v in box)
    _assert_box_holds_segments(x0, y0, x1, y1, (math.nan, math.nan, r), clockwise)


@settings(max_examples=300, deadline=None)
@given(st.floats(-200, 200), st.floats(-200, 200), st.floats(-200, 200), st.floats(-200, 200),
       st.one_of(st.tuples(st.floats(-200, 200), st.floats(-200, 200), st.just(math.nan)),
                 st.tuples(st.just(math.nan), st.just(math.nan), st.floats(-300, 300))),
       st.booleans())
@example(0.0, 0.0, 0.0, 2.2250738585072014e-308, (math.nan, math.nan, 4.0), False)
def test_the_box_holds_the_segments_written_and_no_more(x0: float, y0: float, x1: float, y1: float,
                                                         centre: tuple[float, float, float], clockwise: bool) -> None:
    i, j, r = centre
    words = {b"X": x1, b"Y": y1} | ({b"I": i, b"J": j} if math.isnan(r) else {b"R": r})
    assume(segments((x0, y0, 0.0, 0.0), words, clockwise) is not None)
    _assert_box_holds_segments(x0, y0, x1, y1, centre, clockwise)


def _assert_box_holds_segments(x0: float, y0: float, x1: float, y1: float, centre: tuple[float, float, float],
                               clockwise: bool) -> None:
    i, j, r = centre
    words = {b"X": x1, b"Y": y1} | ({b"I": i, b"J": j} if math.isnan(r) else {b"R": r})
    lines = segments((x0, y0, 0.0, 0.0), words, clockwise)
    assert lines is not None
    xs = [x0] + [float(line.split()[1][1:]) for line in lines]
    ys = [y0] + [float(line.split()[2][1:]) for line in lines]
    box = [float(v[0]) for v in arc_box(*(np.array([v]) for v in (x0, y0, x1, y1, i, j, r)), np.array([clockwise]))]
    radius = math.hypot(i, j) if math.isnan(r) else abs(r)
    slack = 1e-3 + 1e-9 * radius
    assert box[0] <= min(xs) + slack
    assert max(xs) <= box[1] + slack
    assert box[2] <= min(ys) + slack
    assert max(ys) <= box[3] + slack
    if math.isnan(r) and abs(math.hypot(x1 - x0 - i, y1 - y0 - j) - radius) > 1e-6 * (1 + radius):
        return  # an end off the start's circle: the box also holds the circle's point at the end's angle
    # the segments' corners lie on the arc, at most one step (sagitta 0.01 mm, or 1/4096 turn) from an extreme
    step = 0.05 + radius * (1 - math.cos(2 * math.pi / 4096)) + 1e-6 * radius
    assert min(xs) - box[0] <= step
    assert box[1] - max(xs) <= step
    assert min(ys) - box[2] <= step
    assert box[3] - max(ys) <= step


@pytest.mark.parametrize("arc", [b"G2 I500 J0\n", b"G3 J-400\n", b"G2 R300\n"])
def test_a_piece_of_arcs_without_axis_words_is_counted(arc: bytes) -> None:
    analyzer = MoveAnalyzer()
    analyzer.feed_chunk(BASE)
    if b"R" in arc:  # R with the same start and end point has no centre: Marlin refuses it (G2_G3.cpp)
        with pytest.raises(Ambiguous):
            analyzer.feed_chunk(arc * 3)
        return
    analyzer.feed_chunk(arc * 3)  # a piece whose only words are centre offsets or radii
    (low_x, high_x), (low_y, high_y), _z = analyzer.result().extent or ()
    assert max(high_x - low_x, high_y - low_y) >= 800
