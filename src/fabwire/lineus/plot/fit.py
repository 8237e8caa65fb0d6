"""Placing a drawing inside the drawing area: the largest box of the drawing's shape, or a check of the drawing
as given. The drawing area is the official app's (its rectangle within reach) unless the whole reachable area is
asked for."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from fabwire.errors import InputError
from fabwire.lineus.kinematics import (
    APP_AREA,
    UNITS_PER_MM,
    is_reachable,
    outside_length,
    reachable_mask,
    segments_outside,
)
from fabwire.lineus.plot.geometry import (
    FloatArray,
    Polylines,
    affine,
    bbox,
    compose,
    drawn_length,
    extent,
    flatten,
    inner_segments,
    scale_translate,
)


@dataclass(frozen=True, slots=True)
class Box:
    """An axis-aligned rectangle in machine units, by centre and size."""

    cx: float
    cy: float
    width: float
    height: float

    def corners(self) -> tuple[float, float, float, float]:
        hw, hh = self.width / 2, self.height / 2
        return (self.cx - hw, self.cy - hh, self.cx + hw, self.cy + hh)


_OUTLINE_SAMPLES = 48
_OUTLINE_T = np.linspace(0.0, 1.0, _OUTLINE_SAMPLES)
_OUTLINE_ONES = np.ones(_OUTLINE_SAMPLES)
"""A side's constant coordinate is this times the coordinate: exactly it, without a `np.full` each time."""
_OUTLINE_STEP = 5.0


@functools.lru_cache(maxsize=256)
def _step_t(n: int) -> FloatArray:
    """Where `outside_length` samples a segment it cuts into `n` steps: the middle of each step."""
    t: FloatArray = (np.arange(n) + 0.5) / n
    return t


def _box_inside(cx: float, cy: float, w: float, h: float, margin: float, full: bool) -> bool:
    """Whether the box (with `margin` around it) lies in the area: its corners reachable, its outline reachable
    at 48 points a side and at the middle of every 5-unit step of each side (the points `outside_length` samples
    at that step, computed the same way), all in one `reachable_mask` call."""
    x0, y0 = cx - w / 2 - margin, cy - h / 2 - margin
    x1, y1 = cx + w / 2 + margin, cy + h / 2 + margin
    if not full:
        ax0, ay0, ax1, ay1 = APP_AREA
        if x0 < ax0 or y0 < ay0 or x1 > ax1 or y1 > ay1:
            return False
    if not (is_reachable(x0, y0) and is_reachable(x1, y0) and is_reachable(x1, y1) and is_reachable(x0, y1)):
        return False  # the corners alone, without arrays: most boxes tried fail here
    t = _OUTLINE_T
    # The four sides from (x0, y0) anticlockwise, as start + direction x t.
    sides = ((x0, y0, x1 - x0, 0.0), (x1, y0, 0.0, y1 - y0), (x1, y1, x0 - x1, 0.0), (x0, y1, 0.0, y0 - y1))
    steps = [_step_t(min(max(1, math.ceil(math.hypot(dx, dy) / _OUTLINE_STEP)), 1 << 20))
             for _, _, dx, dy in sides]
    xs = np.concatenate([x0 + (x1 - x0) * t, _OUTLINE_ONES * x1, x1 - (x1 - x0) * t, _OUTLINE_ONES * x0,
                         *(ax + dx * st for (ax, _, dx, _), st in zip(sides, steps, strict=True))])
    ys = np.concatenate([_OUTLINE_ONES * y0, y0 + (y1 - y0) * t, _OUTLINE_ONES * y1, y1 - (y1 - y0) * t,
                         *(ay + dy * st for (_, ay, _, dy), st in zip(sides, steps, strict=True))])
    return bool(reachable_mask(xs, ys).all())


