"""Markers drawn at the vertices of path, line, polyline and polygon (SVG 2 §13.7)."""

from __future__ import annotations

import numpy as np
import pytest

from fabwire.lineus.plot import parse_svg
from fabwire.lineus.plot.svg import MAX_MARKERS

DOT = ('<marker id="m" markerUnits="userSpaceOnUse" markerWidth="4" markerHeight="4" refX="2" refY="2">'
       '<rect width="4" height="4" fill="none" stroke="black" stroke-width="0.1"/></marker>')
"""A 4 x 4 square centred on the vertex."""


def svg(body: str) -> str:
    return f'<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200">{body}</svg>'


def centres(text: str) -> list[tuple[float, float]]:
    """Centres of the 4 x 4 squares the plan draws, in order."""
    found = []
    for line in parse_svg(text).lines:
        size = line.max(axis=0) - line.min(axis=0)
        if np.allclose(size, 4, atol=0.2):
            found.append(tuple(np.round((line.max(axis=0) + line.min(axis=0)) / 2, 3).tolist()))
    return found


def test_start_mid_and_end_mark_every_vertex_once() -> None:
    body = (f'<defs>{DOT}</defs><path d="M20 20 L100 20 Q150 20 150 80 M20 150 H180" fill="none" stroke="black" '
            'marker-start="url(#m)" marker-mid="url(#m)" marker-end="url(#m)"/>')
    assert sorted(centres(svg(body))) == sorted([(20, 20), (100, 20), (150, 80), (20, 150), (180, 150)])


def test_each_property_marks_its_own_vertices() -> None:
    body = (f'<defs>{DOT}</defs><polyline points="20,20 100,20 100,100" fill="none" stroke="black" '
            'marker-end="url(#m)"/>')
    assert centres(svg(body)) == [(100, 100)]


def test_the_marker_shorthand_is_a_property_not_an_attribute() -> None:
    line = '<line x1="20" y1="20" x2="180" y2="20" stroke="black" {}/>'
    assert centres(svg(DOT + line.format('marker="url(#m)"'))) == []
    assert sorted(centres(svg(DOT + line.format('style="marker: url(#m)"')))) == [(20, 20), (180, 20)]


def test_markers_are_not_drawn_on_rect_or_circle() -> None:
    body = f'{DOT}<rect x="20" y="20" width="50" height="50" stroke="black" fill="none" marker-start="url(#m)"/>'
    assert centres(svg(body)) == []


@pytest.mark.parametrize(("orient", "tip"), [("auto", (120.0, 100.0)), ("90", (100.0, 120.0)),
                                             ("auto-start-reverse", (80.0, 100.0))])
def test_orient_turns_the_marker(orient: str, tip: tuple[float, float]) -> None:
    arrow = (f'<marker id="a" markerUnits="userSpaceOnUse" markerWidth="20" markerHeight="20" refX="0" refY="10" '
             f'orient="{orient}"><path d="M0 0 L20 10 L0 20" fill="none" stroke="black" stroke-width="0.1"/></marker>')
    body = f'{arrow}<line x1="100" y1="100" x2="150" y2="100" stroke="black" marker-start="url(#a)"/>'
    lines = parse_svg(svg(body)).lines
    arrowhead = next(line for line in lines if len(line) == 3)
    assert tuple(np.round(arrowhead[1], 6).tolist()) == tip


def test_a_marker_inside_itself_is_left_out() -> None:
    body = ('<marker id="r" markerUnits="userSpaceOnUse" markerWidth="10" markerHeight="10" overflow="visible">'
            '<path d="M0 0 L5 5" stroke="black" marker-end="url(#r)"/></marker>'
            '<line x1="20" y1="20" x2="100" y2="20" stroke="black" marker-end="url(#r)"/>')
    assert len(parse_svg(svg(body)).lines) == 2


def test_an_opaque_marker_hides_the_line_under_it() -> None:
    body = ('<marker id="b" markerUnits="userSpaceOnUse" markerWidth="20" markerHeight="20" refX="10" refY="10">'
            '<rect width="20" height="20"/></marker>'
            '<line x1="20" y1="100" x2="180" y2="100" stroke="black" marker-end="url(#b)"/>')
    lines = parse_svg(svg(body)).lines
    assert max(float(line[:, 0].max()) for line in lines if len(line) == 2) == pytest.approx(170)


def test_context_paint_comes_from_the_use_or_the_marked_shape_and_is_none_without_one() -> None:
    used = ('<defs><rect id="r" x="20" y="20" width="40" height="40" fill="context-fill"/></defs>'
            '<use href="#r" fill="black"/><use href="#r" x="100" fill="none"/>')
    assert [line.min(axis=0).tolist() for line in parse_svg(svg(used)).lines] == [[20, 20]]
    alone = '<rect x="20" y="20" width="40" height="40" fill="context-fill" stroke="context-stroke"/>'
    assert parse_svg(svg(alone)).lines == []
    marked = ('<marker id="c" markerUnits="userSpaceOnUse" markerWidth="4" markerHeight="4" refX="2" refY="2">'
              '<rect width="4" height="4" fill="context-stroke"/></marker>'
              '<line x1="20" y1="20" x2="80" y2="20" stroke="none" marker-end="url(#c)"/>'
              '<line x1="20" y1="50" x2="80" y2="50" stroke="black" stroke-width="0.5" marker-end="url(#c)"/>')
    assert centres(svg(marked)) == [(80, 50)]


def test_marker_copies_are_bounded_and_the_rest_named() -> None:
    points = " ".join(f"{i % 200},{(i * 7) % 200}" for i in range(MAX_MARKERS + 50))
    body = ('<marker id="d" markerUnits="userSpaceOnUse" overflow="visible"><path d="M0 0 h1" stroke="black"/>'
            f'</marker><polyline points="{points}" fill="none" stroke="black" marker-mid="url(#d)"/>')
    drawing = parse_svg(svg(body))
    assert len(drawing.lines) <= MAX_MARKERS // 2 + 1  # each copy draws the marker and its path: two elements
    assert any(f"markers past {MAX_MARKERS:,}" in note for note in drawing.notes)
