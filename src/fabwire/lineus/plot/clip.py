"""Clip regions (SVG 1.1 §14.3: the filled area of a clipPath's shapes, each by its clip-rule) and the cutting of
pen lines to them: the parts inside are drawn, the parts outside are kept apart so a preview can show them."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from fabwire.errors import InputError
from fabwire.lineus.plot.geometry import FloatArray, Polylines


class TooComplex(InputError):
    """Geometry whose clipping or filling would cost unbounded time and memory; the reader adds the file's name."""


CLIP_PIECE_POINTS = 256
"""Points of one line handed to GEOS at a time. GEOS nodes a line against itself before cutting it, which costs the
square of the line's length when the line retraces itself (a path circling the same ring thousands of times took
many GB); cut piece by piece the work grows linearly, and the parts inside and outside are the same."""
MAX_CLIP_PARTS = 1_000_000
"""Pieces cutting may produce at most for one drawing's clip (a line crossing itself in a piece is split at every
crossing, so a small piece can still come out as thousands of parts; beyond this the drawing is refused)."""
MAX_CROSSING_RING_POINTS = 10_000
"""Points a ring crossing itself may have for its filled area to be found (GEOS nodes it against itself, which costs
the square of its length for a ring retracing itself; a ring that does not cross itself has no limit)."""


def area_of_rings(rings: Sequence[FloatArray], rule: str) -> BaseGeometry:
    """The area one shape fills: its closed rings combined by `rule` ('evenodd' or 'nonzero').

    Non-zero winding is taken ring by ring: a ring wound against the largest one and lying inside the area so far
    cuts a hole, any other ring adds area (exact for shapes without self-overlapping rings). Raises TooComplex for
    a ring of more than MAX_CROSSING_RING_POINTS points that crosses itself.
    """
    if len(rings) == 1 and len(rings[0]) >= 4:
        simple = shapely.Polygon(rings[0])
        if shapely.is_valid(simple):  # one ring that does not cross itself: the common case, read directly
            return simple
    polygons: list[tuple[float, BaseGeometry]] = []
    for ring in rings:
        if len(ring) < 3:
            continue
        x, y = ring[:, 0], ring[:, 1]
        signed = 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
        if signed == 0:
            continue
        polygon = shapely.Polygon(ring)
        if len(ring) > MAX_CROSSING_RING_POINTS and not shapely.is_valid(polygon):
            raise TooComplex(f"a filled shape too complex to fill: a ring of {len(ring):,} points crosses itself "
                             f"(at most {MAX_CROSSING_RING_POINTS:,})")
        # A self-crossing ring: by non-zero winding all it encloses is filled ("structure"); even-odd keeps the
        # pieces with odd crossings (the default "linework" split).
        polygons.append((signed, shapely.make_valid(polygon, method="structure") if rule != "evenodd"
                         else shapely.make_valid(polygon)))
    region: BaseGeometry = shapely.Polygon()
    if not polygons:
        return region
    polygons.sort(key=lambda item: -abs(item[0]))
    outer_sign = np.sign(polygons[0][0])
    for signed, poly in polygons:
        if rule == "evenodd":
            region = shapely.symmetric_difference(region, poly)
        elif np.sign(signed) != outer_sign and shapely.covers(region, poly):
            region = shapely.difference(region, poly)
        else:
            region = shapely.union(region, poly)
    return region


def _parts(geometry: BaseGeometry) -> Polylines:
    out: Polylines = []
    for part in shapely.get_parts(shapely.line_merge(geometry) if geometry.geom_type == "MultiLineString"
                                  else geometry):
        if part.geom_type == "LineString" and not part.is_empty:
            out.append(np.asarray(part.coords, dtype=float)[:, :2])
        elif part.geom_type in ("MultiLineString", "GeometryCollection"):
            out.extend(_parts(part))
    return out


def _pieces(line: FloatArray) -> list[FloatArray]:
    """`line` split into runs of at most CLIP_PIECE_POINTS + 1 points, each sharing its last point with the next."""
    if len(line) <= CLIP_PIECE_POINTS + 1:
        return [line]
    return [line[i:i + CLIP_PIECE_POINTS + 1] for i in range(0, len(line) - 1, CLIP_PIECE_POINTS)]


def _join(out: Polylines, parts: Polylines, start: int) -> None:
    """Append `parts` to `out`, continuing the last line of `out` (when it was added from index `start` on) where a
    part begins at its end point: the seam between two pieces of one cut line."""
    for part in parts:
        if len(out) > start and len(part) > 1 and len(out[-1]) > 1 and bool((out[-1][-1] == part[0]).all()):
            out[-1] = np.vstack([out[-1], part[1:]])
        else:
            out.append(part)


def cut(lines: Polylines, region: BaseGeometry) -> tuple[Polylines, Polylines]:
    """(kept, hidden): the pieces of `lines` inside `region` and those outside it. Dots stay whole.

    Long lines are cut CLIP_PIECE_POINTS at a time and rejoined at the seams. Raises TooComplex when the cut comes
    to more than MAX_CLIP_PARTS pieces (lines crossing themselves that many times are too complex to clip).
    """
    if not lines:
        return [], []
    if region.is_empty:
        return [], list(lines)
    shapely.prepare(region)
    kept: Polylines = []
    hidden: Polylines = []
    for line in lines:
        if len(line) == 1:
            (kept if shapely.intersects_xy(region, line[0, 0], line[0, 1]) else hidden).append(line)
            continue
        geometry = shapely.LineString(line)
        if shapely.contains_properly(region, geometry):
            kept.append(line)
        elif shapely.disjoint(region, geometry):
            hidden.append(line)
        else:
            first_kept, first_hidden = len(kept), len(hidden)
            for piece in _pieces(line):
                part = shapely.LineString(piece)
                _join(kept, _parts(shapely.intersection(part, region)), first_kept)
                _join(hidden, _parts(shapely.difference(part, region)), first_hidden)
                if len(kept) + len(hidden) > MAX_CLIP_PARTS:
                    raise TooComplex(f"lines too complex to clip: cutting them comes to more than "
                                     f"{MAX_CLIP_PARTS:,} pieces")
    return kept, hidden


def cut_edge(area: BaseGeometry, region: BaseGeometry) -> tuple[Polylines, BaseGeometry]:
    """Where `region` cuts a filled `area`: (the edges of the cut, which a browser shows as the new border of the
    fill, and the part of the area that remains)."""
    if area.is_empty or shapely.covers(region, area):
        return [], area
    if shapely.disjoint(region, area):
        return [], shapely.Polygon()
    edges = _parts(shapely.intersection(region.boundary, area))
    return edges, shapely.intersection(area, region)
