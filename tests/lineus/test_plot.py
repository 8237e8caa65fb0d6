"""The drawing pipeline: SVG/G-code/text in, placed and ordered strokes out, the same lines drawn."""

from __future__ import annotations

import itertools
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from fabwire.errors import InputError
from fabwire.lineus import kinematics as kin
from fabwire.lineus.plot import (
    MoveTo,
    PenDown,
    PenUp,
    PlanOptions,
    greedy_order,
    improve,
    join_touching,
    optimise,
    parse_gcode_text,
    parse_svg,
    plan_file,
    plan_lines,
    plan_text,
    text_lines,
)
from fabwire.lineus.plot.optimize import arrange, drop_fine_points, orient_runs, travel_length

sys.path.insert(0, str(Path(__file__).parent))
from test_plot_support import segments, shape_distance

DATA = Path(__file__).parent / "data" / "svg"


def arc(cx: float, cy: float, rx: float, ry: float, t0: float, t1: float, n: int = 400) -> np.ndarray:
    t = np.linspace(t0, t1, n)
    return np.column_stack([cx + rx * np.cos(t), cy + ry * np.sin(t)])


def rounded_rect(x: float, y: float, w: float, h: float, r: float) -> np.ndarray:
    parts = [
        arc(x + w - r, y + r, r, r, -math.pi / 2, 0, 50),
        arc(x + w - r, y + h - r, r, r, 0, math.pi / 2, 50),
        arc(x + r, y + h - r, r, r, math.pi / 2, math.pi, 50),
        arc(x + r, y + r, r, r, math.pi, 1.5 * math.pi, 50),
    ]
    loop = np.concatenate(parts)
    return np.vstack([loop, loop[:1]])


# Each file's drawing as independently computed page coordinates (y down).
EXPECTED = {
    "transforms.svg": [
        [(10, 10), (50, 10), (50, 50), (10, 50), (10, 10)],
        [(100, 30 - 10 * math.sqrt(2)), (100 + 10 * math.sqrt(2), 30), (100, 30 + 10 * math.sqrt(2)),
         (100 - 10 * math.sqrt(2), 30), (100, 30 - 10 * math.sqrt(2))],
        [(30, 125), (90, 125), (90, 155)],
        [(150, 150), (190, 190)],
    ],
    "use.svg": [
        [(10, 10), (50, 10), (30, 40), (10, 10)],
        [(100, 10), (140, 10), (120, 40), (100, 10)],
        [(200, 60), (160, 60), (180, 30), (200, 60)],
    ],
    "arcs.svg": [
        arc(30, 30, 20, 20, 0, 2 * math.pi),
        arc(85, 30, 25, 12, 0, 2 * math.pi),
        arc(30, 70, -20, -10, 0, math.pi),  # from (10, 70) over the top to (50, 70)
        arc(75, 70, -15, 15, 0, math.pi),  # from (60, 70) under the bottom to (90, 70)
        rounded_rect(95, 55, 20, 20, 5),
    ],
    "mixed.svg": [
        [(10, 10), (40, 10), (25, 35), (10, 10)],
        [(50, 10), (60, 30), (70, 10), (80, 30)],
        [(10, 50), (90, 50)],
        [(10, 60), (40, 60), (40, 90), (10, 90), (10, 60)],
    ],
}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_planned_strokes_match_the_file_geometry(name: str) -> None:
    plan = plan_file(DATA / name)
    expected = [np.asarray(e, dtype=float) for e in EXPECTED[name]]
    assert shape_distance(list(plan.strokes), expected) < 0.004
    for stroke in plan.strokes:
        assert kin.polyline_reachable(stroke)


def test_text_converted_to_paths_keeps_outlines_and_reports_live_text() -> None:
    drawing = parse_svg(DATA / "text_paths.svg", text="outline")
    assert drawing.skipped == {"text": 1}
    assert len(drawing.lines) == 4  # L, the O's two contours, S
    for line in drawing.lines:  # every contour closes
        assert np.allclose(line[0], line[-1])
    # By default the live text is drawn in single-stroke letters below the outlines, and named.
    drawn = parse_svg(DATA / "text_paths.svg")
    assert drawn.skipped == {}
    letters = drawn.lines[4:]
    assert len(letters) > 20
    assert all(line[:, 1].max() <= 58.5 and line[:, 0].min() >= 9.5 for line in letters)
    plan = plan_file(DATA / "text_paths.svg")
    assert any("single-stroke" in note for note in plan.notes)


