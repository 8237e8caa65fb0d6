"""SVG intake: a drawing plans exactly the strokes a browser shows (symbols through use, viewports, lone movetos
and dots, clip paths, hiding), curves flattened in machine units, compressed files, bounded expansion."""

from __future__ import annotations

import gzip
import math
import resource
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import svgelements as se
from hypothesis import example, given, settings
from hypothesis import strategies as st

from fabwire.errors import InputError
from fabwire.lineus.plot import PlanOptions, parse_svg, plan_drawing, plan_file, read_drawing
from fabwire.lineus.plot.svg import MAX_POINTS, MAX_USE_COPIES
from fabwire.lineus.plot.svgpath import PathBuilder, straight_path_data, straight_paths

DATA = Path(__file__).parent / "data" / "svg"
HEAD = '<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" '


def svg(body: str, attrs: str = 'width="100" height="100"') -> str:
    return f"{HEAD}{attrs}>{body}</svg>"


def lines_of(text: str) -> list[np.ndarray]:
    return parse_svg(text, tolerance=0.01).lines


def boxes(lines: list[np.ndarray]) -> list[tuple[float, float, float, float]]:
    out = []
    for line in lines:
        lo, hi = line.min(axis=0), line.max(axis=0)
        out.append(tuple(round(float(v), 6) for v in (*lo, *hi)))
    return sorted(out)


# -- symbols and use ---------------------------------------------------------------------------------------------


def test_symbol_use_maps_the_viewbox_onto_the_use_viewport() -> None:
    lines = parse_svg(DATA / "symbol_use_viewport.svg").lines
    sides = sorted((float(np.ptp(line[:, 0])) for line in lines), reverse=True)
    assert [round(s / sides[0], 3) for s in sides] == [1.0, 0.64, 0.32, 0.16, 0.08]


def test_symbols_nested_in_groups_and_used_under_transforms() -> None:
    text = svg(
        '<defs><g transform="translate(500 500)"><symbol id="sq" viewBox="0 0 10 10">'
        '<rect width="10" height="10" fill="none" stroke="black"/></symbol></g></defs>'
        '<g transform="translate(10 20)"><use href="#sq" x="5" y="5" width="20" height="20"/></g>'
        '<g transform="rotate(90)"><use xlink:href="#sq" width="10" height="10" transform="translate(0 -50)"/></g>'
        '<symbol id="outer" viewBox="0 0 2 2"><use href="#sq" width="1" height="1"/></symbol>'
        '<use href="#outer" x="60" y="60" width="40" height="40"/>'
    )
    assert boxes(lines_of(text)) == [(15.0, 25.0, 35.0, 45.0), (40.0, 0.0, 50.0, 10.0), (60.0, 60.0, 80.0, 80.0)]


def test_symbol_viewbox_aspect_and_default_size() -> None:
    # A 2:1 viewBox in a square viewport is centred (xMidYMid meet); without width/height the use is 100 %.
    text = svg('<symbol id="s" viewBox="0 0 20 10"><line x1="0" y1="5" x2="20" y2="5" stroke="black" '
               'stroke-width="0.2"/></symbol>'
               '<use href="#s" width="40" height="40"/><use href="#s" y="50"/>')
    assert boxes(lines_of(text)) == [(0.0, 20.0, 40.0, 20.0), (0.0, 100.0, 100.0, 100.0)]


def test_defs_symbols_clip_paths_and_markers_are_not_drawn_directly() -> None:
    text = svg('<defs><path d="M0 0 L10 10" stroke="black"/></defs><symbol><path d="M0 0 L5 5" stroke="black"/>'
               '</symbol><clipPath><rect width="5" height="5"/></clipPath><marker><path d="M0 0 L1 1"/></marker>'
               '<mask><rect width="9" height="9"/></mask><pattern><rect width="3" height="3"/></pattern>'
               '<path d="M20 20 L30 30" stroke="black"/>')
    assert boxes(lines_of(text)) == [(20.0, 20.0, 30.0, 30.0)]


