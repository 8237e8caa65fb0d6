"""Line-us geometry: machine units, the exact reachable area, the two-link arm and the motion-time model.

One module shared by the simulator (where the pen can go, how long a move takes) and the drawing planner
(what to fit into, what a plan will cost), so both agree to the unit.

Machine units: origin at the servo shafts, 20 units per millimetre, +X away from the body. The reachable area is
the closed form of the published drawing-area outline: radius <= 1950, both joints within their +/-35 degree
limits, and body clearance x >= 500 (y >= 0) / x >= 700 (y < 0).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

UNITS_PER_MM = 20.0
HOME = (1000.0, 1000.0)
Z_UP = 1000.0
Z_DOWN = 0.0
PEN_DOWN_BELOW = 500.0
"""A Z below this counts as pen-down (for speed and for drawing)."""

LINK = 1000.0
"""Both arm links (shoulder to elbow, elbow to pen), in units."""
R_MAX = 1950.0
JOINT_LIMIT_DEG = 35.0
X_MIN_UPPER = 500.0
"""Body clearance for y >= 0."""
X_MIN_LOWER = 700.0
"""Body clearance for y < 0."""
X_MIN_LOWER_FW1 = X_MIN_UPPER
"""Firmware 1.0.1 and older let the arm go to x >= 500 for y < 0 too, where the pen screw can hit the body
(Line-us-Programming README, "CAUTION"); software must keep x >= 700 there itself."""

_EPS = 1e-6
_LIMIT = math.radians(JOINT_LIMIT_DEG)
_CENTRE_UP = (LINK * math.cos(_LIMIT), LINK * math.sin(_LIMIT))
"""Centre of the upper boundary arc (second joint at +35 degrees)."""
_CENTRE_DOWN = (LINK * math.cos(_LIMIT), -LINK * math.sin(_LIMIT))
"""Centre of the lower boundary arc (first joint at -35 degrees)."""

Y_EXTENT = _CENTRE_UP[1] + LINK
BOUNDS = (X_MIN_UPPER, -Y_EXTENT, R_MAX, Y_EXTENT)
"""Bounding box of the reachable area: (x_min, y_min, x_max, y_max)."""
APP_AREA = (650.0, -1000.0, 1775.0, 1000.0)
"""The official app's drawing rectangle (x_min, y_min, x_max, y_max), from the published drawing-area sheet.
Its far corners and x < 700 below y = 0 are not reachable, so the app area is this rectangle within reach."""
BODY = (-251.0, -1356.0, 249.0, 564.0)
"""The machine body's footprint (x_min, y_min, x_max, y_max), from the same sheet."""

_MAX_SAMPLES = 1 << 20
"""Points sampled per slice when measuring segments against the area."""

Point = tuple[float, float]
FloatArray = npt.NDArray[np.float64]


def is_reachable(x: float, y: float, *, x_min_lower: float = X_MIN_LOWER) -> bool:
    """True if the pen can reach (x, y): the closed form of the documented drawing area.

    `x_min_lower` is the body clearance below y = 0 (700; `X_MIN_LOWER_FW1` for what firmware 1.0.1 allows).
    Plain math rather than numpy: the simulator asks this once per move, where array set-up would dominate.
    It applies exactly the tests of `reachable_mask`.
    """
    x = float(x)
    y = float(y)
    if not (math.isfinite(x) and math.isfinite(y)):
        return False
    if x < (X_MIN_UPPER if y >= 0 else x_min_lower) - _EPS:
        return False
    r = math.hypot(x, y)
    if not r <= R_MAX + _EPS:
        return False
    alpha = math.acos(min(r / (2 * LINK), 1.0))
    phi = math.atan2(y, x)
    return phi - alpha <= _LIMIT + 1e-9 and phi + alpha >= -_LIMIT - 1e-9