_COARSE_CX = np.linspace(850.0, 1500.0, 27).tolist()
_COARSE_CY = np.linspace(-500.0, 500.0, 21).tolist()
_FINE_DX = np.linspace(-25.0, 25.0, 9).tolist()
_FINE_DY = np.linspace(-50.0, 50.0, 9).tolist()
"""The centres `largest_box` tries: a coarse grid over the area, then a finer one around the best of it."""


@functools.lru_cache(maxsize=64)
def largest_box(aspect: float, margin: float = 0.0, full: bool = False) -> Box:
    """The largest rectangle of width/height `aspect` that lies, with `margin` units around it, in the app area
    (with `full`, in the whole reachable area)."""
    if not aspect > 0:
        raise ValueError("aspect must be positive")
    best = Box(1200.0, 0.0, 0.0, 0.0)

    def grow(cx: float, cy: float) -> None:
        nonlocal best
        lo, hi = best.height, 3400.0
        if not _box_inside(cx, cy, lo * aspect + 1e-3, lo + 1e-3, margin, full):
            return
        for _ in range(18):
            mid = (lo + hi) / 2
            if _box_inside(cx, cy, mid * aspect, mid, margin, full):
                lo = mid
            else:
                hi = mid
        if lo > best.height:
            best = Box(cx, cy, lo * aspect, lo)

    for cy in _COARSE_CY:
        for cx in _COARSE_CX:
            grow(cx, cy)
    # Then finer around the best centre found (the coarse grid steps are 25 and 50 units).
    centre = (best.cx, best.cy)
    for dy in _FINE_DY:
        for dx in _FINE_DX:
            grow(centre[0] + dx, centre[1] + dy)
    if best.height <= 0:
        raise InputError(f"a margin of {margin / UNITS_PER_MM:g} mm leaves no room in the drawing area")
    return best


@dataclass(frozen=True, slots=True)
class Placement:
    """How the drawing was put on the machine: the input-to-machine matrix and what did not fit."""

    matrix: FloatArray
    scale: float
    box: Box | None
    outside: float
    """Pen-down length outside the reachable area, in machine units (0 after fitting)."""


def fit_scale(lines: Polylines, *, margin: float = 0.0, full: bool = False) -> tuple[float, Box]:
    """The scale `fit_into_area` gives `lines` (at most: it may shrink a little more), and the box it fills."""
    return _fit_scale(bbox(lines), margin, full)


def _fit_scale(extent: tuple[float, float, float, float], margin: float, full: bool) -> tuple[float, Box]:
    x0, y0, x1, y1 = extent
    w, h = x1 - x0, y1 - y0
    aspect = max(w, 1e-9) / max(h, 1e-9)
    aspect = min(max(aspect, 1e-3), 1e3)
    box = largest_box(round(aspect, 4), margin, full)
    if w <= 1e-9 and h <= 1e-9:
        return 1.0, box
    return float(min(box.width / w if w > 1e-9 else np.inf, box.height / h if h > 1e-9 else np.inf)), box


def fit_into_area(lines: Polylines, *, margin: float = 0.0, full: bool = False) -> tuple[Polylines, Placement]:
    """Scale (keeping the aspect ratio) and centre `lines`, already in machine orientation, into the area."""
    placement = fit_placement(bbox(lines), margin=margin, full=full)
    return affine(lines, placement.matrix), placement


def fit_placement(extent: tuple[float, float, float, float], *, margin: float = 0.0, full: bool = False
                  ) -> Placement:
    """How `fit_into_area` places a drawing whose bounding box (x_min, y_min, x_max, y_max, machine units) is
    `extent`: a uniform scale and a translation, as a 2x3 matrix."""
    x0, y0, x1, y1 = extent
    scale, box = _fit_scale(extent, margin, full)
    m = scale_translate(float(scale), box.cx - (x0 + x1) / 2 * scale, box.cy - (y0 + y1) / 2 * scale)
    # Every line lies in the drawing's placed bounding rectangle, and a rectangle is convex: when its outline is
    # inside the area, so is all of the drawing. The box was checked on a sampled outline, so check the placed
    # rectangle finely and shrink a little in the rare case a corner still grazes out.
    for _ in range(8):
        corners = np.array([[x0, y0], [x1, y1]]) @ m[:, :2].T + m[:, 2]
        if rectangle_inside(float(corners[0, 0]), float(corners[0, 1]), float(corners[1, 0]), float(corners[1, 1])):
            break
        shrink = np.array([[0.99, 0.0, box.cx * 0.01], [0.0, 0.99, box.cy * 0.01]])
        m = compose(shrink, m)
        scale *= 0.99
    return Placement(m, float(scale), box, 0.0)