def test_clip_path_cycles_leave_out_the_looping_reference() -> None:
    drawing = parse_svg(svg('<clipPath id="a" clip-path="url(#b)"><rect width="5" height="5"/></clipPath>'
                            '<clipPath id="b" clip-path="url(#a)"><rect width="4" height="4"/></clipPath>'
                            '<path d="M0 0 L9 9" stroke="black" clip-path="url(#a)"/>'))
    assert boxes(drawing.lines) == [(0.0, 0.0, 4.0, 4.0)]
    assert any("refers back to itself" in note for note in drawing.notes)


def test_use_cycles_leave_out_the_looping_reference_and_fanout_is_refused() -> None:
    drawing = parse_svg(svg('<g id="a"><path d="M0 0 L1 1" stroke="black"/><use href="#a"/></g>'))
    assert boxes(drawing.lines) == [(0.0, 0.0, 1.0, 1.0)]
    assert any("refers back to itself" in note for note in drawing.notes)
    body = '<defs><path id="u0" d="M0 0 L1 1" stroke="black"/>'
    for i in range(1, 25):
        body += f'<g id="u{i}"><use href="#u{i - 1}"/><use href="#u{i - 1}" transform="translate(1 0)"/></g>'
    with pytest.raises(InputError, match=f"more than {MAX_USE_COPIES:,}"):
        parse_svg(svg(body + '</defs><use href="#u24"/>'))
    # A modest fan-out is drawn in full: 2^10 copies.
    assert len(parse_svg(svg(body + '</defs><use href="#u10"/>')).lines) == 1024


def test_missing_use_target_is_reported_not_invented() -> None:
    drawing = parse_svg(svg('<use href="#nothing"/><use href="other.svg#x"/><path d="M0 0 H9" stroke="black"/>'))
    assert len(drawing.lines) == 1
    assert any("'nothing'" in note for note in drawing.notes)
    assert any("other.svg#x" in note for note in drawing.notes)


# -- movetos and zero-length subpaths ----------------------------------------------------------------------------


def test_lone_movetos_file_plans_four_strokes_without_dots() -> None:
    lines = parse_svg(DATA / "lone_movetos.svg").lines
    assert len(lines) == 4
    assert all(len(line) == 2 and np.hypot(*(line[1] - line[0])) > 100 for line in lines)


SEGMENTS = ["L 40 40", "l 30 30", "H 60", "h 30", "V 60", "v 30", "C 20 40 40 40 50 10", "c 10 30 30 30 40 0",
            "S 40 50 60 10", "s 20 40 40 0", "Q 30 50 50 10", "q 20 40 40 0", "T 70 10", "t 20 0",
            "A 20 20 0 0 1 50 10", "a 20 20 0 0 1 40 0"]


@pytest.mark.parametrize("segment", SEGMENTS)
@pytest.mark.parametrize("cap", ["butt", "round"])
def test_every_path_command_between_lone_movetos(segment: str, cap: str) -> None:
    # Lone movetos before, between and after; each is never stroked, whatever the caps.
    d = f"M 5 5 M 10 10 {segment} M 80 80 m 3 3 M 90 90"
    page = 'width="200" height="200" viewBox="-50 -50 200 200"'  # room for the arcs that bulge above y = 0
    lines = lines_of(svg(f'<path d="{d}" stroke="black" fill="none" stroke-linecap="{cap}"/>', page))
    assert len(lines) == 1
    assert len(lines[0]) >= 2
    assert np.allclose(lines[0][0], (60, 60))
    assert float(np.ptp(lines[0], axis=0).max()) > 5


@pytest.mark.parametrize(("d", "cap", "dots"), [
    ("M 10 10 Z", "butt", 0), ("M 10 10 Z", "round", 1), ("M 10 10 L 10 10", "square", 1),
    ("M 10 10 l 0 0 M 20 20 z", "round", 2), ("M 10 10 h 0 M 20 20 v 0", "butt", 0),
])
def test_zero_length_subpaths_are_dots_only_with_round_or_square_caps(d: str, cap: str, dots: int) -> None:
    lines = lines_of(svg(f'<path d="{d}" stroke="black" stroke-linecap="{cap}"/>'))
    assert len(lines) == dots
    assert all(len(line) == 1 for line in lines)
    # Filled but unstroked: nothing to see at all.
    assert lines_of(svg(f'<path d="{d}" fill="black" stroke-linecap="{cap}"/>')) == []