def reachable_mask(xs: npt.ArrayLike, ys: npt.ArrayLike, *, x_min_lower: float = X_MIN_LOWER
                   ) -> npt.NDArray[np.bool_]:
    """`is_reachable` for whole arrays of points at once."""
    x = np.asarray(xs, dtype=float)
    y = np.asarray(ys, dtype=float)
    r = np.hypot(x, y)
    with np.errstate(invalid="ignore"):
        alpha = np.arccos(np.clip(r / (2 * LINK), -1.0, 1.0))
    phi = np.arctan2(y, x)
    ok = r <= R_MAX + _EPS
    ok &= phi - alpha <= _LIMIT + 1e-9
    ok &= phi + alpha >= -_LIMIT - 1e-9
    ok &= np.where(y >= 0, x >= X_MIN_UPPER - _EPS, x >= x_min_lower - _EPS)
    ok &= np.isfinite(x) & np.isfinite(y)
    return np.asarray(ok, dtype=bool)


def outside_length(points: Sequence[Point] | FloatArray, *, step: float = 2.0) -> float:
    """Length of a polyline that lies outside the reachable area, sampled every `step` units.

    Sampling matters: the body-clearance step makes the area non-convex, so a segment between two reachable
    ends can still cross x < 700 below y = 0.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(pts) < 2:
        return 0.0
    return segments_outside(pts[:-1], pts[1:], step=step)


def segments_outside(starts: FloatArray, ends: FloatArray, *, step: float = 2.0) -> float:
    """Total length of the straight segments starts[i] → ends[i] that lies outside the reachable area."""
    a = np.asarray(starts, dtype=float).reshape(-1, 2)
    d = np.asarray(ends, dtype=float).reshape(-1, 2) - a
    if len(a) == 0:
        return 0.0
    lengths = np.hypot(d[:, 0], d[:, 1])
    n = np.minimum(np.maximum(1, np.ceil(lengths / step)), 1 << 20).astype(np.int64)
    # Sample in slices of about _MAX_SAMPLES points, so memory stays bounded whatever the segment lengths.
    total = 0.0
    cuts = np.searchsorted(np.cumsum(n), np.arange(_MAX_SAMPLES, int(n.sum()) + _MAX_SAMPLES, _MAX_SAMPLES))
    lo = 0
    for hi in [*cuts.tolist(), len(n)]:
        hi = max(hi, lo + 1)
        if lo >= len(n):
            break
        part = n[lo:hi]
        seg = np.repeat(np.arange(lo, hi), part)
        first = np.cumsum(part) - part
        t = (np.arange(int(part.sum())) - first[seg - lo] + 0.5) / n[seg]
        bad = ~reachable_mask(a[seg, 0] + d[seg, 0] * t, a[seg, 1] + d[seg, 1] * t)
        total += float(np.sum(lengths[seg] / n[seg] * bad))
        lo = hi
    return total


def lines_outside(lines: Sequence[FloatArray], *, step: float = 2.0) -> float:
    """`outside_length` summed over many polylines in one vectorised pass."""
    multi = [line for line in lines if len(line) > 1]
    if not multi:
        return 0.0
    starts = np.concatenate([line[:-1] for line in multi])
    ends = np.concatenate([line[1:] for line in multi])
    return segments_outside(starts, ends, step=step)


def polyline_reachable(points: Sequence[Point] | FloatArray, *, step: float = 2.0) -> bool:
    """True if every vertex and every sampled point of every segment is reachable."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if not bool(np.all(reachable_mask(pts[:, 0], pts[:, 1]))):
        return False
    return outside_length(pts, step=step) == 0.0


@dataclass(frozen=True, slots=True)
class Joints:
    """Arm angles in degrees: `shoulder` is the upper arm, `elbow` the forearm's absolute direction."""

    shoulder: float
    elbow: float


def inverse(x: float, y: float) -> Joints:
    """Joint angles that put the pen at (x, y); ValueError beyond the arm's length or at the shaft centre."""
    r = math.hypot(x, y)
    if not 0.0 < r <= 2 * LINK:
        raise ValueError(f"({x:g}, {y:g}) is {r:g} units from the shafts: the arm spans 0 < r <= {2 * LINK:g}")
    alpha = math.acos(r / (2 * LINK))
    phi = math.atan2(y, x)
    return Joints(math.degrees(phi + alpha), math.degrees(phi - alpha))