def test_curves_are_flattened_within_tolerance() -> None:
    svg = '<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100"><circle cx="50" cy="50" r="40" ' \
          'stroke="black" fill="none"/></svg>'
    for tolerance in (0.5, 0.05, 0.005):
        (line,) = parse_svg(svg, tolerance=tolerance).lines
        r = np.hypot(line[:, 0] - 50, line[:, 1] - 50)
        assert np.allclose(r, 40, atol=1e-6)
        mids = (line[1:] + line[:-1]) / 2
        sag = 40 - np.hypot(mids[:, 0] - 50, mids[:, 1] - 50)
        assert sag.max() <= tolerance * 1.01
    assert len(parse_svg(svg, tolerance=0.005).lines[0]) > len(parse_svg(svg, tolerance=0.5).lines[0])


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("", "not a readable SVG"),
        ("<svg xmlns='http://www.w3.org/2000/svg'><path d='M 0 0 L 10", "not a readable SVG"),
        ("\x00\x01binary", "not a readable SVG"),
    ],
)
def test_unreadable_svg_is_an_input_error(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "bad.svg"
    path.write_text(content)
    with pytest.raises(InputError, match=message):
        plan_file(path)


def test_empty_and_missing_files_are_input_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"empty.*image"):
        plan_file(DATA / "empty.svg")
    text_only = tmp_path / "text.svg"
    text_only.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">'
                         '<text x="10" y="50">only text</text></svg>')
    assert plan_file(text_only).strokes  # drawn in single-stroke letters
    with pytest.raises(InputError, match="no such file"):
        plan_file(tmp_path / "missing.svg")
    pdf = tmp_path / "drawing.pdf"
    pdf.write_bytes(b"%PDF-1.7\n%\xe2\xe3\xcf\xd3\n")
    with pytest.raises(InputError, match=r"unknown drawing type '\.pdf'"):
        plan_file(pdf)


def random_segments_svg(rng: np.random.Generator, count: int) -> tuple[str, list[np.ndarray]]:
    """Separate lines and some chains that share ends, in a random order."""
    lines: list[np.ndarray] = []
    for _ in range(count):
        a = rng.uniform(80, 320, 2).round(2)  # every line on the page: a browser shows no more than that
        b = (a + rng.uniform(-40, 40, 2)).round(2)
        lines.append(np.array([a, b]))
        if rng.random() < 0.3:  # a second line starting where this one ends
            c = (b + rng.uniform(-30, 30, 2)).round(2)
            lines.append(np.array([b, c]) if rng.random() < 0.5 else np.array([c, b]))
    order = rng.permutation(len(lines))
    lines = [lines[i] for i in order]
    body = "".join(f'<path d="M {a[0]} {a[1]} L {b[0]} {b[1]}"/>' for a, b in lines)
    svg = (f'<svg xmlns="http://www.w3.org/2000/svg" width="400" height="400" viewBox="0 0 400 400">'
           f'<g stroke="black" fill="none">{body}</g></svg>')
    return svg, lines


def test_optimised_order_draws_exactly_the_input_and_travels_less(tmp_path: Path) -> None:
    svg, _ = random_segments_svg(np.random.default_rng(7), 600)
    path = tmp_path / "lines.svg"
    path.write_text(svg)
    as_is = plan_file(path, PlanOptions(optimize=False))
    best = plan_file(path, PlanOptions(optimize=True, time_budget=0.5))
    assert segments(best.strokes, 2) == segments(as_is.strokes, 2)
    f_as_is, f_best = as_is.figures(), best.figures()
    assert f_best.pen_down_length == pytest.approx(f_as_is.pen_down_length, rel=1e-6)
    assert f_best.pen_up_travel < 0.2 * f_as_is.pen_up_travel
    assert f_best.pen_lifts < f_as_is.pen_lifts  # touching lines were joined
    assert f_best.estimated_seconds < f_as_is.estimated_seconds