def test_dots_keep_their_place_and_do_not_stretch_the_fit() -> None:
    text = svg('<path d="M 0 0 Z M 90 90 Z" stroke="black"/><path d="M 40 40 L 60 60" stroke="black"/>')
    plan_lines = parse_svg(text).lines
    assert boxes(plan_lines) == [(40.0, 40.0, 60.0, 60.0)]


# -- hiding ------------------------------------------------------------------------------------------------------


def test_display_visibility_opacity_and_paint_hide_as_in_a_browser() -> None:
    text = svg(
        '<style>.gone{display:none} .ink{stroke:black;fill:none}</style>'
        '<g display="none"><path d="M0 0 H10" stroke="black"/></g>'
        '<g style="visibility:hidden"><path d="M0 10 H10" stroke="black"/>'
        '<path d="M0 20 H10" stroke="black" visibility="visible"/></g>'
        '<g opacity="0"><path d="M0 30 H10" stroke="black"/></g>'
        '<path d="M0 40 H10" stroke="none" fill="none"/>'
        '<path d="M0 50 H10" stroke="black" stroke-opacity="0" fill="none"/>'
        '<path d="M0 60 H10" stroke="rgba(0,0,0,0)" fill="none"/>'
        '<path d="M0 70 H10" stroke="black" stroke-width="0" fill="none"/>'
        '<path class="gone ink" d="M0 80 H10"/>'
        '<path class="ink" d="M0 90 H10"/>'
        '<path d="M0 95 H10" stroke="black" opacity="0.5"/>'
    )
    assert sorted(float(line[0, 1]) for line in lines_of(text)) == [20.0, 90.0, 95.0]


# -- clip paths --------------------------------------------------------------------------------------------------


def test_clip_path_file_keeps_hatching_inside_the_frame() -> None:
    drawing = read_drawing(DATA / "clip_hatching.svg")
    xs = np.concatenate(drawing.lines)[:, 0]
    assert xs.max() <= 650 + 20 * 20 + 1e-3  # the 20 mm frame at real size
    assert sum(np.ptp(h[:, 0]) for h in drawing.hidden) == pytest.approx(3 * 15 * 20, rel=1e-6)


def test_clip_paths_on_groups_with_transforms() -> None:
    text = svg(
        '<clipPath id="c"><rect x="0" y="0" width="10" height="10"/></clipPath>'
        '<clipPath id="t" transform="translate(50 0)"><rect width="10" height="100"/></clipPath>'
        '<g transform="translate(20 0) scale(2)" clip-path="url(#c)"><path d="M -5 5 H 30" stroke="black"/></g>'
        '<g clip-path="url(#t)"><path d="M 0 50 H 100" stroke="black"/></g>'
        '<path d="M 0 5 H 100" stroke="black" clip-path="url(#c)" transform="translate(45 60)"/>',
        'width="200" height="200"')
    assert boxes(lines_of(text)) == [(20.0, 10.0, 40.0, 10.0), (45.0, 65.0, 55.0, 65.0), (50.0, 50.0, 60.0, 50.0)]


def test_clip_rules_bounding_box_units_and_nesting() -> None:
    donut = "M 0 0 H 100 V 100 H 0 Z M 25 25 H 75 V 75 H 25 Z"
    text = svg(
        f'<clipPath id="even"><path d="{donut}" clip-rule="evenodd"/></clipPath>'
        '<clipPath id="box" clipPathUnits="objectBoundingBox"><rect x="0.5" y="0" width="0.5" height="1"/></clipPath>'
        '<clipPath id="left"><rect width="50" height="200"/></clipPath>'
        '<path d="M 0 50 H 100" stroke="black" clip-path="url(#even)"/>'
        '<path d="M 0 150 H 100 V 160" stroke="black" fill="none" clip-path="url(#box)"/>'
        '<g clip-path="url(#left)"><path d="M 0 180 H 100" stroke="black" clip-path="url(#box)"/></g>',
        'width="200" height="200"')
    assert boxes(lines_of(text)) == [(0.0, 50.0, 25.0, 50.0), (50.0, 150.0, 100.0, 160.0), (75.0, 50.0, 100.0, 50.0)]


