"""Geometry comparisons the drawing tests share."""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


def resample(lines: Sequence[Array], spacing: float) -> Array:
    """Points every `spacing` along every polyline (vertices included)."""
    out = []
    for line in lines:
        line = np.asarray(line, dtype=float).reshape(-1, 2)
        out.append(line)
        for a, b in itertools.pairwise(line):
            n = int(np.ceil(np.hypot(*(b - a)) / spacing))
            if n > 1:
                t = np.linspace(0, 1, n + 1)[1:-1, None]
                out.append(a + t * (b - a))
    return np.concatenate(out)


def normalised(points: Array) -> Array:
    """Points moved and scaled so their bounding box starts at 0 and its longer side is 1."""
    lo = points.min(axis=0)
    size = float((points.max(axis=0) - lo).max())
    return (points - lo) / size


def hausdorff(a: Array, b: Array) -> float:
    """Symmetric Hausdorff distance between two point sets."""
    def one_way(p: Array, q: Array) -> float:
        worst = 0.0
        for chunk in np.array_split(p, max(1, len(p) // 2000)):
            d = np.hypot(chunk[:, None, 0] - q[None, :, 0], chunk[:, None, 1] - q[None, :, 1]).min(axis=1)
            worst = max(worst, float(d.max()))
        return worst

    return max(one_way(a, b), one_way(b, a))


def shape_distance(drawn: Sequence[Array], expected: Sequence[Array], *, flip_expected_y: bool = True) -> float:
    """How far two drawings differ once each is scaled to a unit box (as a share of the drawing's size)."""
    flip = np.array([1.0, -1.0 if flip_expected_y else 1.0])
    exp = [np.asarray(e, dtype=float).reshape(-1, 2) * flip for e in expected]

    def dense(lines: Sequence[Array]) -> Array:
        vertices = np.concatenate([np.asarray(line, dtype=float).reshape(-1, 2) for line in lines])
        return normalised(resample(lines, float(np.ptp(vertices, axis=0).max()) / 400))

    return hausdorff(dense(drawn), dense(exp))


def segments(lines: Sequence[Array], digits: int = 3) -> Counter[tuple[tuple[float, float], tuple[float, float]]]:
    """The multiset of straight pen-down segments, each direction-free."""
    out: Counter[tuple[tuple[float, float], tuple[float, float]]] = Counter()
    for line in lines:
        pts = [(round(float(x), digits), round(float(y), digits)) for x, y in np.asarray(line).reshape(-1, 2)]
        for a, b in itertools.pairwise(pts):
            if a != b:
                out[(a, b) if a <= b else (b, a)] += 1
    return out