def forward(joints: Joints) -> Point:
    """Pen position for the given joint angles."""
    t1 = math.radians(joints.shoulder)
    t2 = math.radians(joints.elbow)
    return (LINK * (math.cos(t1) + math.cos(t2)), LINK * (math.sin(t1) + math.sin(t2)))


def servo_angles(x: float, y: float) -> tuple[float, float]:
    """The (S, E) servo readings `M114 S` would report: S = shoulder + 45, E = 45 - elbow (home = 135, 45)."""
    j = inverse(x, y)
    return (j.shoulder + 45.0, 45.0 - j.elbow)


@dataclass(frozen=True, slots=True)
class Clamped:
    """Where an out-of-area target really goes: the firmware moves as close as it can and lifts the pen."""

    x: float
    y: float
    clamped: bool

    @property
    def lift_pen(self) -> bool:
        return self.clamped


def _circle_candidates(px: float, py: float, cx: float, cy: float, radius: float) -> list[Point]:
    dx, dy = px - cx, py - cy
    d = math.hypot(dx, dy)
    if d == 0.0:
        return [(cx + radius, cy)]
    return [(cx + dx / d * radius, cy + dy / d * radius)]


def _vertices(x_min_lower: float) -> list[Point]:
    """Corners of the area, where two boundary pieces meet."""
    out: list[Point] = [(X_MIN_UPPER, 0.0), (x_min_lower, 0.0)]
    for xl, (cx, cy) in ((X_MIN_UPPER, _CENTRE_UP), (x_min_lower, _CENTRE_DOWN)):
        h = math.sqrt(LINK**2 - (xl - cx) ** 2)
        out.extend([(xl, cy + h), (xl, cy - h)])
    for cx, cy in (_CENTRE_UP, _CENTRE_DOWN):
        d = math.hypot(cx, cy)
        a = (R_MAX**2 - LINK**2 + d**2) / (2 * d)
        h = math.sqrt(R_MAX**2 - a**2)
        mx, my = a * cx / d, a * cy / d
        out.extend([(mx + h * cy / d, my - h * cx / d), (mx - h * cy / d, my + h * cx / d)])
    return out


_VERTICES = _vertices(X_MIN_LOWER)


def nearest_reachable(x: float, y: float, *, x_min_lower: float = X_MIN_LOWER) -> Point:
    """The reachable point closest to (x, y) (itself when already reachable)."""
    if is_reachable(x, y, x_min_lower=x_min_lower):
        return (x, y)
    cands: list[Point] = list(_VERTICES) if x_min_lower == X_MIN_LOWER else list(_vertices(x_min_lower))
    cands += _circle_candidates(x, y, 0.0, 0.0, R_MAX)
    cands += _circle_candidates(x, y, *_CENTRE_UP, LINK)
    cands += _circle_candidates(x, y, *_CENTRE_DOWN, LINK)
    cands += [(X_MIN_UPPER, max(y, 0.0)), (x_min_lower, min(y, 0.0)), (min(max(x, X_MIN_UPPER), x_min_lower), 0.0)]
    best: Point | None = None
    best_d = math.inf
    for cx, cy in cands:
        if not is_reachable(cx, cy, x_min_lower=x_min_lower):
            continue
        d = math.hypot(cx - x, cy - y)
        if d < best_d:
            best, best_d = (cx, cy), d
    assert best is not None  # the vertex (500, 0) is always a candidate and always reachable
    return best