def test_improvement_never_loses_to_greedy_and_keeps_every_line() -> None:
    rng = np.random.default_rng(3)
    starts = rng.uniform(600, 1800, (800, 2))
    ends = starts + rng.normal(0, 15, (800, 2))
    order, flips = greedy_order(starts, ends)
    assert sorted(order.tolist()) == list(range(800))
    lines = [np.array([s, e]) for s, e in zip(starts, ends, strict=True)]
    greedy = travel_length(arrange(lines, order, flips))
    order2, flips2 = improve(starts, ends, order, flips, work=50_000)
    assert sorted(order2.tolist()) == list(range(800))
    improved = travel_length(arrange(lines, order2, flips2))
    assert improved < greedy * 0.95


def test_huge_path_count(tmp_path: Path) -> None:
    rng = np.random.default_rng(11)
    n = 10000
    pts = rng.uniform(0, 990, (n, 2)).round(1)
    body = "".join(f'<path d="M{x} {y}h3v2"/>' for x, y in pts)
    path = tmp_path / "huge.svg"
    path.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" width="1000" height="1000">'
                    f'<g stroke="black" fill="none">{body}</g></svg>')
    plan = plan_file(path, PlanOptions(time_budget=0.3))
    figures = plan.figures()
    assert figures.segments == 2 * n
    assert figures.strokes <= n  # a few happen to touch and are joined
    as_is = plan_file(path, PlanOptions(optimize=False))
    assert figures.pen_up_travel < 0.1 * as_is.figures().pen_up_travel


def test_fine_points_are_dropped_and_touching_lines_joined() -> None:
    line = np.array([[0.0, 0.0], [0.3, 0.0], [0.6, 0.0], [1.2, 0.0], [5.0, 0.0], [5.2, 0.1]])
    (kept,) = drop_fine_points([line], 1.0)
    assert kept.tolist() == [[0.0, 0.0], [1.2, 0.0], [5.2, 0.1]]
    a = np.array([[0.0, 0.0], [10.0, 0.0]])
    b = np.array([[20.0, 0.0], [10.0, 0.0]])  # touches a's end with its own end
    c = np.array([[0.0, 0.0], [0.0, 10.0]])  # touches a's start
    joined = join_touching([a, b, c])
    assert len(joined) == 1
    assert segments(joined) == segments([a, b, c])


def test_move_stream_and_estimate() -> None:
    plan = plan_lines([[(900, 0), (1100, 0), (1100, 200)], [(1300, 300), (1400, 300)]],
                      PlanOptions(fit=False, optimize=False))
    moves = list(plan.moves())
    assert moves == [
        MoveTo(900, 0), PenDown(), MoveTo(1100, 0), MoveTo(1100, 200), PenUp(),
        MoveTo(1300, 300), PenDown(), MoveTo(1400, 300), PenUp(),
    ]
    m = plan.motion
    expected = (
        m.move_time((1000, 1000, 1000), (900, 0, 1000)) + 4 * m.pen_time
        + m.move_time((900, 0, 0), (1100, 0, 0)) + m.move_time((1100, 0, 0), (1100, 200, 0))
        + m.move_time((1100, 200, 1000), (1300, 300, 1000)) + m.move_time((1300, 300, 0), (1400, 300, 0))
    )
    figures = plan.figures()
    assert figures.estimated_seconds == pytest.approx(expected)
    assert (figures.strokes, figures.segments, figures.pen_lifts) == (2, 3, 2)
    assert figures.pen_down_length == pytest.approx(500)
    assert figures.pen_up_travel == pytest.approx(math.hypot(100, 1000) + math.hypot(200, 100))
    assert [type(m) for m in plan.stroke_moves(1)] == [MoveTo, PenDown, MoveTo, PenUp]


