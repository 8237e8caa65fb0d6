"""Where a gradient leaves a mark on the paper: the stretches of its 0..1 (against a direct evaluation of its
colour over the paper) and the region of the plane they make, for each spread method and both kinds."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given
from hypothesis import strategies as st

from fabwire.lineus.plot import parse_svg, svg
from fabwire.lineus.plot.gradient import SAMPLES, Stop, shown_intervals, shown_region
from fabwire.lineus.plot.svgstyle import PAPER_TOLERANCE

WHITE, BLACK = (1.0, 1.0, 1.0), (0.0, 0.0, 0.0)


def marks(stops: list[Stop], opacity: float, t: float) -> bool:
    """The colour at `t` laid over white paper, computed stop by stop, differs from it beyond the tolerance."""
    if t <= stops[0].offset:
        a, b, share = stops[0], stops[0], 0.0
    elif t >= stops[-1].offset:
        a, b, share = stops[-1], stops[-1], 0.0
    else:
        i = max(k for k in range(len(stops)) if stops[k].offset <= t)
        a, b = stops[i], stops[i + 1]
        share = (t - a.offset) / (b.offset - a.offset) if b.offset > a.offset else 1.0
    rgb = [x + share * (y - x) for x, y in zip(a.rgb, b.rgb, strict=True)]
    alpha = (a.alpha + share * (b.alpha - a.alpha)) * opacity
    return max(abs(alpha * (255 * c - 255)) for c in rgb) > PAPER_TOLERANCE


def inside(intervals: list[tuple[float, float]], t: float) -> bool:
    return any(a <= t <= b for a, b in intervals)


channel = st.floats(0, 1)
stops_strategy = st.lists(st.tuples(st.floats(0, 1), st.tuples(channel, channel, channel), st.floats(0, 1)),
                          min_size=1, max_size=5)


@given(stops_strategy, st.floats(0.05, 1), st.lists(st.floats(0, 1), min_size=1, max_size=20))
def test_shown_stretches_are_where_the_colour_differs_from_the_paper(raw: list[tuple[float, tuple[float, float,
                                                                                                  float], float]],
                                                                     opacity: float, ts: list[float]) -> None:
    offsets = np.maximum.accumulate([o for o, _, _ in raw])
    stops = [Stop(float(o), rgb, a) for o, (_, rgb, a) in zip(offsets, raw, strict=True)]
    intervals = shown_intervals(stops, opacity)
    assert intervals == sorted(intervals)
    step = 2.0 / SAMPLES
    for t in ts:
        if any(abs(t - edge) < step for pair in intervals for edge in pair):
            continue  # within a sample of a stretch's end
        if any(abs(t - s.offset) < step for s in stops):
            continue  # a sharp step between two stops at one offset
        # the colour changes by at most 255 per sample step near a steep stop: allow a band of tolerance there
        near_threshold = any(marks(stops, opacity, u) != marks(stops, opacity, t) for u in (t - step, t + step)
                             if 0 <= u <= 1)
        if near_threshold:
            continue
        assert inside(intervals, t) == marks(stops, opacity, t), (t, intervals)


@pytest.mark.parametrize(("stops", "expected"), [
    ([Stop(0, BLACK, 1)], [(0.0, 1.0)]),
    ([Stop(0, WHITE, 1), Stop(1, WHITE, 1)], []),
    ([Stop(0, BLACK, 0), Stop(1, BLACK, 0)], []),
    ([Stop(0, WHITE, 1), Stop(1, BLACK, 1)], [(PAPER_TOLERANCE / 255, 1.0)]),
    ([Stop(0, BLACK, 1), Stop(0.5, WHITE, 1), Stop(1, BLACK, 1)], [(0.0, 0.5 - PAPER_TOLERANCE / 510),
                                                                    (0.5 + PAPER_TOLERANCE / 510, 1.0)]),
])
def test_shown_stretches_of_plain_gradients(stops: list[Stop], expected: list[tuple[float, float]]) -> None:
    found = shown_intervals(stops, 1.0)
    assert len(found) == len(expected)
    for (a, b), (c, d) in zip(found, expected, strict=True):
        assert a == pytest.approx(c, abs=2 / SAMPLES)
        assert b == pytest.approx(d, abs=2 / SAMPLES)


def attrs(values: dict[str, str]):  # type: ignore[no-untyped-def]
    return values.get


FADE = [Stop(0, WHITE, 1), Stop(0.5, WHITE, 1), Stop(0.5, BLACK, 1), Stop(1, BLACK, 1)]
"""White over the first half, black over the second, with a sharp step between."""


@pytest.mark.parametrize(("method", "x2", "expected"), [
    ("pad", "1", [(50, 100)]),
    ("pad", "0.25", [(12.5, 100)]),
    ("repeat", "0.25", [(12.5, 25), (37.5, 50), (62.5, 75), (87.5, 100)]),
    ("reflect", "0.25", [(12.5, 37.5), (62.5, 87.5)]),
])
def test_linear_bands_follow_the_spread_method(method: str, x2: str, expected: list[tuple[float, float]]) -> None:
    region = shown_region("linearGradient", attrs({"spreadMethod": method, "x2": x2}), shown_intervals(FADE, 1.0),
                          (0.0, 0.0, 100.0, 50.0), (200.0, 200.0), 0.1)
    assert region is not None
    cut = shapely.intersection(region, shapely.box(0, 0, 100, 50))
    want = shapely.union_all([shapely.box(a, 0, b, 50) for a, b in expected])
    assert shapely.symmetric_difference(cut, want).area < 100 * 50 * 2 / SAMPLES


def test_radial_shows_a_ring_and_user_space_units() -> None:
    stops = [Stop(0.5, WHITE, 1), Stop(0.5, BLACK, 1)]
    region = shown_region("radialGradient", attrs({"gradientUnits": "userSpaceOnUse", "cx": "100", "cy": "100",
                                                   "r": "40"}), shown_intervals(stops, 1.0), (0.0, 0.0, 200.0, 200.0),
                          (200.0, 200.0), 0.05)
    assert region is not None
    assert not region.contains(shapely.Point(100, 100))
    assert region.contains(shapely.Point(100, 125))
    assert region.contains(shapely.Point(5, 5))
    hole = shapely.difference(shapely.box(0, 0, 200, 200), region)
    assert hole.area == pytest.approx(np.pi * 20**2, rel=0.01)


def test_a_gradient_shown_everywhere_gives_no_region() -> None:
    assert shown_region("linearGradient", attrs({}), shown_intervals([Stop(0, BLACK, 1), Stop(1, (1.0, 0.0, 0.0), 1)],
                                                                     1.0),
                        (0.0, 0.0, 10.0, 10.0), (200.0, 200.0), 0.1) is None


def test_a_fill_fading_into_the_paper_is_outlined_where_it_shows() -> None:
    drawing = parse_svg('<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200">'
                        '<linearGradient id="g"><stop offset="0.5" stop-color="white"/>'
                        '<stop offset="0.5" stop-color="black"/></linearGradient>'
                        '<rect x="0" y="0" width="200" height="100" fill="url(#g)"/></svg>')
    points = np.concatenate(drawing.lines)
    assert points[:, 0].min() == pytest.approx(100, abs=0.2)
    assert points[:, 0].max() == pytest.approx(200, abs=1e-6)


def page(body: str) -> str:
    return f'<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200">{body}</svg>'


STEP = '<stop offset="0.5" stop-color="white"/><stop offset="0.5" stop-color="black"/>'
FULL = (0.0, 0.0, 200.0, 200.0)
HOSTILE: dict[str, tuple[str, tuple[float, float, float, float] | None]] = {
    # name: (document, the box of what is drawn, as Chromium shows it; None for nothing)
    "not-a-number attributes": (page('<linearGradient id="g" x1="nan" x2="inf" gradientTransform="matrix(1e38 0 0 '
                                     '1e-38 0 0)"><stop offset="nan" stop-color="white"/><stop offset="-1e400"/>'
                                     '</linearGradient><rect width="200" height="60" fill="url(#g)" '
                                     'stroke="url(#g)" stroke-width="30"/>'), (0.0, 0.0, 200.0, 75.0)),
    "a hair-thin repeated vector": (page(f'<linearGradient id="g" spreadMethod="reflect" x2="0.00001">{STEP}'
                                         '</linearGradient><rect width="200" height="200" fill="url(#g)"/>'), FULL),
    "a vanishing radius": (page(f'<radialGradient id="g" r="1e-30" spreadMethod="repeat">{STEP}</radialGradient>'
                                '<rect width="200" height="200" fill="url(#g)"/>'), FULL),
    "a huge radius": (page(f'<radialGradient id="g" r="1e30">{STEP}</radialGradient>'
                           '<rect width="200" height="200" fill="url(#g)"/>'), None),
    "a focal circle wider than the end circle": (page(f'<radialGradient id="g" fr="0.9" r="0.5">{STEP}'
                                                      '</radialGradient><rect width="200" height="200" '
                                                      'fill="url(#g)"/>'), FULL),
    "an href cycle": (page('<linearGradient id="a" href="#b"/><linearGradient id="b" href="#a"/>'
                           '<rect width="200" height="200" fill="url(#a)"/>'), None),
    "a singular transform": (page(f'<linearGradient id="g" gradientTransform="scale(0 1)">{STEP}'
                                  '</linearGradient><rect width="200" height="200" fill="url(#g)"/>'), None),
    "a flat shape": (page(f'<linearGradient id="g">{STEP}</linearGradient>'
                          '<path d="M0 0 L200 0" fill="url(#g)" stroke="url(#g)"/>'), None),
    "one white stop repeated over a hair-thin vector": (page('<linearGradient id="w" x2="1e-12" spreadMethod="repeat">'
                                                             '<stop stop-color="white"/></linearGradient><rect x="10" '
                                                             'y="10" width="180" height="180" fill="url(#w)"/><rect '
                                                             'x="80" y="80" width="40" height="40"/>'),
                                                        (80.0, 80.0, 120.0, 120.0)),
    "a focus on the end circle, reflected": (page('<radialGradient id="w" cy="1" fy="0.5" spreadMethod="reflect">'
                                                  '<stop stop-color="white"/></radialGradient><rect x="10" y="10" '
                                                  'width="180" height="180" fill="url(#w)"/>'), None),
    "a vector beyond floats": (page('<linearGradient id="g" gradientUnits="userSpaceOnUse" x1="-1e308" x2="1e308" '
                                    'spreadMethod="repeat"><stop offset="0" stop-color="white"/><stop offset="1" '
                                    'stop-color="black"/></linearGradient><rect x="10" y="10" width="180" '
                                    'height="180" fill="url(#g)"/>'), (10.0, 10.0, 190.0, 190.0)),
    "a colour in CIE Lab": (page('<rect x="10" y="10" width="180" height="180" fill="lab(50 20 20)" '
                                 'stroke="oklch(0.6 0.1 40)"/>'), (10.0, 10.0, 190.0, 190.0)),
    "a dot inside a gradient fill": (page('<linearGradient id="g"><stop offset="0" stop-color="white"/><stop '
                                          'offset="1" stop-color="black"/></linearGradient><path d="M10 10 L190 10 '
                                          'L190 190 L10 190 Z M100 100 L100 100" fill="url(#g)" stroke="black" '
                                          'stroke-linecap="round"/>'), (10.0, 10.0, 190.0, 190.0)),
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_hostile_gradients_draw_what_a_browser_shows(name: str) -> None:
    text, box = HOSTILE[name]
    drawing = parse_svg(text)
    if box is None:
        assert drawing.lines == []
        return
    points = np.concatenate(drawing.lines)
    assert np.isfinite(points).all()
    assert [*points.min(axis=0), *points.max(axis=0)] == pytest.approx(box, abs=0.5)


def test_gradients_past_the_drawing_budget_are_outlined_whole(monkeypatch: pytest.MonkeyPatch) -> None:
    shapes = "".join(f'<rect x="{x}" y="20" width="30" height="160" fill="url(#g)"/>' for x in (20, 70, 120))
    text = page(f'<linearGradient id="g">{STEP}</linearGradient>{shapes}')
    cut = parse_svg(text)
    assert np.concatenate(cut.lines)[:, 0].min() == pytest.approx(35, abs=0.2)  # each shows from its middle
    monkeypatch.setattr(svg, "MAX_GRADIENT_POINTS", 0)
    whole = parse_svg(text)
    assert np.concatenate(whole.lines)[:, 0].min() == pytest.approx(20)
    assert any("gradients past 0 points are outlined whole" in note for note in whole.notes)


def test_a_gradient_takes_its_stops_through_a_bounded_href_chain() -> None:
    chain = "".join(f'<linearGradient id="g{i}" href="#g{i + 1}"/>' for i in range(svg.MAX_HREF_CHAIN + 5))
    far = page(f'{chain}<linearGradient id="g{svg.MAX_HREF_CHAIN + 5}"><stop offset="0"/></linearGradient>'
               '<rect x="10" y="10" width="50" height="50" fill="url(#g0)"/><rect x="100" y="100" width="50" '
               'height="50"/>')
    drawing = parse_svg(far)
    assert np.concatenate(drawing.lines).min(axis=0).tolist() == [100.0, 100.0]  # the far stops are not reached
    assert any(f"more than {svg.MAX_HREF_CHAIN} others" in note for note in drawing.notes)
    near = far.replace('fill="url(#g0)"', f'fill="url(#g{svg.MAX_HREF_CHAIN + 4})"')  # one link from its stops
    assert np.concatenate(parse_svg(near).lines).min(axis=0).tolist() == [10.0, 10.0]