def clamp_target(x: float, y: float, *, x_min_lower: float = X_MIN_LOWER) -> Clamped:
    """Out-of-area handling: radially toward the origin beyond the outer radius, else to the nearest point.

    `clamped` (and so `lift_pen`) is True whenever the target was moved: the firmware then lifts the pen.
    """
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"target ({x}, {y}) is not a finite point")
    if is_reachable(x, y, x_min_lower=x_min_lower):
        return Clamped(x, y, False)
    r = math.hypot(x, y)
    if r > R_MAX:
        rx, ry = x * R_MAX / r, y * R_MAX / r
        if is_reachable(rx, ry, x_min_lower=x_min_lower):
            return Clamped(rx, ry, True)
    nx, ny = nearest_reachable(x, y, x_min_lower=x_min_lower)
    return Clamped(nx, ny, True)


def in_body_zone(x: float, y: float) -> bool:
    """True inside the body-clearance notch (x < 700 below y = 0) that firmware 1.0.1 does not keep out of."""
    return x < X_MIN_LOWER - _EPS and y < 0


def clamp_note(x: float, y: float, *, notch_guarded: bool) -> str | None:
    """The one line a person is told when a move aimed at (x, y) ended elsewhere, or None: when (x, y) is reachable,
    or when it lies in the body notch and the client's firmware 1.x guard has already said where the arm went
    (`LineUs.guard_body`)."""
    if is_reachable(x, y):
        return None
    notch = in_body_zone(x, y) and is_reachable(x, y, x_min_lower=X_MIN_LOWER_FW1)  # only the notch keeps it out
    if notch and notch_guarded:
        return None
    where = "in the notch beside the robot's body" if notch else "outside the drawing area"
    return f"({x:g}, {y:g}) is {where}: the arm went to the nearest point, pen up"


def crosses_body_zone(a: Point, b: Point) -> bool:
    """True if the straight move a-b passes through the body-clearance notch (ends included).

    The notch is the quadrant x < 700, y < 0, so the part of a-b below y = 0 is tested at its own ends.
    """
    (ax, ay), (bx, by) = a, b
    if ay >= 0 and by >= 0:
        return False
    if ay < 0 and by < 0:
        return min(ax, bx) < X_MIN_LOWER - _EPS
    t = ay / (ay - by)  # where the move crosses y = 0
    cx = ax + (bx - ax) * t
    below = ax if ay < 0 else bx
    return min(cx, below) < X_MIN_LOWER - _EPS


def body_detour(a: Point, b: Point) -> list[Point]:
    """Waypoints after `a` up to `b` for a pen-up hop that keeps out of the body-clearance notch.

    A hop between two points outside the notch can only cut it from the x < 700, y >= 0 side to the
    x >= 700, y < 0 side; going by the notch's corner (700, 0) keeps each half on one safe side.
    """
    if not crosses_body_zone(a, b) or in_body_zone(*a) or in_body_zone(*b):
        return [b]
    return [(X_MIN_LOWER, 0.0), b]


def _outer_meet(cx: float, cy: float) -> Point:
    """Where a joint-limit arc leaves the outer radius (the meeting point farther from the X axis).

    The limit circles cross the outer circle twice; between the two crossings they bulge beyond it.
    """
    d = math.hypot(cx, cy)
    a = (R_MAX**2 - LINK**2 + d**2) / (2 * d)
    h = math.sqrt(R_MAX**2 - a**2)
    mx, my = a * cx / d, a * cy / d
    first = (mx + h * cy / d, my - h * cx / d)
    second = (mx - h * cy / d, my + h * cx / d)
    return first if abs(first[1]) > abs(second[1]) else second