def test_unfitted_drawing_outside_the_area_is_refused_or_clipped() -> None:
    lines = [[(1000, 0), (2500, 0)], [(1000, 500), (1200, 500)]]
    with pytest.raises(InputError, match=r"27\.5 mm of the 85\.0 mm drawing .* outside the reachable area"):
        plan_lines(lines, PlanOptions(fit=False))
    plan = plan_lines(lines, PlanOptions(fit=False, clip=True, optimize=False))
    assert plan.clipped == pytest.approx(550, rel=0.01)
    assert plan.figures().pen_down_length == pytest.approx(950 + 200, rel=0.01)
    assert any("clipped 27.5 mm" in note for note in plan.notes)
    with pytest.raises(InputError, match="nothing of the drawing"):
        plan_lines([[(0, 0), (100, 0)]], PlanOptions(fit=False, clip=True))
    with pytest.raises(InputError, match="not finite"):
        plan_lines([[(1000, 0), (math.inf, 0)]])


def test_fit_margin_and_rotation() -> None:
    wide = [[(0, 0), (400, 0), (400, 100), (0, 100), (0, 0)]]
    plain = plan_lines(wide, PlanOptions(margin_mm=0, optimize=False))
    x0, y0 = np.min(plain.strokes[0], axis=0)
    x1, y1 = np.max(plain.strokes[0], axis=0)
    assert (x1 - x0) / (y1 - y0) == pytest.approx(4.0, rel=1e-6)
    assert 1100 < (x1 - x0) <= 1125  # fills the app area's width (650..1775)
    assert min(x0 - 650, 1775 - x1, y0 + 1000, 1000 - y1) >= -1e-6  # inside the app area
    full = plan_lines(wide, PlanOptions(margin_mm=0, optimize=False, full_area=True))
    fx0, fx1 = np.min(full.strokes[0][:, 0]), np.max(full.strokes[0][:, 0])
    assert fx1 - fx0 > 1200  # the whole reachable area is wider than the app's
    assert kin.polyline_reachable(full.strokes[0])
    rotated = plan_lines(wide, PlanOptions(rotate_deg=90, margin_mm=0, optimize=False))
    rx0, ry0 = np.min(rotated.strokes[0], axis=0)
    rx1, ry1 = np.max(rotated.strokes[0], axis=0)
    assert (ry1 - ry0) / (rx1 - rx0) == pytest.approx(4.0, rel=1e-6)
    assert (ry1 - ry0) > (x1 - x0)  # taller than the area is wide
    margin = plan_lines(wide, PlanOptions(margin_mm=10, optimize=False))
    stroke = margin.strokes[0]
    # 10 mm around the drawing is still reachable everywhere.
    for dx, dy in ((-200, -200), (200, 200), (-200, 200), (200, -200)):
        assert kin.polyline_reachable(stroke + np.array([dx, dy]) * 0.99)
    for plan in (plain, rotated, margin):
        assert kin.polyline_reachable(plan.strokes[0])


def test_gcode_files() -> None:
    text = """; Line-us drawing
G54 X0 Y0 S1
G01 X900 Y300 Z1000
G01 X900 Y-300 Z0   (pen lands at the end of the move)
G01 X900 Y300 Z0
g1 x1200 y300
G01 Z1000
G0 X1300 Y0
G01 Z0
G01 X1400Y0 Z0
G28
M114
"""
    lines = parse_gcode_text(text)
    assert [line.tolist() for line in lines] == [
        [[900, -300], [900, 300], [1200, 300]],
        [[1300, 0], [1400, 0]],
    ]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("G91\nG01 X1 Y1", "G91 .relative positioning"),
        ("G02 X1 Y1 I1 J1", "arcs"),
        ("G01 X10 Yabc Z0", "cannot read parameters"),
        ("hello there", "cannot read"),
        ("G05 X1", "unknown command"),
    ],
)
def test_bad_gcode_is_an_input_error(text: str, message: str) -> None:
    with pytest.raises(InputError, match=message):
        parse_gcode_text(text, name="bad.gcode")


def test_gcode_out_of_range_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "far.gcode"
    path.write_text("G01 X1000 Y0 Z1000\nG01 X1000 Y0 Z0\nG01 X3000 Y0 Z0\nG01 Z1000\n")
    with pytest.raises(InputError, match="outside the reachable area"):
        plan_file(path)
    fitted = plan_file(path, PlanOptions(fit=True))
    assert all(kin.polyline_reachable(s) for s in fitted.strokes)