def test_clip_that_cannot_be_found_is_reported() -> None:
    drawing = parse_svg(svg('<path d="M0 0 H10" stroke="black" clip-path="url(#none)"/>'))
    assert len(drawing.lines) == 1
    assert any("clip-path" in note for note in drawing.notes)


@settings(max_examples=40, deadline=None)
@given(st.floats(-60, 60), st.floats(-60, 60), st.floats(0, 180), st.floats(0.2, 3))
def test_clipped_lines_stay_inside_the_clip_under_any_transform(dx: float, dy: float, angle: float,
                                                                 s: float) -> None:
    text = svg(f'<clipPath id="c"><circle cx="50" cy="50" r="30"/></clipPath>'
               f'<g transform="translate({dx} {dy}) rotate({angle} 50 50) scale({s})" clip-path="url(#c)">'
               '<path d="M -200 40 H 300 M -200 60 H 300 M 50 -200 V 300" stroke="black"/></g>',
               'width="100" height="100"')
    drawing = parse_svg(text, tolerance=0.01)
    # The clip circle is in the group's user space: map the kept points back through the group's transform.
    a = math.radians(angle)
    for line in drawing.lines:
        centre = np.array([50.0, 50.0])
        p = line - np.array([dx, dy]) - centre
        turned = np.column_stack([p[:, 0] * math.cos(a) + p[:, 1] * math.sin(a),
                                  -p[:, 0] * math.sin(a) + p[:, 1] * math.cos(a)])
        back = (turned + centre) / s
        assert (np.hypot(back[:, 0] - 50, back[:, 1] - 50) <= 30 + 1e-3 / s + 1e-6).all()


# -- viewports and flattening ------------------------------------------------------------------------------------


@pytest.mark.parametrize(("aspect", "expected"), [
    ("xMidYMid meet", [(25.0, 0.0, 75.0, 100.0)]), ("xMinYMin meet", [(0.0, 0.0, 50.0, 100.0)]),
    ("none", [(0.0, 0.0, 100.0, 100.0)]),
    ("xMidYMid slice", [(0.0, 0.0, 0.0, 100.0), (100.0, 0.0, 100.0, 100.0)]),  # top and bottom overflow the page
])
def test_viewbox_maps_onto_the_viewport(aspect: str, expected: list[tuple[float, ...]]) -> None:
    text = svg('<rect width="10" height="20" stroke="black" stroke-width="0.1" fill="none"/>',
               f'width="100" height="100" viewBox="0 0 10 20" preserveAspectRatio="{aspect}"')
    assert boxes(lines_of(text)) == expected


@pytest.mark.parametrize("page_mm", [(105, 148), (210, 297), (297, 420), (841, 1189), (20, 20)])
def test_chord_error_on_paper_is_at_most_005_mm_for_any_page(tmp_path: Path, page_mm: tuple[int, int]) -> None:
    w, h = page_mm
    path = tmp_path / "small.svg"
    path.write_text(svg(f'<circle cx="{w / 2}" cy="{h / 2}" r="2" fill="none" stroke="black" '
                        f'stroke-width="0.1"/><path d="M {w / 2 - 3} {h / 2} q 3 -6 6 0" fill="none" '
                        'stroke="black" stroke-width="0.1"/>',
                        f'width="{w}mm" height="{h}mm" viewBox="0 0 {w} {h}"'))
    plan = plan_file(path, PlanOptions(optimize=False))
    circle = max(plan.strokes, key=len)
    centre = (circle.max(axis=0) + circle.min(axis=0)) / 2
    radius = float(np.hypot(*(circle - centre).T).max())
    mids = (circle[1:] + circle[:-1]) / 2
    error = radius - np.hypot(*(mids - centre).T)
    assert radius > 300  # fitted large: the 4 mm circle is enlarged
    assert error.max() <= 1.0  # machine units: 0.05 mm


