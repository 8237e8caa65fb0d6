"""The area a wide stroke paints (SVG 2 §13.5 stroke shape): its centre lines widened to both sides, with the caps at
open ends and the joins at corners a browser draws.

Coordinates are the user units the stroke width is given in; the caller places the area on the page.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from fabwire.lineus.plot.geometry import FloatArray

CAPS: dict[str, Literal["flat", "round", "square"]] = {"butt": "flat", "round": "round", "square": "square"}
"""stroke-linecap to GEOS cap styles; a value in error is butt (the initial value)."""
MAX_QUARTER_SEGMENTS = 64
"""Chords per quarter circle of a round cap or join at most, whatever the tolerance."""


@dataclass(frozen=True, slots=True)
class Pen:
    """How a stroke widens its centre lines: half its width, cap, join and miter limit (SVG 2 §13.5.2-13.5.4), and
    the chord tolerance of round caps and joins, all in user units."""

    half: float
    cap: str = "butt"
    join: str = "miter"
    miter_limit: float = 4.0
    tolerance: float = 0.1

    @property
    def quarter_segments(self) -> int:
        if self.tolerance >= self.half:
            return 1
        step = 2 * math.acos(1 - self.tolerance / self.half)
        if not step > 0:  # a tolerance lost beside a half width beyond floats: the finest allowed
            return MAX_QUARTER_SEGMENTS
        return max(1, min(MAX_QUARTER_SEGMENTS, math.ceil(math.pi / 2 / step)))


def pen_of(style: dict[str, str], half: float, tolerance: float) -> Pen:
    """The Pen of a computed style: stroke-linecap, stroke-linejoin and stroke-miterlimit, values in error taking
    the initial ones (butt, miter, 4). Chromium draws `miter-clip` and `arcs` as `miter`."""
    cap = style.get("stroke-linecap", "butt").strip()
    join = style.get("stroke-linejoin", "miter").strip()
    try:
        limit = float(style.get("stroke-miterlimit", "4").strip())
    except ValueError:
        limit = 4.0
    if not (math.isfinite(limit) and limit >= 1):
        limit = 4.0
    return Pen(half, cap if cap in CAPS else "butt",
               join if join in ("round", "bevel") else "miter", limit, tolerance)


def _miters(points: FloatArray, closed: bool, pen: Pen) -> list[BaseGeometry]:
    """The pointed corners a miter join adds to a bevel join, where the miter stays within the limit and reaches
    more than the tolerance beyond the bevel."""
    steps = np.diff(points, axis=0)
    lengths = np.hypot(steps[:, 0], steps[:, 1])
    keep = lengths > 0
    steps, corners = steps[keep] / lengths[keep, None], points[1:][keep]
    if len(steps) < 2 and not closed:
        return []
    if closed:
        incoming, outgoing, at = steps, np.roll(steps, -1, axis=0), corners
    else:
        incoming, outgoing, at = steps[:-1], steps[1:], corners[:-1]
    cos = np.clip((incoming * outgoing).sum(axis=1), -1.0, 1.0)
    cross = incoming[:, 0] * outgoing[:, 1] - incoming[:, 1] * outgoing[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.sqrt(2 / (1 + cos))  # miter length over stroke width: 1 / sin(half the angle between segments)
        reach = pen.half * (ratio - np.sqrt((1 + cos) / 2))  # how far the miter tip lies beyond the bevel
    wanted = (cross != 0) & (ratio <= pen.miter_limit) & (reach > pen.tolerance)
    out: list[BaseGeometry] = []
    for k in np.flatnonzero(wanted).tolist():
        side = -math.copysign(1.0, float(cross[k]))  # the outer side of the turn
        n1 = side * np.array([-incoming[k, 1], incoming[k, 0]])
        n2 = side * np.array([-outgoing[k, 1], outgoing[k, 0]])
        tip = at[k] + pen.half * (n1 + n2) / (1 + cos[k])
        out.append(shapely.Polygon([at[k], at[k] + pen.half * n1, tip, at[k] + pen.half * n2]))
    return out


def stroke_area(lines: Sequence[tuple[FloatArray, bool]], pen: Pen) -> BaseGeometry:
    """The area `pen` paints along `lines` ((points, closed) each, user units): closed lines join all round, open
    ones end in caps; a line of one point, or of a length 0, is a dot for round and square caps (axis-aligned
    square) and nothing for butt caps."""
    parts: list[BaseGeometry] = []
    quads = pen.quarter_segments
    cap = CAPS[pen.cap]
    join: Literal["round", "bevel"] = "round" if pen.join == "round" else "bevel"
    for points, closed in lines:
        if len(points) == 0 or not np.isfinite(points).all():
            continue
        if len(points) == 1 or bool((points == points[0]).all()):
            if pen.cap != "butt":
                parts.append(shapely.Point(points[0]).buffer(pen.half, quad_segs=quads, cap_style=cap))
            continue
        if closed and not bool((points[0] == points[-1]).all()):
            points = np.vstack([points, points[:1]])
        if closed and len(points) >= 4:
            geometry: BaseGeometry = shapely.LinearRing(points)
        else:  # a closed line of two points turns back on itself: flat where it turns
            geometry = shapely.LineString(points)
        parts.append(geometry.buffer(pen.half, quad_segs=quads, cap_style="flat" if closed else cap,
                                     join_style=join))
        if pen.join == "miter":
            parts.extend(_miters(points, closed, pen))
    if not parts:
        return shapely.Polygon()
    return shapely.union_all(parts)
