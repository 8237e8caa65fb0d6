"""Where a gradient leaves a mark on the paper: the part of its plane whose colour, laid over the paper at its
opacity, differs from the paper. A pen outlines the part of a shape a browser shows, so the stretch of a gradient
that fades into the paper (white, or transparent) draws nothing, as a white fill draws nothing.

Sources: SVG 1.1 §13.2 (gradients: `gradientUnits`, `gradientTransform`, `spreadMethod`, the defaults of x1, y1,
x2, y2, cx, cy, r, fx, fy, and "a gradient vector of zero length paints the last stop's colour", "r = 0 paints
the last stop's colour"), §7.11 (objectBoundingBox on a box with no width or height: the paint is ignored),
§13.2.4 (stop offsets clamped to 0..1 and never below an earlier one), SVG 2 §14.3.3 (`fr`, the focal circle).
Colours are interpolated per channel in sRGB, colour and alpha apart, as Chromium (Skia) paints SVG gradients.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from fabwire.lineus.plot.geometry import FloatArray
from fabwire.lineus.plot.svgstyle import PAPER, PAPER_TOLERANCE, number
from fabwire.lineus.plot.svgunits import IDENTITY, flattens, length, transform

SAMPLES = 2048
"""Samples of the gradient's colour over 0..1: a band edge lies within 1/SAMPLES of the gradient's length of
where the colour crosses PAPER_TOLERANCE (under 0.1 px for any gradient shorter than 200 px)."""
MAX_BANDS = 500
"""Bands a repeated or reflected gradient may make over one shape; beyond, the whole shape is taken as shown."""
FINEST_PERIOD = 20
"""Chord tolerances in the shortest period of a repeated or reflected gradient whose stripes are drawn: a pen
line is about 20 of them wide (0.5 mm against 0.025 mm), and finer stripes show as one even tone."""
MAX_REGION_POINTS = 20_000
"""Vertices one gradient's shown region may have (bands times their circles' vertices); beyond, the whole shape
is taken as shown, so a hostile gradient costs bounded time."""


@dataclass(frozen=True)
class Stop:
    """One gradient stop: `offset` 0..1 (already clamped and ordered), `rgb` channels 0..1, `alpha` 0..1 (the
    colour's own alpha times stop-opacity)."""

    offset: float
    rgb: tuple[float, float, float]
    alpha: float


def shown_intervals(stops: Sequence[Stop], opacity: float) -> list[tuple[float, float]]:
    """The stretches of the gradient's 0..1 whose colour, at `opacity` (the paint's fill- or stroke-opacity),
    differs from the paper by more than PAPER_TOLERANCE in a channel, as (start, end) pairs in order."""
    if not stops:
        return []
    t = np.linspace(0.0, 1.0, SAMPLES + 1)
    offsets = np.array([s.offset for s in stops])
    colours = np.array([[*s.rgb, s.alpha] for s in stops])
    # a stop at the same offset as the one before starts a sharp step: interpolating needs increasing offsets
    offsets = offsets + np.arange(len(offsets)) * 1e-9
    values = np.stack([np.interp(t, offsets, colours[:, k]) for k in range(4)], axis=1)
    share = values[:, 3] * opacity
    paper = np.array(PAPER, dtype=float)
    mark = np.abs(share[:, None] * (255 * values[:, :3] - paper)).max(axis=1) > PAPER_TOLERANCE
    out: list[tuple[float, float]] = []
    edges = np.flatnonzero(np.diff(mark.astype(np.int8)))
    starts = ([0] if mark[0] else []) + [int(e) + 1 for e in edges if not mark[e]]
    ends = [int(e) for e in edges if mark[e]] + ([SAMPLES] if mark[-1] else [])
    given = np.array([s.offset for s in stops])

    def between(low: float, high: float) -> float:
        """Where the mark changes between two samples: at a stop there (a sharp step), else halfway."""
        at = given[(given >= low) & (given <= high)]
        return float(at[0]) if len(at) else (low + high) / 2

    for a, b in zip(starts, ends, strict=True):
        lo = 0.0 if a == 0 else between(t[a - 1], t[a])
        hi = 1.0 if b == SAMPLES else between(t[b], t[b + 1])
        out.append((lo, hi))
    return out


def _spread(shown: list[tuple[float, float]], method: str, low: float, high: float) -> list[tuple[float, float]] | None:
    """The shown stretches over `low`..`high` of the gradient's parameter, past 0..1 as `spreadMethod` says
    (pad, reflect, repeat); None when they would make more than MAX_BANDS bands."""
    if not shown:
        return []
    if method in ("reflect", "repeat"):
        if not (math.isfinite(low) and math.isfinite(high)):
            return None
        first, last = math.floor(low), math.ceil(high)
        if (last - first) * len(shown) > MAX_BANDS:
            return None
        out = []
        for k in range(first, last):
            for a, b in shown:
                if method == "reflect" and k % 2:
                    a, b = 1 - b, 1 - a
                out.append((k + a, k + b))
        return _merged(out)
    out = list(shown)
    if shown and shown[0][0] <= 0:
        out[0] = (min(low, 0.0) - 1, out[0][1])
    if shown and shown[-1][1] >= 1:
        out[-1] = (out[-1][0], max(high, 1.0) + 1)
    return out


def _merged(spans: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """`spans` in order with those that overlap or touch joined: their bands are then disjoint."""
    out: list[tuple[float, float]] = []
    for a, b in sorted(spans):
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


def _matrix_then(a: FloatArray, b: FloatArray) -> FloatArray:
    return np.asarray((np.vstack([a, [0.0, 0.0, 1.0]]) @ np.vstack([b, [0.0, 0.0, 1.0]]))[:2], dtype=float)


def _apply(matrix: FloatArray, points: FloatArray) -> FloatArray:
    return np.asarray(points @ matrix[:, :2].T + matrix[:, 2], dtype=float)


def shown_region(kind: str, attr: Callable[[str], str | None], shown: Sequence[tuple[float, float]],
                 box: tuple[float, float, float, float], viewport: tuple[float, float],
                 tolerance: float, margin: float = 0.0) -> BaseGeometry | None:
    """The part of the user space around `box` (the painted element's bounding box, x0, y0, x1, y1 in user
    units) where a gradient leaves a mark; None when it leaves one everywhere over the box (the common case), or
    when its stripes are finer than a pen line or the numbers overflow (the shape is then taken as shown whole).

    `kind` is 'linearGradient' or 'radialGradient'; `attr(name)` reads an attribute along the gradient's `href`
    chain; `shown` are its stretches that mark the paper (`shown_intervals`); `viewport` (width, height) resolves
    percentages in userSpaceOnUse; `tolerance` is the chord error of the circles of a radial gradient, user
    units; `margin` (user units) is how far beyond the box the paint reaches (a stroke's half width and miters),
    which the region must cover too."""
    with np.errstate(all="ignore"):  # numbers beyond floats are caught as not finite, not warned about
        return _region(kind, attr, list(shown), box, viewport, tolerance, margin)


def _region(kind: str, attr: Callable[[str], str | None], shown: list[tuple[float, float]],
            box: tuple[float, float, float, float], viewport: tuple[float, float],
            tolerance: float, margin: float) -> BaseGeometry | None:
    if not shown:
        return shapely.Polygon()  # no stretch of it marks the paper
    if len(shown) == 1 and shown[0] == (0.0, 1.0):
        return None
    x0, y0, x1, y1 = box
    if not (x1 > x0 or y1 > y0):
        return None
    bounding = (attr("gradientUnits") or "").strip() != "userSpaceOnUse"
    if bounding and not (x1 > x0 and y1 > y0):
        return shapely.Polygon()  # a box with no width or height: the gradient paints nothing, as in Chromium
    try:
        own = transform(attr("gradientTransform"))
    except ValueError:
        own = IDENTITY
    frame = np.array([[x1 - x0, 0.0, x0], [0.0, y1 - y0, y0]]) if bounding else IDENTITY
    space = _matrix_then(frame, own)
    if flattens(space):
        return shapely.Polygon()  # a gradientTransform that flattens the plane paints nothing, as in Chromium
    inverse = np.asarray(np.linalg.inv(np.vstack([space, [0.0, 0.0, 1.0]]))[:2], dtype=float)
    m = max(0.0, margin)
    corners = _apply(inverse, np.array([[x0 - m, y0 - m], [x1 + m, y0 - m], [x1 + m, y1 + m], [x0 - m, y1 + m]],
                                       dtype=float))
    if not np.isfinite(corners).all():
        return None
    vw, vh = viewport

    def read(name: str, default: str, across: float) -> float:
        value = attr(name)
        value = default if value is None else value
        if bounding:
            return number(value, number(default, 0.0))
        return length(value, across, default=length(default, across))

    method = (attr("spreadMethod") or "pad").strip()
    diagonal = math.hypot(vw, vh) / math.sqrt(2)
    if kind == "linearGradient":
        p1 = np.array([read("x1", "0%", vw), read("y1", "0%", vh)])
        p2 = np.array([read("x2", "100%", vw), read("y2", "0%", vh)])
        step = p2 - p1
        reach = float(step @ step)
        if reach == 0:
            return None if shown and shown[-1][1] >= 1 else shapely.Polygon()
        across = np.array([-step[1], step[0]]) / math.sqrt(reach)
        along = (corners - p1) @ step / reach
        side = (corners - p1) @ across
        period = float(np.hypot(*(space[:, :2] @ step)))  # the gradient vector's length in user units
        if not (np.isfinite(along).all() and np.isfinite(side).all() and math.isfinite(period)):
            return None
        if method in ("reflect", "repeat") and period < FINEST_PERIOD * tolerance:
            return None
        spans = _spread(shown, method, float(along.min()), float(along.max()))
        if spans is None or 4 * len(spans) > MAX_REGION_POINTS:
            return None
        s0, s1 = float(side.min()) - 1, float(side.max()) + 1
        bands = [shapely.Polygon([p1 + a * step + s0 * across, p1 + b * step + s0 * across,
                                  p1 + b * step + s1 * across, p1 + a * step + s1 * across]) for a, b in spans]
        region: BaseGeometry = shapely.MultiPolygon(bands)  # disjoint strips: no union needed
    else:
        centre = np.array([read("cx", "50%", vw), read("cy", "50%", vh)])
        radius = read("r", "50%", diagonal)
        focus = np.array([read("fx", str(attr("cx") or "50%"), vw), read("fy", str(attr("cy") or "50%"), vh)])
        focal_radius = max(0.0, read("fr", "0%", diagonal))
        if radius <= 0:
            return None if shown and shown[-1][1] >= 1 else shapely.Polygon()
        if float(np.hypot(*(focus - centre))) + focal_radius > radius or focal_radius >= radius:
            return None  # a cone, not nested circles: taken as shown
        far = float(np.hypot(*(corners - focus).T).max())
        high = far / (radius - float(np.hypot(*(focus - centre))) - focal_radius + 1e-12) + 1
        reach = radius * float(np.sqrt(abs(np.linalg.det(space[:, :2]))))
        if not (math.isfinite(high) and math.isfinite(reach)):
            return None
        if method in ("reflect", "repeat") and (high > MAX_BANDS or reach < FINEST_PERIOD * tolerance):
            return None
        spans = _spread(shown, method, 0.0, high)
        chord = min(1.0, max(1e-6, tolerance / reach)) if tolerance > 0 and reach > 0 else 1e-3
        quads = max(4, min(128, math.ceil(math.pi / math.acos(1 - chord) / 4)))
        if spans is None or 2 * 4 * (quads + 1) * len(spans) > MAX_REGION_POINTS:
            return None
        outer: BaseGeometry = shapely.box(*(np.r_[corners.min(axis=0), corners.max(axis=0)] + [-1, -1, 1, 1]))
        outer = shapely.union(outer, shapely.Point(*centre).buffer(radius, quad_segs=quads))

        def disc(t: float) -> BaseGeometry:
            """Where the parameter is below `t`: inside the circle between the focal and the end circle."""
            if t < 0 or (t == 0 and focal_radius == 0):
                return shapely.Polygon()
            if t >= high:
                return outer
            at = focus + t * (centre - focus)
            found: BaseGeometry = shapely.Point(*at).buffer(focal_radius + t * (radius - focal_radius),
                                                            quad_segs=quads)
            return found

        rings = [shapely.difference(disc(b), disc(a)) for a, b in spans]
        region = shapely.MultiPolygon([part for ring in rings for part in shapely.get_parts(ring)
                                       if part.geom_type == "Polygon" and not part.is_empty])  # disjoint rings
    placed: BaseGeometry = shapely.transform(region, lambda xy: _apply(space, xy))
    return placed
