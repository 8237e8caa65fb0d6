"""The estimator: PrusaSlicer's own estimate on a corpus it slices here, arcs by their length, layers from the
slicers' markers or the heights (spiral vase included), the trapezoid per move under the file's limits."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.xyz import intake, motion
from fabwire.xyz.gcodeinfo import LAYER_MARKERS, MoveAnalyzer
from fabwire.xyz.slicerfigures import read_value
from prusaslicer_corpus import CASES, Case, prusaslicer_estimate, slice_case, without_stated_figures

TOLERANCE = 0.05


@pytest.fixture(scope="module")
def corpus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("corpus")
    return {case.name: slice_case(case, folder) for case in CASES}


@pytest.mark.parametrize("case", CASES, ids=lambda case: case.name)
def test_estimate_within_five_percent_of_prusaslicer(corpus: dict[str, Path], case: Case) -> None:
    sliced = corpus[case.name].read_bytes()
    theirs = read_value(prusaslicer_estimate(sliced).encode(), "duration")
    assert theirs is not None
    bare = without_stated_figures(sliced)
    stated, computed = intake.stream_metadata(io.BytesIO(bare), case.name)
    assert stated.print_time_s is None  # nothing stated: the estimate is fabwire's own
    assert computed is not None
    assert computed.print_time_s is not None
    assert abs(computed.print_time_s - theirs) <= TOLERANCE * theirs, (computed.print_time_s, theirs)
    assert computed.layers == sliced.count(b"\n;LAYER_CHANGE\n")


def test_info_shows_the_computed_estimate(corpus: dict[str, Path], tmp_path: Path) -> None:
    case = CASES[0]
    sliced = corpus[case.name].read_bytes()
    bare = tmp_path / "bare.gcode"
    bare.write_bytes(without_stated_figures(sliced))
    done = run_cli("--json", "xyz", "info", str(bare), env=cli_env())
    info = json.loads(done.stdout)
    theirs = read_value(prusaslicer_estimate(sliced).encode(), "duration")
    assert info["sources"]["print_time_s"] == "computed"
    assert theirs is not None
    assert abs(info["print_time_s"] - theirs) <= TOLERANCE * theirs


def test_vase_layers_without_markers(corpus: dict[str, Path]) -> None:
    sliced = corpus[Case("cylinder", 0.2, "normal", vase=True).name].read_bytes()
    analyzer = MoveAnalyzer()
    analyzer.feed_chunk(sliced.replace(b";LAYER_CHANGE\n", b""))
    assert analyzer.layers == sliced.count(b"\n;LAYER_CHANGE\n")


def _circles(arcs: bool, radius: float = 20.0, turns: int = 10, sides: int = 200) -> bytes:
    lines = ["G90", "M82", "G92 E0", "G1 Z0.2 F600", f"G1 X{75 - radius} Y75 F1200"]
    e = 0.0
    for turn in range(turns):
        if arcs:
            lines.append(f"G2 X{75 - radius} Y75 I{radius} J0 E{(turn + 1) * 40:.2f} F1200")
            continue
        for k in range(1, sides + 1):
            a = math.pi - 2 * math.pi * k / sides
            e += 40 / sides
            lines.append(f"G1 X{75 + radius * math.cos(a):.4f} Y{75 + radius * math.sin(a):.4f} E{e:.4f}")
    return ("\n".join(lines) + "\n").encode()


@pytest.mark.parametrize("by_lines", [False, True])
def test_full_circle_arcs_take_as_long_as_the_circle(by_lines: bool) -> None:
    arcs, lines = MoveAnalyzer(), MoveAnalyzer()
    (arcs.feed_lines if by_lines else arcs.feed_chunk)(_circles(True))
    lines.feed_chunk(_circles(False))
    assert arcs.arcs == 10
    assert arcs.seconds == pytest.approx(lines.seconds, rel=0.02)
    assert arcs.path_seconds == pytest.approx(0.2 / 10 + math.hypot(55, 75) / 20 + 10 * 2 * math.pi * 20 / 20, rel=1e-6)


@pytest.mark.parametrize("by_lines", [False, True])
@pytest.mark.parametrize(("move", "length"), [
    pytest.param("G3 X10 Y10 I0 J10", math.pi * 10 / 2, id="quarter-ccw"),
    pytest.param("G2 X10 Y10 I0 J10", 3 * math.pi * 10 / 2, id="three-quarters-cw"),
    pytest.param("G2 X10 Y10 R10", math.pi * 10 / 2, id="radius-short-way"),
    pytest.param("G2 X10 Y10 R-10", 3 * math.pi * 10 / 2, id="radius-long-way"),
    pytest.param("G3 X0 Y0 I5 J0", 2 * math.pi * 5, id="full-circle"),
    pytest.param("G2 X20 Y0 R5", math.pi * 10, id="radius-too-small-is-the-half-circle-on-its-chord"),
    pytest.param("G2 X10 Y10", math.hypot(10, 10), id="no-centre-is-its-chord"),
    pytest.param("G3 X0 Y0 Z4 I5 J0", math.hypot(2 * math.pi * 5, 4), id="helix"),
])
def test_arc_lengths(move: str, length: float, by_lines: bool) -> None:
    analyzer = MoveAnalyzer()
    text = f"G1 X0 Y0 F600\n{move} F600\n".encode()
    (analyzer.feed_lines if by_lines else analyzer.feed_chunk)(text)
    assert analyzer.path_seconds == pytest.approx(length / 10, rel=1e-9)


EXAMPLES = [b";LAYER_CHANGE\n;Z:0.2\n", b";LAYER:0\n", b"; layer 1, Z = 0.200\n", b";; --- layer 0 (0.2)\n",
            b"; END_LAYER_OBJECT z=0.200\n"]


def test_every_marker_has_an_example() -> None:
    assert len(EXAMPLES) == len(LAYER_MARKERS)
    assert all(marker.source for marker in LAYER_MARKERS)


@pytest.mark.parametrize(("marker", "example"), list(zip(LAYER_MARKERS, EXAMPLES, strict=True)),
                         ids=[m.slicers for m in LAYER_MARKERS])
def test_layers_come_from_each_slicers_markers(marker: object, example: bytes) -> None:
    """Seven marked layers, each printed in many small rising steps (no distinct heights to count)."""
    text = b"G28\nG1 Z0.2 F600\n"
    z = 0.2
    for _ in range(7):
        text += example
        for k in range(40):
            z += 0.005
            text += b"G1 X%d Y%d Z%.3f E%d F1200\n" % (k % 2 * 10, k % 3, z, k)
    analyzer = MoveAnalyzer()
    analyzer.feed_chunk(text)
    assert analyzer.layers == 7


def test_spiral_vase_layers_from_the_rise() -> None:
    """Three flat bottom layers at 0.25 mm, then a spiral rising 0.25 mm per turn for 40 turns: 43 layers."""
    text = "G28\nM83\n"
    for k in range(3):
        text += f"G1 Z{0.25 * (k + 1):.2f}\n" + "".join(f"G1 X{x} Y{x % 7} E0.1 F1200\n" for x in range(10))
    z = 0.75
    for _turn in range(40):
        for k in range(30):
            z += 0.25 / 30
            a = 2 * math.pi * k / 30
            text += f"G1 X{50 + 20 * math.cos(a):.3f} Y{50 + 20 * math.sin(a):.3f} Z{z:.4f} E0.05\n"
    analyzer = MoveAnalyzer()
    analyzer.feed_chunk(text.encode())
    assert analyzer.layers == 43


def test_one_move_is_a_trapezoid_from_and_to_the_jerk_speed() -> None:
    analyzer = MoveAnalyzer()
    analyzer.feed_chunk(b"M201 X1000 Y1000\nM204 P1000 R1000 T1000\nM205 X8 Y8\nM203 X500 Y500\nG1 X100 F3000\n")
    v, s, a, d = 50.0, 8.0, 1000.0, 100.0
    ramp = (v * v - s * s) / (2 * a)
    assert analyzer.seconds == pytest.approx(2 * (v - s) / a + (d - 2 * ramp) / v)


def test_short_move_is_a_triangle() -> None:
    analyzer = MoveAnalyzer()
    analyzer.feed_chunk(b"M204 T100\nM205 X0.01 Y0.01\nG1 X1 F6000\n")
    assert analyzer.seconds == pytest.approx(2 * math.sqrt(1 / 100), rel=1e-3)  # half the way up, half down


@pytest.mark.parametrize(("limits", "slower"), [
    (b"M201 X200 Y200\n", True), (b"M204 P300 T300\n", True), (b"M204 S300\n", True),
    (b"M205 X1 Y1\n", True), (b"M203 X20 Y20\n", True), (b"M201 X100000 Y100000\nM204 P100000 T100000\n", False),
])
def test_the_files_limits_are_used(limits: bytes, slower: bool) -> None:
    moves = b"G28\nG1 Z0.2 F600\n" + b"".join(b"G1 X%d Y%d E%d F6000\n" % (k % 2 * 40, k % 3 * 7, k)
                                               for k in range(200))
    plain, limited = MoveAnalyzer(), MoveAnalyzer()
    plain.feed_chunk(moves)
    limited.feed_chunk(limits + moves)
    assert (limited.seconds > plain.seconds * 1.01) is slower
    assert limited.seconds >= limited.path_seconds * (0.999 if not slower else 1.0)


@pytest.mark.parametrize("limits", [b"M204 S0\n", b"M201 X0 Y-5\n", b"M205 X0 Y0 E0\n", b"M203 X0\n"])
def test_zero_limits_do_not_stop_the_machine(limits: bytes) -> None:
    analyzer = MoveAnalyzer()
    analyzer.feed_chunk(limits + b"G1 X100 Y5 F3000\nG1 X0 Y0\n")
    assert math.isfinite(analyzer.seconds)
    assert analyzer.seconds >= analyzer.path_seconds


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(0, 60_000), max_size=3))
def test_the_estimate_does_not_depend_on_how_the_file_is_cut(cuts: list[int]) -> None:
    text = b"M83\n" + b"".join(b"G1 X%d Y%d E0.1 F%d\n" % (k % 37, k % 11, 600 + k % 5 * 900)
                               for k in range(motion.WINDOW * 2 + 100))
    whole, pieces = MoveAnalyzer(), MoveAnalyzer()
    whole.feed_chunk(text)
    bounds = sorted({text.find(b"\n", c) + 1 for c in cuts} - {0, len(text)})
    for a, b in zip([0, *bounds], [*bounds, len(text)], strict=True):
        pieces.feed_chunk(text[a:b])
    assert pieces.seconds == pytest.approx(whole.seconds, rel=1e-12)



_DELTA = st.one_of(st.just(0.0), st.just(0.0), st.floats(-200, 200, allow_nan=False),
                   st.sampled_from([1e-9, -3.5, 5e-324]))


@settings(max_examples=150, deadline=None)
@given(moves=st.lists(st.tuples(_DELTA, _DELTA, _DELTA, _DELTA, st.floats(1, 20_000)), min_size=1, max_size=120),
       window=st.integers(2, 40), limits=st.lists(st.tuples(st.integers(0, 119), st.sampled_from(
           [b"M205", b"M203", b"M201"]), st.floats(0.05, 5_000)), max_size=3))
def test_an_axis_planned_only_where_it_moves_gives_the_same_time(
        moves: list[tuple[float, float, float, float, float]], window: int,
        limits: list[tuple[int, bytes, float]]) -> None:
    """Planning a rarely moving axis at its own moves only is exact: the same seconds to the last bit."""

    def plan(sparse: float) -> float:
        planner = motion.Planner()
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(motion, "WINDOW", window)
            patch.setattr(motion, "SPARSE", sparse)
            for k, (dx, dy, dz, de, feed) in enumerate(moves):
                for at, command, value in limits:
                    if at == k:
                        planner.set_limits(motion.apply_command(planner.limits, command, {b"Z": value, b"X": value}))
                columns = [np.array([v]) for v in (dx, dy, dz, de, math.sqrt(dx * dx + dy * dy + dz * dz), feed)]
                with np.errstate(all="ignore"):
                    planner.add((columns[0], columns[1], columns[2], columns[3]), columns[4], columns[5])
            with np.errstate(all="ignore"):
                return planner.total()

    times = [plan(1 / 8), plan(0.0), plan(2.0)]
    assert times[0] == times[1] == times[2] or all(math.isnan(t) for t in times)
