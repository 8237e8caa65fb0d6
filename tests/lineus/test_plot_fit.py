"""The fit's box test against its definition: every point it samples, the way `outside_length` samples."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fabwire.lineus.kinematics import APP_AREA, is_reachable, outside_length, reachable_mask
from fabwire.lineus.plot.fit import Box, _box_inside, largest_box


def box_inside_by_definition(cx: float, cy: float, w: float, h: float, margin: float, full: bool) -> bool:
    """In the app rectangle (unless `full`), corners reachable, 48 points a side reachable, and nothing of the
    outline outside when measured every 5 units."""
    x0, y0 = cx - w / 2 - margin, cy - h / 2 - margin
    x1, y1 = cx + w / 2 + margin, cy + h / 2 + margin
    if not full and (x0 < APP_AREA[0] or y0 < APP_AREA[1] or x1 > APP_AREA[2] or y1 > APP_AREA[3]):
        return False
    if not all(is_reachable(x, y) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))):
        return False
    t = np.linspace(0.0, 1.0, 48)
    xs = np.concatenate([x0 + (x1 - x0) * t, np.full(48, x1), x1 - (x1 - x0) * t, np.full(48, x0)])
    ys = np.concatenate([np.full(48, y0), y0 + (y1 - y0) * t, np.full(48, y1), y1 - (y1 - y0) * t])
    if not bool(reachable_mask(xs, ys).all()):
        return False
    return outside_length([(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)], step=5.0) == 0.0


@settings(max_examples=3000, deadline=None)
@given(st.floats(400, 2100), st.floats(-1300, 1300), st.floats(1e-3, 1600), st.floats(1e-3, 1600),
       st.sampled_from([0.0, 40.0, 100.0, 400.0]) | st.floats(0, 300), st.booleans())
def test_box_inside_is_its_definition(cx: float, cy: float, w: float, h: float, margin: float, full: bool) -> None:
    assert _box_inside(cx, cy, w, h, margin, full) == box_inside_by_definition(cx, cy, w, h, margin, full)


def test_box_inside_near_the_edges_is_its_definition() -> None:
    """Boxes grown from the search's own centres to just around the largest that fits: the answers that decide
    the fit, where the sampled outline touches the area's edge."""
    for aspect, margin, full in ((1.3333, 40.0, False), (0.2646, 0.0, True), (4.5, 100.0, False), (1.0, 0.0, True)):
        box = largest_box(aspect, margin, full)
        for cx in np.linspace(box.cx - 30, box.cx + 30, 7):
            for scale in np.linspace(0.98, 1.02, 41):
                args = (float(cx), box.cy, box.width * scale, box.height * scale, margin, full)
                assert _box_inside(*args) == box_inside_by_definition(*args)


def test_largest_box_of_the_readme_shapes() -> None:
    """The box a 4:3 drawing gets with the default 2 mm margin, to the last digit (the plan figures quoted in the
    documentation start from it)."""
    assert largest_box(1.3333, 40.0, False) == Box(1200.0, 425.0, 1019.9984482719108, 765.0179616529745)