def test_text_in_a_single_stroke_font() -> None:
    lines = text_lines("H")
    assert len(lines) == 3  # two uprights and a bar, each drawn once
    ys = np.concatenate(lines)[:, 1]
    assert ys.min() == pytest.approx(0)
    assert ys.max() == pytest.approx(1)
    plan = plan_text("HH", size_mm=10)
    points = np.concatenate(plan.strokes)
    assert np.ptp(points[:, 1]) == pytest.approx(200)  # capitals 10 mm = 200 units tall
    assert all(kin.polyline_reachable(s) for s in plan.strokes)
    with pytest.raises(InputError, match=r"does not fit .* use --size"):
        plan_text("A long line of text", size_mm=40)
    with pytest.raises(InputError, match="unknown font"):
        plan_text("x", font="comic-sans")
    with pytest.raises(InputError, match="empty"):
        plan_text("   ")
    fitted = plan_text("two\nlines", font="scripts")
    assert all(kin.polyline_reachable(s) for s in fitted.strokes)


def test_optimise_keeps_dots_and_closed_loops() -> None:
    loop = np.array([[1000.0, 0], [1100, 0], [1100, 100], [1000, 0]])
    dot = np.array([[1200.0, 200.0]])
    out = optimise([loop, dot], time_budget=0.1)
    assert sorted(len(x) for x in out) == [1, 4]


def zigzag(x: float, y: float, count: int, mirrored: bool) -> list[np.ndarray]:
    """A hatched patch of `count` lines 10 long, 2 apart, drawn as a zig-zag starting at its left (or right)."""
    lines = [np.array([[x, y + 2 * k], [x + 10, y + 2 * k]]) for k in range(count)]
    lines = [line if k % 2 == 0 else line[::-1] for k, line in enumerate(lines)]
    return [line[::-1] for line in lines] if mirrored else lines


def turned_way(run: list[np.ndarray], way: int) -> list[np.ndarray]:
    """A run as drawn (0), backwards (1), mirrored (2) or mirrored backwards (3)."""
    ordered = run[::-1] if way in (1, 3) else run
    return [line[::-1] for line in ordered] if way in (1, 2) else list(ordered)


def test_runs_are_turned_the_best_of_four_ways_for_their_order() -> None:
    # Hatched patches drawn from awkward corners; the best of all 4^3 ways, found by trying each, is the answer.
    runs = [zigzag(0, 0, 4, mirrored=False), zigzag(12, 0, 4, mirrored=False), zigzag(4, 14, 5, mirrored=True)]
    lines = [line for run in runs for line in run]
    def travel(ways: tuple[int, ...]) -> float:
        return travel_length([line for run, way in zip(runs, ways, strict=True) for line in turned_way(run, way)],
                             (10.0, -1.0))

    best = min(travel(ways) for ways in itertools.product(range(4), repeat=3))
    assert best < min(travel(ways) for ways in itertools.product(range(2), repeat=3)) - 10  # mirroring pays
    turned = orient_runs(lines, [4, 4, 5], origin=(10.0, -1.0))
    assert segments(turned, 6) == segments(lines, 6)  # every line drawn once, either way round
    assert travel_length(turned, (10.0, -1.0)) == pytest.approx(best)
    # Runs keep their order and their lines stay together.
    assert [float(line[:, 0].min()) for line in turned] == [0.0] * 4 + [12.0] * 4 + [4.0] * 5


@pytest.mark.parametrize("seed", range(5))
def test_turning_runs_never_adds_travel(seed: int) -> None:
    rng = np.random.default_rng(seed)
    lines = [np.array([a, a + rng.normal(0, 20, 2)]) for a in rng.uniform(0, 300, (60, 2))]
    sizes = [3, 1, 7, 12, 2, 20, 15]
    turned = orient_runs(lines, sizes, origin=(0.0, 0.0))
    assert segments(turned, 6) == segments(lines, 6)
    assert travel_length(turned, (0.0, 0.0)) <= travel_length(lines, (0.0, 0.0)) + 1e-9