def test_unfitted_curves_are_flattened_in_machine_units(tmp_path: Path) -> None:
    path = tmp_path / "circle.svg"
    path.write_text(svg('<circle cx="20" cy="20" r="15" fill="none" stroke="black"/>',
                        'width="40mm" height="40mm" viewBox="0 0 40 40"'))
    plan = plan_file(path, PlanOptions(fit=False, optimize=False))
    (circle,) = plan.strokes
    centre = (650 + 20 * 20, 1000 - 20 * 20)
    mids = (circle[1:] + circle[:-1]) / 2
    assert (300 - np.hypot(mids[:, 0] - centre[0], mids[:, 1] - centre[1])).max() <= 1.0


# -- compressed and piped drawings ------------------------------------------------------------------------------


def test_compressed_svg_reads_like_the_plain_file(tmp_path: Path) -> None:
    plain = read_drawing(DATA / "transforms.svg")
    packed = tmp_path / "transforms.svgz"
    packed.write_bytes(gzip.compress((DATA / "transforms.svg").read_bytes()))
    unpacked = read_drawing(packed)
    assert len(unpacked.lines) == len(plain.lines)
    assert all(np.allclose(a, b) for a, b in zip(unpacked.lines, plain.lines, strict=True))
    square = read_drawing(DATA / "compressed.svgz")
    assert len(square.lines) == 1
    assert len(square.lines[0]) == 5


def test_broken_compressed_files_are_input_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad.svgz"
    bad.write_bytes(gzip.compress(b"<svg xmlns='http://www.w3.org/2000/svg'><path d='M0 0 L1 1'/></svg>")[:30])
    with pytest.raises(InputError, match="gzip"):
        read_drawing(bad)
    junk = tmp_path / "junk.svgz"
    junk.write_bytes(gzip.compress(b"\x00\x01\x02 not xml"))
    with pytest.raises(InputError, match="not a readable SVG"):
        read_drawing(junk)


def test_unsupported_features_are_named() -> None:
    drawing = parse_svg(svg('<mask id="m"><rect width="5" height="5" fill="white"/></mask>'
                            '<path d="M0 0 H10" stroke="black" mask="url(#m)"/>'
                            '<path d="M0 5 H10" stroke="black" filter="url(#blur)"/>'
                            '<style>g &gt;&gt; path { stroke: red }</style>'))
    assert len(drawing.lines) == 2
    text = " ".join(drawing.notes)
    assert "mask" in text
    assert "filter" in text
    assert "g >> path" in text


# -- hostile files -----------------------------------------------------------------------------------------------

