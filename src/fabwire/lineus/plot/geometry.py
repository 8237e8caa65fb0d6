"""Polylines as numpy arrays, and the transforms that place a drawing on the machine."""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
Polylines = list[FloatArray]
"""Each polyline an (n, 2) float array, n >= 1 (a single point is a dot)."""


def flatten(lines: Sequence[FloatArray]) -> tuple[FloatArray, IntArray]:
    """All points of `lines` in one (N, 2) array, and the offsets (len(lines) + 1) where each line starts and the
    last ends: the whole drawing for one numpy operation instead of one per line."""
    sizes = np.fromiter((len(line) for line in lines), dtype=np.int64, count=len(lines))
    offsets = np.zeros(len(lines) + 1, dtype=np.int64)
    np.cumsum(sizes, out=offsets[1:])
    points = np.concatenate(lines).reshape(-1, 2) if lines else np.zeros((0, 2))
    return points.astype(float, copy=False), offsets


def split_at(points: FloatArray, offsets: IntArray) -> Polylines:
    """The inverse of `flatten`: each line as a view of `points`, from `offsets` (len(lines) + 1 of them). What
    `np.split` gives, in a fraction of its time for thousands of lines."""
    return [points[a:b] for a, b in itertools.pairwise(offsets.tolist())]


def extent(points: FloatArray) -> tuple[float, float, float, float]:
    """(x_min, y_min, x_max, y_max) of an (N, 2) array with N >= 1: column by column, which numpy reduces many
    times faster than along the short axis of the whole array."""
    xs, ys = points[:, 0], points[:, 1]
    return (float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max()))


def inner_segments(offsets: IntArray) -> BoolArray:
    """For the N-1 steps between consecutive points of a flattened drawing: True where both points belong to the
    same line (a stroke's segment), False for the jump from one line's end to the next line's start."""
    inner = np.ones(max(int(offsets[-1]) - 1, 0), dtype=bool)
    cuts = offsets[1:-1] - 1
    inner[cuts[(cuts >= 0) & (cuts < len(inner))]] = False
    return inner


def as_polylines(lines: Iterable[Sequence[tuple[float, float]] | FloatArray]) -> Polylines:
    """Normalise any sequences of points to (n, 2) float arrays, dropping empty ones."""
    out: Polylines = []
    for line in lines:
        arr = np.asarray(line, dtype=float).reshape(-1, 2)
        if len(arr):
            out.append(arr)
    return out


def bbox(lines: Sequence[FloatArray]) -> tuple[float, float, float, float]:
    """(x_min, y_min, x_max, y_max) of all points; ValueError when there are none."""
    if not lines:
        raise ValueError("no points")
    return extent(np.concatenate(lines).reshape(-1, 2))


def segment_count(lines: Sequence[FloatArray]) -> int:
    """Pen-down straight segments (a dot counts as none)."""
    return sum(max(0, len(line) - 1) for line in lines)


def drawn_length(lines: Sequence[FloatArray]) -> float:
    """Total pen-down length."""
    if not lines:
        return 0.0
    points, offsets = flatten(lines)
    d = np.diff(points, axis=0)[inner_segments(offsets)]
    return float(np.hypot(d[:, 0], d[:, 1]).sum())


def affine(lines: Sequence[FloatArray], matrix: FloatArray) -> Polylines:
    """Apply a 2x3 affine matrix [[a, b, tx], [c, d, ty]] to every point."""
    lin = matrix[:, :2].T
    off = matrix[:, 2]
    with np.errstate(over="ignore", invalid="ignore"):  # points beyond a float become inf: the planner refuses them
        return [line @ lin + off for line in lines]


def rotation(degrees: float) -> FloatArray:
    """Counter-clockwise rotation about the origin, as a 2x3 matrix."""
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0]])


def scale_translate(scale: float, dx: float, dy: float, *, flip_y: bool = False) -> FloatArray:
    """x' = s·x + dx, y' = ±s·y + dy as a 2x3 matrix."""
    return np.array([[scale, 0.0, dx], [0.0, -scale if flip_y else scale, dy]])


def compose(second: FloatArray, first: FloatArray) -> FloatArray:
    """The 2x3 matrix doing `first` then `second`."""
    out: FloatArray = second[:, :2] @ first
    out[:, 2] += second[:, 2]
    return out


MAX_DASHES = 1_000_000
"""Dashes one line may be cut into at most (a tiny dash array over a long line is drawn solid beyond this)."""


def dash_count(line: FloatArray, pattern: Sequence[float]) -> int:
    """Dashes a `pattern` (as for `dashed`) cuts `line` into, at most one more than exact, found from the line's
    length alone (so a refusal costs no dash); 0 for a pattern with no positive period."""
    values = list(pattern) * (2 if len(pattern) % 2 else 1)
    period = float(sum(values))
    if len(line) < 2 or not period > 0:
        return 0
    total = float(np.hypot(*np.diff(line, axis=0).T).sum())
    return (math.floor(total / period) + 1) * (len(values) // 2)


def dashed(line: FloatArray, pattern: Sequence[float], offset: float = 0.0) -> Polylines:
    """The dashes of `line` for a dash `pattern` (alternate dash and gap lengths, at least one positive, none
    negative; an odd count is repeated, SVG 1.1 §11.4) started `offset` along the pattern. A dash of length 0 comes
    out as a single point. The line itself (one dash) when the pattern would cut it into more than MAX_DASHES."""
    values = list(pattern) * (2 if len(pattern) % 2 else 1)
    period = float(sum(values))
    if len(line) < 2 or not period > 0:
        return [line]
    steps = np.hypot(*np.diff(line, axis=0).T)
    along = np.concatenate([[0.0], np.cumsum(steps)])
    total = float(along[-1])
    if dash_count(line, pattern) > MAX_DASHES:
        return [line]
    bounds = np.cumsum([0.0, *values])
    start = -(offset % period)
    cycles = np.arange(start, total, period)
    dash_starts = (cycles[:, None] + bounds[:-1:2][None, :]).ravel()
    dash_ends = (cycles[:, None] + bounds[1::2][None, :]).ravel()
    out: Polylines = []
    for a, b in zip(dash_starts.tolist(), dash_ends.tolist(), strict=True):
        a, b = max(a, 0.0), min(b, total)
        if b < a:
            continue
        inner = np.flatnonzero((along > a) & (along < b))
        points = [np.array([np.interp(a, along, line[:, 0]), np.interp(a, along, line[:, 1])])]
        points.extend(line[inner])
        if b > a:
            points.append(np.array([np.interp(b, along, line[:, 0]), np.interp(b, along, line[:, 1])]))
        out.append(np.array(points))
    return out
