"""The area a wide stroke paints, and wide strokes in SVG drawn as the border of that area."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fabwire.lineus.plot import parse_svg
from fabwire.lineus.plot.stroke import Pen, pen_of, stroke_area

CORNER = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0]])
"""A right-angle turn: the miter tip of a 20-wide stroke lies at (110, -10), miter ratio sqrt(2)."""


def test_a_miter_within_the_limit_reaches_its_tip() -> None:
    area = stroke_area([(CORNER, False)], Pen(10.0, join="miter", miter_limit=4.0))
    assert area.bounds == pytest.approx((0.0, -10.0, 110.0, 100.0))
    assert area.area == pytest.approx(100 * 20 + 90 * 20 + 100 + 100, rel=1e-9)  # two arms and the square corner


def test_a_miter_past_the_limit_is_beveled() -> None:
    area = stroke_area([(CORNER, False)], Pen(10.0, join="miter", miter_limit=1.4))
    assert area.area == pytest.approx(100 * 20 + 90 * 20 + 100 + 50, rel=1e-9)  # the corner's outer triangle only


def test_caps_extend_open_ends() -> None:
    line = np.array([[0.0, 0.0], [100.0, 0.0]])
    assert stroke_area([(line, False)], Pen(5.0, cap="butt")).bounds == pytest.approx((0, -5, 100, 5))
    assert stroke_area([(line, False)], Pen(5.0, cap="square")).bounds == pytest.approx((-5, -5, 105, 5))
    rounded = stroke_area([(line, False)], Pen(5.0, cap="round", tolerance=0.01)).area
    assert 1000 + math.pi * 4.99 ** 2 <= rounded <= 1000 + math.pi * 25


def test_a_point_is_a_dot_for_round_and_square_caps_only() -> None:
    dot = np.array([[10.0, 10.0], [10.0, 10.0]])
    assert stroke_area([(dot, False)], Pen(4.0, cap="butt")).is_empty
    assert stroke_area([(dot, False)], Pen(4.0, cap="square")).area == pytest.approx(64)
    disc = stroke_area([(dot, False)], Pen(4.0, cap="round", tolerance=0.01)).area
    assert math.pi * 3.99 ** 2 <= disc <= math.pi * 16  # chords within the tolerance of the circle


def test_a_closed_line_joins_all_round_and_leaves_a_hole() -> None:
    square = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0], [0.0, 0.0]])
    area = stroke_area([(square, True)], Pen(10.0, cap="round"))
    assert area.bounds == pytest.approx((-10, -10, 110, 110))
    assert area.area == pytest.approx(120 * 120 - 80 * 80)


def test_pen_of_reads_the_style_and_takes_initial_values_for_errors() -> None:
    assert pen_of({"stroke-linecap": "round", "stroke-linejoin": "bevel", "stroke-miterlimit": "2"}, 3.0, 0.1) \
        == Pen(3.0, "round", "bevel", 2.0, 0.1)
    assert pen_of({"stroke-linecap": "x", "stroke-linejoin": "miter-clip", "stroke-miterlimit": "0.5"}, 3.0, 0.1) \
        == Pen(3.0, "butt", "miter", 4.0, 0.1)


def svg(body: str) -> str:
    return f'<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200">{body}</svg>'


def test_a_wide_stroke_is_drawn_as_the_border_of_its_band() -> None:
    lines = parse_svg(svg('<rect x="50" y="50" width="100" height="100" fill="none" stroke="black" '
                          'stroke-width="20"/>')).lines
    boxes = sorted(tuple(np.round([*line.min(axis=0), *line.max(axis=0)], 6).tolist()) for line in lines)
    assert boxes == [(40.0, 40.0, 160.0, 160.0), (60.0, 60.0, 140.0, 140.0)]


def test_a_thin_stroke_is_drawn_along_its_centre_line() -> None:
    lines = parse_svg(svg('<rect x="50" y="50" width="100" height="100" fill="none" stroke="black" '
                          'stroke-width="5"/>')).lines
    assert [(line.min(axis=0).tolist(), line.max(axis=0).tolist()) for line in lines] == [([50, 50], [150, 150])]


def test_a_wide_stroke_and_its_fill_are_one_shape_and_hide_what_lies_under_them() -> None:
    lines = parse_svg(svg('<path d="M0 100 H200" stroke="black"/><rect x="50" y="50" width="100" height="100" '
                          'fill="gray" stroke="black" stroke-width="20"/>')).lines
    boxes = sorted(tuple(np.round([*line.min(axis=0), *line.max(axis=0)], 6).tolist()) for line in lines)
    assert boxes == [(0.0, 100.0, 40.0, 100.0), (40.0, 40.0, 160.0, 160.0), (160.0, 100.0, 200.0, 100.0)]


def test_a_translucent_wide_stroke_hides_nothing() -> None:
    lines = parse_svg(svg('<path d="M0 100 H200" stroke="black"/><path d="M100 20 V180" stroke="black" '
                          'stroke-width="20" stroke-opacity="0.5"/>')).lines
    assert any(line.min(axis=0)[0] == 0 and line.max(axis=0)[0] == 200 for line in lines)


def test_a_stroke_scaled_beyond_floats_is_drawn_or_refused_in_one_line() -> None:
    assert Pen(half=1e300, tolerance=1e-20).quarter_segments >= 1  # the tolerance is lost beside the width
    drawing = parse_svg('<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100"><path d="M10 10 L90 10 '
                        'L90 90 Z" fill="none" stroke="red" stroke-width="10" transform="scale(3e38)"/>'
                        '<rect x="10" y="10" width="20" height="20"/></svg>')
    assert np.concatenate(drawing.lines).min(axis=0).tolist() == [10.0, 10.0]