HOSTILE = {
    "deep nesting": svg("<g>" * 3000 + '<path d="M0 0 L1 1" stroke="black"/>' + "</g>" * 3000),
    "long use chain": svg('<defs><path id="u0" d="M0 0 L1 1" stroke="black"/>'
                          + "".join(f'<use id="u{i}" href="#u{i - 1}"/>' for i in range(1, 1000))
                          + '</defs><use href="#u999"/>'),
    "clip chain": svg("".join(f'<clipPath id="c{i}" clip-path="url(#c{i + 1})"><rect width="50" height="50"/>'
                              "</clipPath>" for i in range(3000))
                      + '<path d="M0 0 L9 9" stroke="black" clip-path="url(#c0)"/>'),
    "entity expansion": '<?xml version="1.0"?><!DOCTYPE s [<!ENTITY a "aaaaaaaaaa">'
                        + "".join(f'<!ENTITY {n} "{("&" + p + ";") * 10}">' for p, n in zip("abcdef", "bcdefg",
                                                                                             strict=True))
                        + f']>{HEAD}><title>&g;</title></svg>',
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_hostile_structures_are_refused_with_a_reason(name: str) -> None:
    with pytest.raises(InputError, match=r"SVG text: \S"):
        parse_svg(HOSTILE[name])


@pytest.mark.parametrize(("body", "note"), [
    (f'<path d="M0 0 L{"9" * 5000} 1" stroke="black"/>', "a number beyond what a browser can hold"),
    ('<g transform="scale(1e38 1e-38)">' * 8 + '<path d="M0 0 L1e38 1" stroke="black"/>' + "</g>" * 8,
     "not finite"),
])
def test_numbers_no_viewer_can_place_are_left_out_and_named(body: str, note: str) -> None:
    drawing = parse_svg(svg(body + '<path d="M0 50 H9" stroke="black"/>'))
    assert len(drawing.lines) == 1
    assert any(note in n for n in drawing.notes)


@settings(max_examples=150, deadline=None)
@given(st.text(alphabet="MmLlHhVvCcSsQqTtAaZz0123456789.-+eE ,", max_size=60),
       st.sampled_from(["", 'transform="rotate(30) scale(2 0)"', 'stroke-linecap="round"', 'clip-path="url(#c)"']))
def test_any_path_data_reads_or_is_refused_cleanly(d: str, extra: str) -> None:
    text = svg(f'<clipPath id="c"><circle cx="50" cy="50" r="40"/></clipPath><path d="{d}" stroke="black" {extra}/>')
    try:
        drawing = parse_svg(text)
    except InputError:
        return
    for line in drawing.lines:
        assert np.isfinite(line).all()
        assert len(line) >= 1


def test_switch_draws_its_first_qualifying_child() -> None:
    text = svg('<switch><foreignObject requiredExtensions="http://www.w3.org/1999/xhtml"><p>x</p></foreignObject>'
               '<path d="M0 0 H10" stroke="black"/><path d="M0 5 H10" stroke="black"/></switch>')
    drawing = parse_svg(text)
    assert boxes(drawing.lines) == [(0.0, 0.0, 10.0, 0.0)]
    assert drawing.skipped == {}


def test_memory_follows_the_geometry(tmp_path: Path) -> None:
    # A long generated path: reading and planning hold a few hundred bytes per segment at most, not kilobytes.
    count = 20_000
    path = tmp_path / "long.svg"
    steps = " ".join(f"L{i % 100} {(i * 7) % 100}" for i in range(count))
    path.write_text(svg(f'<path d="M0 0 {steps}" stroke="black" fill="none"/>'))
    tracemalloc.start()
    try:
        drawing = read_drawing(path)
        read_peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.reset_peak()
        plan_drawing(drawing, PlanOptions(time_budget=0.05))
        plan_peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert read_peak / count < 400
    assert plan_peak / count < 400


@st.composite
def straight_command(draw: st.DrawFn) -> tuple[str, list[int]]:
    """A straight-line path command, mostly with the right count of numbers, sometimes not."""
    letter = draw(st.sampled_from("MmLlHhVvZz"))
    arity = {"m": 2, "l": 2, "h": 1, "v": 1, "z": 0}[letter.lower()]
    size = arity * draw(st.integers(1, 3)) if draw(st.integers(0, 9)) else draw(st.integers(0, 5))
    return letter, draw(st.lists(st.integers(-50, 50), min_size=size, max_size=size))


@settings(max_examples=300, deadline=None)
@given(st.lists(straight_command(), min_size=1, max_size=40), st.sampled_from([" ", ",", " , ", "\n"]),
       st.booleans())
def test_straight_path_reader_agrees_with_the_general_one(commands: list[tuple[str, list[int]]], sep: str,
                                                          tidy: bool) -> None:
    if tidy:  # what generators write: a fresh absolute moveto after every closepath
        commands = [part for c in commands for part in ([c, ("M", [4, 8])] if c[0] in "Zz" else [c])]
    d = " ".join(f"{c}{sep.join(str(v / 4) for v in values)}" for c, values in commands)
    d = d + " " * max(0, 300 - len(d))  # long enough to take the array route
    matrix = np.array([[2.0, 0.5, 3.0], [-0.5, 1.5, 7.0]])
    fast = PathBuilder(matrix, 0.1)
    taken = straight_path_data(fast, d)
    general = PathBuilder(matrix, 0.1)
    try:
        se.SVGLexicalParser().parse(general, d)
        general.end()
    except ValueError:
        general.subpaths = []
        assert not taken or fast.subpaths == []
        return
    if not taken:
        return
    assert len(fast.subpaths) == len(general.subpaths)
    for a, b in zip(fast.subpaths, general.subpaths, strict=True):
        assert a.closed == b.closed
        assert a.segments == b.segments
        assert np.allclose(a.points, b.points)


def test_straight_path_reader_takes_generated_paths() -> None:
    d = "M0 0 " + " ".join(f"L{i % 100} {(i * 7) % 100}" for i in range(500)) + " Z M 5 5 h 10 v -3.5e1 l-2-2z"
    builder = PathBuilder(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), 0.1)
    assert straight_path_data(builder, d)
    first, second = builder.subpaths
    assert first.closed
    assert first.segments == 501
    assert np.allclose(second.points, [(5, 5), (15, 5), (15, -30), (13, -32), (5, 5)])