def rectangle_inside(x0: float, y0: float, x1: float, y1: float) -> bool:
    """Whether the axis-aligned rectangle with corners (x0, y0) and (x1, y1) lies in the reachable area: its
    corners reachable and its outline, sampled finely, nowhere outside. The area has no holes, so then its
    inside is reachable too: everything drawn within the rectangle is."""
    outline = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]])
    return bool(reachable_mask(outline[:, 0], outline[:, 1]).all()) and outside_length(outline, step=0.5) == 0


def check_placed(lines: Polylines, *, clip: bool) -> tuple[Polylines, float]:
    """Refuse (or with `clip`, cut away) pen-down lines outside the area; returns the kept lines and the length
    outside."""
    points, offsets = flatten(lines)
    if rectangle_inside(*extent(points)):
        return lines, 0.0  # what a fitted drawing always passes, at the cost of four sides
    inner = inner_segments(offsets)
    outside = segments_outside(points[:-1][inner], points[1:][inner])
    single = offsets[1:] - offsets[:-1] == 1
    dots = int((single & ~reachable_mask(points[offsets[:-1], 0], points[offsets[:-1], 1])).sum())
    if outside == 0 and not dots:
        return lines, 0.0
    total = drawn_length(lines)
    if not clip:
        share = 100.0 * outside / total if total else 100.0
        raise InputError(
            f"{outside / UNITS_PER_MM:.1f} mm of the {total / UNITS_PER_MM:.1f} mm drawing ({share:.1f} %)"
            f"{f' and {dots} dots' if dots else ''} lie outside the reachable area; use --fit to scale it "
            "into the area, or --clip to leave those parts out"
        )
    return clip_to_area(lines), outside


def clip_to_area(lines: Polylines, *, step: float = 2.0) -> Polylines:
    """Cut polylines where they leave the area, keeping only the reachable pieces (densified at the cuts)."""
    out: Polylines = []
    for line in lines:
        if len(line) == 1:
            if reachable_mask(line[:, 0], line[:, 1])[0]:
                out.append(line)
            continue
        ok = reachable_mask(line[:, 0], line[:, 1])
        d = np.diff(line, axis=0)
        if bool(ok.all()) and outside_length(line, step=step) == 0:
            out.append(line)
            continue
        current: list[FloatArray] = []
        for i in range(len(d)):
            a, b = line[i], line[i + 1]
            n = max(1, int(np.ceil(np.hypot(*d[i]) / step)))
            t = np.linspace(0.0, 1.0, n + 1)
            pts = a + np.outer(t, b - a)
            inside = reachable_mask(pts[:, 0], pts[:, 1])
            for k in range(len(pts)):
                if inside[k]:
                    if not current or not np.array_equal(current[-1], pts[k]):
                        current.append(pts[k])
                elif current:
                    if len(current) > 1:
                        out.append(np.array(current))
                    current = []
        if len(current) > 1:
            out.append(np.array(current))
    return [_simplify_collinear(p) for p in out]


def _simplify_collinear(line: FloatArray) -> FloatArray:
    if len(line) < 3:
        return line
    d1 = line[1:-1] - line[:-2]
    d2 = line[2:] - line[1:-1]
    cross = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    keep = np.concatenate([[True], cross > 1e-6 * (np.hypot(*d1.T) * np.hypot(*d2.T) + 1e-12), [True]])
    kept: FloatArray = line[keep]
    return kept