def area_outline(step_deg: float = 1.0) -> list[Point]:
    """The closed boundary of the reachable area, counter-clockwise from (700, 0), first point repeated last."""
    pts: list[Point] = [(X_MIN_LOWER, 0.0)]

    def arc(cx: float, cy: float, radius: float, p0: Point, p1: Point) -> None:
        a0 = math.atan2(p0[1] - cy, p0[0] - cx)
        a1 = math.atan2(p1[1] - cy, p1[0] - cx)
        n = max(2, math.ceil(abs(a1 - a0) / math.radians(step_deg)))
        pts.extend((cx + radius * math.cos(a0 + (a1 - a0) * k / n), cy + radius * math.sin(a0 + (a1 - a0) * k / n))
                   for k in range(n + 1))

    dcx, dcy = _CENTRE_DOWN
    ucx, ucy = _CENTRE_UP
    low_body = (X_MIN_LOWER, dcy - math.sqrt(LINK**2 - (X_MIN_LOWER - dcx) ** 2))
    up_body = (X_MIN_UPPER, ucy + math.sqrt(LINK**2 - (X_MIN_UPPER - ucx) ** 2))
    low_outer = _outer_meet(dcx, dcy)
    up_outer = _outer_meet(ucx, ucy)
    arc(dcx, dcy, LINK, low_body, low_outer)
    arc(0.0, 0.0, R_MAX, low_outer, up_outer)
    arc(ucx, ucy, LINK, up_outer, up_body)
    pts.extend([(X_MIN_UPPER, 0.0), (X_MIN_LOWER, 0.0)])
    return pts


@dataclass(frozen=True, slots=True)
class MotionModel:
    """How long moves take: Cartesian interpolation in steps of at most `draw_step` (G94 S, pen down) or
    `travel_step` (G94 P, pen up), `step_time` seconds per step, `pen_time` per pen lift or drop.

    The step period is not published; 10 ms per step fits the measured pen-up hop timings.
    """

    draw_step: float = 5.0
    travel_step: float = 15.0
    step_time: float = 0.010
    pen_time: float = 0.1
    command_time: float = 0.0
    """Fixed cost per command (reply round trip)."""

    def __post_init__(self) -> None:
        for name in ("draw_step", "travel_step"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        for name in ("step_time", "pen_time", "command_time"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must not be negative, got {getattr(self, name)}")

    def steps(self, start: Point, end: Point, *, pen_down: bool) -> int:
        """Interpolation steps of an XY move: ceil(max(|dx|, |dy|) / step)."""
        span = max(abs(end[0] - start[0]), abs(end[1] - start[1]))
        if span <= 0:
            return 0
        return math.ceil(span / (self.draw_step if pen_down else self.travel_step) - 1e-9)

    def interpolate(self, start: Point, end: Point, *, pen_down: bool) -> list[Point]:
        """The intermediate targets the firmware steps through (excluding `start`, ending at `end`)."""
        n = self.steps(start, end, pen_down=pen_down)
        return [
            (start[0] + (end[0] - start[0]) * k / n, start[1] + (end[1] - start[1]) * k / n) for k in range(1, n + 1)
        ]

    def move_time(self, start: Sequence[float], end: Sequence[float], *, pen_down: bool = False) -> float:
        """Seconds for one G01 from `start` to `end`.

        With (x, y, z) positions the pen state comes from z: a lift happens before the XY motion and a drop after
        it, so XY runs at the drawing step only when the pen is down at both ends. With (x, y) positions the
        pen stays as `pen_down` says.
        """
        if len(start) >= 3 and len(end) >= 3:
            down0 = start[2] < PEN_DOWN_BELOW
            down1 = end[2] < PEN_DOWN_BELOW
            xy_down = down0 and down1
            pen = self.pen_time if down0 != down1 else 0.0
        else:
            xy_down = pen_down
            pen = 0.0
        n = self.steps((start[0], start[1]), (end[0], end[1]), pen_down=xy_down)
        return self.command_time + pen + n * self.step_time

    def polyline_time(self, points: Sequence[Point] | FloatArray, *, pen_down: bool = True) -> float:
        """Seconds to run through a polyline's vertices with the pen in one state (one command per vertex)."""
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        if len(pts) < 2:
            return 0.0
        span = np.max(np.abs(np.diff(pts, axis=0)), axis=1)
        step = self.draw_step if pen_down else self.travel_step
        n = np.ceil(span / step - 1e-9)
        n[span <= 0] = 0
        return float(n.sum()) * self.step_time + (len(pts) - 1) * self.command_time