# -- viewports of size zero ------------------------------------------------------------------------------------

LINE = '<path d="M10 10 L90 90" stroke="black"/>'


@pytest.mark.parametrize("attrs", ['width="0" height="100"', 'width="100" height="0px"', 'width="0" height="0"',
                                   'width="100" height="100" viewBox="0 0 0 100"',
                                   'width="100" height="100" viewBox="0,0,100,0"', 'viewBox="0 0 0 0"'])
def test_a_root_viewport_of_size_zero_shows_nothing(attrs: str) -> None:
    drawing = parse_svg(svg(LINE, attrs))
    assert drawing.lines == []
    assert drawing.empty_reason.endswith(" is 0, which disables rendering: a browser shows nothing")


@pytest.mark.parametrize("inner", ['<svg width="0">' + LINE + '</svg>', '<svg viewBox="0 0 100 0">' + LINE + "</svg>",
                                   '<symbol id="s" viewBox="0 0 0 10">' + LINE + '</symbol><use xlink:href="#s"/>',
                                   '<symbol id="s">' + LINE + '</symbol><use xlink:href="#s" height="0"/>'])
def test_a_nested_viewport_of_size_zero_shows_nothing_and_the_rest_stays(inner: str) -> None:
    lines = lines_of(svg(inner + '<path d="M10 90 L90 10" stroke="black"/>'))
    assert boxes(lines) == [(10.0, 10.0, 90.0, 90.0)]
    assert lines[0][0].tolist() == [10.0, 90.0]


def test_a_negative_size_is_an_error_and_ignored_as_browsers_do() -> None:
    assert len(lines_of(svg(LINE, 'width="-5" height="100"'))) == 1


@settings(max_examples=150, deadline=None)
@given(st.lists(st.lists(straight_command(), min_size=1, max_size=12), min_size=2, max_size=8),
       st.sampled_from([" ", ","]))
def test_paths_read_together_match_each_read_alone(paths: list[list[tuple[str, list[int]]]], sep: str) -> None:
    ds = ["M 3 4 " + " ".join(f"{c}{sep.join(str(v * 2.5) for v in values)}" for c, values in commands)
          for commands in paths]
    together = straight_paths(ds)
    alone = []
    for d in ds:
        builder = PathBuilder(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), 0.1)
        alone.append(builder.subpaths if straight_path_data(builder, d) else None)
    if together is None:  # refused whole when any one is not for the straight reader
        assert None in alone
        return
    assert None not in alone
    for mine, theirs in zip(together, alone, strict=True):
        assert [(s.closed, s.segments) for s in mine] == [(s.closed, s.segments) for s in theirs or []]
        for a, b in zip(mine, theirs or [], strict=True):
            assert np.array_equal(a.points, b.points)


def test_many_short_paths_under_their_own_transforms_read_as_one_by_one() -> None:
    body = "".join(f'<path d="M{i} 0 L{i} 10 h2 V{i % 7} Z" transform="rotate({i * 7} 50 50)" stroke="black" '
                   'fill="none"/>'
                   for i in range(40))
    body += '<path d="M5 5 l1e7 0" stroke="black"/><path d="M1 1 q 5 5 10 0" stroke="black" fill="none"/>'
    drawing = parse_svg(svg(body, 'width="300" height="300" viewBox="-100 -100 300 300"'), tolerance=0.01)
    assert len(drawing.lines) == 42
    for i, line in enumerate(drawing.lines[:40]):
        a = math.radians(i * 7)
        rotate = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        user = np.array([[i, 0], [i, 10], [i + 2, 10], [i + 2, i % 7], [i, 0]], dtype=float)
        assert np.allclose(line, (user - 50) @ rotate.T + 150)


@settings(max_examples=100, deadline=None)
@given(st.tuples(st.sampled_from(["a", "html", "é", "svg-"]), st.integers(1, 20_000)).map(lambda t: t[0] * t[1]))
@example("a" * 10_000)
def test_a_root_that_is_not_svg_is_named_in_one_short_line(tag: str) -> None:
    with pytest.raises(InputError, match="not <svg>") as caught:
        parse_svg(f"<{tag}/>".encode())
    assert len(str(caught.value)) <= 160


CURVE_FLOODS = [  # a few bytes of path data whose curves would flatten into millions of points
    ("arcs of a huge radius", "A1e9 1e9 0 1 1 {x} {y}"),
    ("cubic curves with far control points", "C1e9 -1e9 -1e9 1e9 {x} {y}"),
    ("quadratic curves with a far control point", "Q1e9 1e9 {x} {y}"),
]


@pytest.mark.parametrize(("what", "command"), CURVE_FLOODS, ids=[row[0] for row in CURVE_FLOODS])
def test_curves_that_flatten_past_the_drawings_points_are_refused_as_they_are_read(what: str, command: str) -> None:
    """Each curve is held to the points the drawing has left (`MAX_POINTS`) while it is flattened, so memory
    stays bounded by the bound, not by what the file asks for."""
    d = "M0 0 " + " ".join(command.format(x=i % 100, y=(i * 7) % 100) for i in range(2_000))
    started = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(InputError, match=f"its curves make more than {MAX_POINTS:,} points"):
        parse_svg(svg(f'<path d="{d}" fill="none" stroke="black"/>'))
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - started < 1_000_000  # KiB: far below a GB


def test_a_basic_shape_clips_and_one_in_error_is_named_and_left_out() -> None:
    square = '<rect width="100" height="100" clip-path="{}"/>'
    drawing = parse_svg(svg(square.format("circle(20px at 50px 50px)")))
    points = np.concatenate(drawing.lines)
    assert np.allclose(np.hypot(points[:, 0] - 50, points[:, 1] - 50), 20, atol=0.01)
    drawing = parse_svg(svg(square.format("circle(-5px)")))
    assert boxes(drawing.lines) == [(0.0, 0.0, 100.0, 100.0)]
    assert any("circle(-5px)" in note and "in error" in note for note in drawing.notes)


def test_a_gradient_hides_what_lies_under_it_only_when_all_its_stops_are_opaque() -> None:
    def drawn(stops: str) -> list[tuple[float, float, float, float]]:
        body = (f'<linearGradient id="g">{stops}</linearGradient><path d="M0 50 H100" stroke="black"/>'
                '<rect x="40" y="0" width="20" height="100" fill="url(#g)"/>')
        return boxes(parse_svg(svg(body)).lines)

    opaque = '<stop offset="0" stop-color="red"/><stop offset="1" style="stop-color: blue"/>'
    translucent = '<stop offset="0" stop-color="red"/><stop offset="1" stop-color="blue" stop-opacity="0.5"/>'
    assert (0.0, 50.0, 40.0, 50.0) in drawn(opaque)
    assert (0.0, 50.0, 100.0, 50.0) not in drawn(opaque)
    assert (0.0, 50.0, 100.0, 50.0) in drawn(translucent)


def test_a_clipped_opaque_fill_hides_only_what_shows_of_it() -> None:
    body = ('<path d="M0 50 H100" stroke="black"/><clipPath id="c"><rect x="40" y="0" width="20" height="100"/>'
            '</clipPath><g clip-path="url(#c)"><rect width="100" height="100"/></g>')
    assert (0.0, 50.0, 40.0, 50.0) in boxes(parse_svg(svg(body)).lines)
    assert (60.0, 50.0, 100.0, 50.0) in boxes(parse_svg(svg(body)).lines)
    assert (0.0, 50.0, 100.0, 50.0) not in boxes(parse_svg(svg(body)).lines)
