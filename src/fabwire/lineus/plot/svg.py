"""SVG documents to the pen lines a browser shows: every visible shape's outline with its transforms, viewports
and clip paths applied, curves flattened to a chord tolerance. Output is in CSS px of the page (y down).

Rendering follows SVG 1.1 / SVG 2 as browsers do: `<symbol>`, `<defs>`, `<clipPath>` and the like are drawn only
through `<use>` or as clips (§5.5, §5.6); `<use width height>` of a symbol or svg is a new viewport its viewBox
maps onto (§7.8); `display="none"`, `visibility="hidden"` and `opacity="0"` hide (§6, §14.5); a lone moveto is
never stroked, and a zero-length subpath only with round or square caps, as a dot (SVG 2 §13.6); clip paths cut
the geometry (§14.3). A standalone document shows no more than its root's box when that has a definite size,
so lines beyond it are cut away. Geometry attributes follow the browsers' error handling (see svgunits): an
attribute in error is ignored, a size of zero shows nothing, a transform that flattens the plane hides. What
cannot be honoured (masks, markers, text, CSS transforms) is named in `notes`, never drawn otherwise.
"""

from __future__ import annotations

import io
import math
import re
import xml.etree.ElementTree as ET
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from fabwire.errors import InputError
from fabwire.lineus.plot.clip import area_of_rings, cut
from fabwire.lineus.plot.geometry import FloatArray, Polylines, affine
from fabwire.lineus.plot.geometry import compose as then
from fabwire.lineus.plot.svgpath import (
    PathBuilder,
    PathDataError,
    Subpath,
    ellipse,
    is_straight,
    line,
    numbers,
    path_data,
    polyline,
    rect,
    straight_paths,
)
from fabwire.lineus.plot.svgstyle import StyleSheet, inherit, iri, local, number, own_style, paints
from fabwire.lineus.plot.svgunits import (
    IDENTITY,
    beyond_single,
    flattens,
    length,
    read_view_box,
    size_is_zero,
    transform,
    translate,
    viewport_matrix,
)

SVG_NS = "http://www.w3.org/2000/svg"
XLINK_HREF = "{http://www.w3.org/1999/xlink}href"
RELATIVE_TOLERANCE = 2e-4
"""Chord tolerance as a share of the page diagonal when none is given."""
MAX_USE_COPIES = 200_000
"""Shapes `<use>` may add by copying: a bound on expansion (a few KB can otherwise ask for 2^30 copies)."""
MAX_POINTS = 20_000_000
"""Points in one drawing: days of drawing for a Line-us, and about 320 MB of coordinates."""
MAX_DEPTH = 200
"""Nesting of elements and `<use>` references."""
READ_AHEAD_CHARS = 100_000
"""Path data up to this length is read ahead with all the others; longer data is read on its own, in place."""

_CSS_TRANSFORM = re.compile(r"(?:^|;)\s*transform\s*:")

SHAPES = frozenset({"path", "rect", "circle", "ellipse", "line", "polyline", "polygon"})
CONTAINERS = frozenset({"svg", "g", "a", "switch", "use"})
UNDRAWABLE = frozenset({"text", "image", "foreignObject"})


@dataclass
class SvgDrawing:
    lines: Polylines
    skipped: dict[str, int] = field(default_factory=dict)
    """Visible elements that hold nothing a pen can draw (text, images), by tag."""
    notes: list[str] = field(default_factory=list)
    """What the file shows that the plan leaves out or draws differently, one sentence each."""
    hidden: Polylines = field(default_factory=list)
    """Parts of lines cut away by clip paths (not drawn; a preview may show them faintly)."""
    curved: bool = False
    """Whether any curve was flattened (so a finer tolerance would change the lines)."""
    tolerance: float = 0.0
    """The chord tolerance used, px."""
    size: tuple[float, float] = (0.0, 0.0)
    """The page's width and height, px."""
    empty_reason: str = ""
    """Why a browser shows nothing of the whole file, when that is known before drawing (a viewport of size 0)."""


def _read_root(source: str | Path | bytes) -> tuple[ET.Element, str]:
    if isinstance(source, bytes):
        name, data = "SVG data", source
    elif isinstance(source, str) and source.lstrip().startswith("<"):
        name, data = "SVG text", source.encode("utf-8")
    else:
        name = str(source)
        try:
            data = Path(source).read_bytes()
        except FileNotFoundError as exc:
            raise InputError(f"{name}: no such file") from exc
        except OSError as exc:
            raise InputError(f"{name}: cannot read ({exc.strerror or exc})") from exc
    try:
        root = ET.parse(io.BytesIO(data)).getroot()
    except ET.ParseError as exc:
        raise InputError(f"{name}: not a readable SVG (XML error: {exc})") from exc
    except (RecursionError, ValueError, UnicodeError) as exc:
        raise InputError(f"{name}: not a readable SVG ({type(exc).__name__})") from exc
    if local(root.tag) != "svg":
        raise InputError(f"{name}: not a readable SVG (the root element is <{local(root.tag)}>, not <svg>)")
    return root, name


def parse_svg(source: str | Path | bytes, *, tolerance: float | None = None) -> SvgDrawing:
    """Read an SVG file, SVG bytes or text starting with '<' into the pen lines a browser would show.

    `tolerance` is the largest chord error in page px (default: a share of the page diagonal). Raises
    InputError for unreadable files, `<use>` cycles, and expansions past MAX_USE_COPIES or MAX_POINTS.
    """
    if tolerance is not None and not tolerance > 0:
        raise InputError(f"curve tolerance must be positive, got {tolerance}")
    root, name = _read_root(source)
    vb = read_view_box(root.get("viewBox"))
    for which in ("width", "height"):
        if size_is_zero(root.get(which)):
            return SvgDrawing([], empty_reason=f"its {which} is 0, which disables rendering: a browser shows nothing")
    if vb.empty:
        return SvgDrawing([], empty_reason=f"its viewBox {vb.error}, which disables rendering: a browser shows "
                                           "nothing")
    box = vb.box
    page = _page_size(root.get("width"), root.get("height"))
    width, height = page or (0.0, 0.0)
    if width <= 0 or height <= 0:
        width, height = (box[2], box[3]) if box else (1000.0, 1000.0)
    if tolerance is None:
        tolerance = RELATIVE_TOLERANCE * math.hypot(width, height)
    reader = _Reader(root, name, tolerance)
    if vb.error:
        reader.unsupported[f"the viewBox {root.get('viewBox', '')[:60]!r} is in error ({vb.error}): ignored, as "
                           "browsers do"] += 1
    try:
        reader.check_expansion()
        matrix = viewport_matrix(box, 0.0, 0.0, width, height, root.get("preserveAspectRatio"))
        style = inherit({}, own_style(root, reader.sheet))
        if style.get("display") != "none" and _opacity(style) > 0:
            reader.children(root, style, then(matrix, reader.own_transform(root)),
                            (box[2], box[3]) if box else (width, height), reader.lines, 0, ())
        if page:  # a standalone document shows its root's box only, whatever its overflow
            reader.clip_to_page(width, height)
    except RecursionError as exc:
        raise InputError(f"{name}: elements nested too deeply to read") from exc
    except (ValueError, TypeError, ZeroDivisionError, shapely.errors.ShapelyError) as exc:
        raise InputError(f"{name}: malformed SVG geometry ({exc})") from exc
    return SvgDrawing(reader.lines, dict(reader.skipped), reader.report(), reader.hidden, reader.curved,
                      tolerance, (width, height))


def _opacity(style: dict[str, str]) -> float:
    return number(style.get("opacity"), 1.0)


def _without_area(points: FloatArray) -> bool:
    """Whether all points lie on one straight line (so a fill of them covers nothing)."""
    spread = points - points[0]
    far = spread[int(np.argmax(np.abs(spread).sum(axis=1)))]
    cross = spread[:, 0] * far[1] - spread[:, 1] * far[0]
    scale = float(np.abs(far).sum()) ** 2
    return bool(np.abs(cross).max() <= 1e-12 * scale)


def _page_size(width: str | None, height: str | None) -> tuple[float, float] | None:
    """The root's width and height in px when both are definite lengths (not percentages of a window, not in
    error, not negative): the page a browser clips the drawing to."""
    if not width or not height or "%" in width + height:
        return None
    w, h = length(width, 0.0, default=-1.0), length(height, 0.0, default=-1.0)
    return (w, h) if w > 0 and h > 0 else None


class _Reader:
    def __init__(self, root: ET.Element, name: str, tolerance: float) -> None:
        self.root = root
        self.name = name
        self.tolerance = tolerance
        self.ids = {el.get("id"): el for el in root.iter() if el.get("id")}
        self.sheet = StyleSheet()
        for el in root.iter():
            if local(el.tag) == "style" and el.text:
                self.sheet.add(el.text)
        self.lines: Polylines = []
        self.hidden: Polylines = []
        self.skipped: Counter[str] = Counter()
        self.unsupported: Counter[str] = Counter()
        self.curved = False
        self.points = 0
        self._clips: dict[tuple[int, bytes], BaseGeometry] = {}
        self._read_ahead = self._read_straight_paths()

    # -- limits -----------------------------------------------------------------------------------------------

    def check_expansion(self) -> None:
        """Count the shape copies `<use>` makes before drawing any, refusing cycles and fan-out bombs."""
        weights: dict[tuple[int, bool], int] = {}

        def weight(el: ET.Element, stack: tuple[str, ...], depth: int, used: bool) -> int:
            """Shapes drawn for `el`; `used` when reached through a <use> (symbols are drawn only so)."""
            if depth > MAX_DEPTH:
                raise InputError(f"{self.name}: elements or <use> references nested deeper than {MAX_DEPTH}")
            key = (id(el), used)
            if key in weights:
                return weights[key]
            tag = local(el.tag)
            total = 0
            if tag in SHAPES:
                total = 1
            elif tag == "use":
                ref = self._href(el)
                target = self.ids.get(ref) if ref else None
                if ref in stack:
                    raise InputError(f"{self.name}: <use> refers back to itself through #{ref}")
                if target is not None and ref:
                    total = weight(target, (*stack, ref), depth + 1, True)
            elif tag in CONTAINERS or (tag == "symbol" and used):
                for child in el:
                    total += weight(child, stack, depth + 1, False)
                    if total > MAX_USE_COPIES * 64:
                        break
            weights[key] = total
            return total

        direct = sum(1 for el in self.root.iter() if local(el.tag) in SHAPES)
        total = weight(self.root, (), 0, False)
        if total - direct > MAX_USE_COPIES:
            raise InputError(f"{self.name}: <use> elements copy its {direct:,} shapes more than {MAX_USE_COPIES:,} "
                             "times; refusing such an expansion")

    def _read_straight_paths(self) -> dict[int, list[Subpath]]:
        """The subpaths (in user units) of the file's short straight-line paths, read all at once: a generated
        drawing of thousands of paths costs one array pass instead of thousands. Longer paths, curves and
        anything unusual are read one by one where drawn."""
        paths = [el for el in self.root.iter() if local(el.tag) == "path"
                 and 0 < len(el.get("d") or "") <= READ_AHEAD_CHARS and is_straight(el.get("d") or "")]
        if len(paths) < 2:
            return {}
        read = straight_paths([el.get("d") or "" for el in paths])
        return {id(el): subs for el, subs in zip(paths, read, strict=True)} if read is not None else {}

    def own_transform(self, el: ET.Element) -> FloatArray:
        """The element's `transform`; one in error is ignored (with a note), as browsers ignore it."""
        value = el.get("transform")
        try:
            return transform(value)
        except ValueError as exc:
            self.unsupported[f"the transform {(value or '')[:60]!r} on <{local(el.tag)}> is in error ({exc}): "
                             "ignored, as browsers do"] += 1
            return IDENTITY

    def clip_to_page(self, width: float, height: float) -> None:
        """Cut the drawing to the page, (0, 0)-(width, height) px, as a browser shows no more of it."""
        if not self.lines:
            return
        starts = np.cumsum([0] + [len(line) for line in self.lines[:-1]])
        points = np.concatenate(self.lines)
        low = np.minimum.reduceat(points, starts)
        high = np.maximum.reduceat(points, starts)
        inside = (low >= 0).all(axis=1) & (high[:, 0] <= width) & (high[:, 1] <= height)
        if inside.all():
            return
        crossing = np.flatnonzero(~inside).tolist()
        kept, hidden = cut([self.lines[k] for k in crossing], shapely.box(0.0, 0.0, width, height))
        self.lines = [line for line, keep in zip(self.lines, inside.tolist(), strict=True) if keep] + kept
        self.hidden.extend(hidden)
        self.unsupported[f"lines outside the {width:g} x {height:g} px page are hidden, as a browser hides them"] += 1

    def report(self) -> list[str]:
        notes = [f"{what} ({count}x)" if count > 1 else what for what, count in sorted(self.unsupported.items())]
        if self.sheet.ignored:
            shown = ", ".join(sorted(set(self.sheet.ignored))[:5])
            notes.append(f"CSS rules with selectors other than type, #id and .class were ignored: {shown}")
        return notes

    # -- walking ----------------------------------------------------------------------------------------------

    @staticmethod
    def _href(el: ET.Element) -> str | None:
        href = (el.get("href") or el.get(XLINK_HREF) or "").strip()
        return href[1:] if href.startswith("#") else (href or None)

    def children(self, el: ET.Element, style: dict[str, str], matrix: FloatArray, viewport: tuple[float, float],
                 out: Polylines, depth: int, uses: tuple[str, ...]) -> None:
        kids: Iterator[ET.Element] = iter(el)
        if local(el.tag) == "switch":  # the first child that qualifies; no extension is supported (SVG 1.1 §5.8.2)
            kids = iter([k for k in el if local(k.tag) in SHAPES | CONTAINERS | UNDRAWABLE
                         and not (k.get("requiredExtensions") or "").strip()][:1])
        for child in kids:
            self.element(child, style, matrix, viewport, out, depth + 1, uses)

    def element(self, el: ET.Element, parent: dict[str, str], matrix: FloatArray, viewport: tuple[float, float],
                out: Polylines, depth: int, uses: tuple[str, ...]) -> None:
        tag = local(el.tag)
        namespace = el.tag[1:].split("}")[0] if isinstance(el.tag, str) and el.tag.startswith("{") else SVG_NS
        if namespace != SVG_NS or not (tag in SHAPES or tag in CONTAINERS or tag in UNDRAWABLE):
            return
        own = own_style(el, self.sheet)
        style = inherit(parent, own)
        if own.get("display", "").strip() == "none" or _opacity(own) <= 0:
            return
        own_matrix = self.own_transform(el)
        if own_matrix is not IDENTITY:
            matrix = then(matrix, own_matrix)
        if flattens(matrix):
            return  # scaled to a line or a point: nothing of it shows
        if _CSS_TRANSFORM.search(el.get("style") or ""):
            self.unsupported["the CSS transform property is not applied (use the transform attribute)"] += 1
        target: Polylines = []
        if tag in SHAPES:
            self.shape(el, tag, style, matrix, viewport, target)
        elif tag in UNDRAWABLE:
            if style.get("visibility", "visible") == "visible":
                self.skipped["text" if tag == "text" else "image" if tag == "image" else tag] += 1
        elif tag == "use":
            self.use(el, style, matrix, viewport, target, depth, uses)
        elif tag == "svg":
            self.viewport(el, el, style, matrix, viewport, target, depth, uses, None, None)
        else:
            self.children(el, style, matrix, viewport, target, depth, uses)
        if own.get("mask", "none").strip() != "none":
            self.unsupported["masks are not applied: masked elements are drawn whole"] += 1
        clip = own.get("clip-path", "none").strip()
        if clip != "none" and target:
            region = self.clip_region(clip, matrix, target, ())
            if region is not None:
                target, hidden = cut(target, region)
                self.hidden.extend(hidden)
        out.extend(target)

    def use(self, el: ET.Element, style: dict[str, str], matrix: FloatArray, viewport: tuple[float, float],
            out: Polylines, depth: int, uses: tuple[str, ...]) -> None:
        ref = self._href(el)
        target = self.ids.get(ref) if ref else None
        if target is None:
            self.unsupported[f"<use> of {ref or 'nothing'!r}, which is not in this file, draws nothing"] += 1
            return
        if ref in uses or depth > MAX_DEPTH:
            raise InputError(f"{self.name}: <use> refers back to itself through #{ref}")
        if beyond_single(el.get("x")) or beyond_single(el.get("y")):
            return  # placed at infinity: nothing of the copy is on the page
        vw, vh = viewport
        matrix = then(matrix, translate(length(el.get("x"), vw), length(el.get("y"), vh)))
        kind = local(target.tag)
        if kind in ("symbol", "svg"):
            self.viewport(target, el, inherit(style, own_style(target, self.sheet)), matrix, viewport, out,
                          depth, (*uses, str(ref)), el.get("width"), el.get("height"))
        else:
            self.element(target, style, matrix, viewport, out, depth + 1, (*uses, str(ref)))

    def viewport(self, el: ET.Element, placed_by: ET.Element, style: dict[str, str], matrix: FloatArray,
                 viewport: tuple[float, float], out: Polylines, depth: int, uses: tuple[str, ...],
                 width: str | None, height: str | None) -> None:
        """A nested `<svg>` or a used `<symbol>`: a viewport its viewBox maps onto, clipping unless overflow is
        visible (SVG 1.1 §7.9, §14.3.3)."""
        vw, vh = viewport
        x = length(el.get("x"), vw) if el is placed_by else 0.0
        y = length(el.get("y"), vh) if el is placed_by else 0.0
        w = length(width if width is not None else el.get("width"), vw, default=vw)
        h = length(height if height is not None else el.get("height"), vh, default=vh)
        vb = read_view_box(el.get("viewBox"))
        if w <= 0 or h <= 0 or vb.empty:
            return
        if vb.error:
            self.unsupported[f"the viewBox {el.get('viewBox', '')[:60]!r} on <{local(el.tag)}> is in error "
                             f"({vb.error}): ignored, as browsers do"] += 1
        box = vb.box
        inner = then(matrix, viewport_matrix(box, x, y, w, h, el.get("preserveAspectRatio")))
        drawn: Polylines = []
        self.children(el, style, inner, (box[2], box[3]) if box else (w, h), drawn, depth, uses)
        if style.get("overflow", "hidden").strip() in ("hidden", "scroll") and drawn:
            corners = np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h], [x, y]])
            ring = corners @ matrix[:, :2].T + matrix[:, 2]
            drawn, hidden = cut(drawn, shapely.Polygon(ring))
            self.hidden.extend(hidden)
        out.extend(drawn)

    def subpaths(self, el: ET.Element, tag: str, matrix: FloatArray, viewport: tuple[float, float]) -> list[Subpath]:
        ahead = self._read_ahead.pop(id(el), None) if tag == "path" else None
        if ahead is not None:
            placed = affine([sub.points for sub in ahead], matrix)
            return [Subpath(points, sub.closed, sub.segments) for points, sub in zip(placed, ahead, strict=True)]
        builder = PathBuilder(matrix, self.tolerance)
        vw, vh = viewport
        diag = math.hypot(vw, vh) / math.sqrt(2)

        def get(name: str, relative: float, default: float = 0.0) -> float:
            return length(el.get(name), relative, default=default)

        try:
            if tag == "path":
                path_data(builder, el.get("d") or "")
            elif tag == "rect":
                rx = el.get("rx")
                ry = el.get("ry")
                rect(builder, get("x", vw), get("y", vh), get("width", vw), get("height", vh),
                     None if rx is None or rx == "auto" else get("rx", vw),
                     None if ry is None or ry == "auto" else get("ry", vh))
            elif tag == "circle":
                r = get("r", diag)
                ellipse(builder, get("cx", vw), get("cy", vh), r, r)
            elif tag == "ellipse":
                ellipse(builder, get("cx", vw), get("cy", vh), get("rx", vw), get("ry", vh))
            elif tag == "line":
                line(builder, get("x1", vw), get("y1", vh), get("x2", vw), get("y2", vh))
            else:
                polyline(builder, numbers(el.get("points") or ""), close=(tag == "polygon"))
        except ValueError as exc:
            why = f" ({exc})" if isinstance(exc, PathDataError) else ""
            self.unsupported[f"<{tag}> data with an error{why} is drawn up to the error, as browsers do"] += 1
        self.curved = self.curved or builder.curved
        return builder.subpaths

    def shape(self, el: ET.Element, tag: str, style: dict[str, str], matrix: FloatArray,
              viewport: tuple[float, float], out: Polylines) -> None:
        if style.get("visibility", "visible").strip() != "visible":
            return
        stroke, fill = paints(style, "stroke"), paints(style, "fill")
        if not (stroke or fill):
            return
        dots = stroke and style.get("stroke-linecap", "butt").strip() in ("round", "square")
        if any(style.get(k, "none").strip() != "none" for k in ("marker", "marker-start", "marker-mid",
                                                                 "marker-end")):
            self.unsupported["markers (arrowheads and the like) are not drawn"] += 1
        for sub in self.subpaths(el, tag, matrix, viewport):
            if sub.segments == 0:
                continue  # a lone moveto is never stroked
            pts = sub.points
            if not np.isfinite(pts).all():
                self.unsupported["subpaths with coordinates that are not finite numbers are left out"] += 1
                continue
            if not stroke and _without_area(pts):
                continue  # a fill with no area shows nothing
            if bool((pts == pts[0]).all()):
                if dots:
                    out.append(pts[:1].copy())
                    self.points += 1
                continue
            self.points += len(pts)
            if self.points > MAX_POINTS:
                raise InputError(f"{self.name}: the drawing has more than {MAX_POINTS:,} points; refusing it")
            out.append(pts)

    # -- clipping ---------------------------------------------------------------------------------------------

    def clip_region(self, value: str, matrix: FloatArray, content: Polylines,
                    stack: tuple[str, ...]) -> BaseGeometry | None:
        """The area `clip-path: value` lets through, in output units; None (and a note) when it can't be used."""
        ref = iri(value)
        clip = self.ids.get(ref) if ref else None
        if clip is None or local(clip.tag) != "clipPath":
            self.unsupported[f"clip-path {value!r} does not name a clipPath here: drawn unclipped"] += 1
            return None
        if ref in stack:
            raise InputError(f"{self.name}: clip path #{ref} refers back to itself")
        by_box = clip.get("clipPathUnits", "").strip() == "objectBoundingBox"
        if by_box:
            pts = np.concatenate(content)
            inverse = np.linalg.inv(np.vstack([matrix, [0.0, 0.0, 1.0]]))[:2]
            user = pts @ inverse[:, :2].T + inverse[:, 2]
            (x0, y0), (x1, y1) = user.min(axis=0), user.max(axis=0)
            matrix = then(matrix, np.array([[x1 - x0, 0.0, x0], [0.0, y1 - y0, y0]]))
        matrix = then(matrix, self.own_transform(clip))
        key = (id(clip), matrix.tobytes())
        if key in self._clips and not by_box:
            return self._clips[key]
        base = inherit({}, own_style(clip, self.sheet))
        region: BaseGeometry = shapely.Polygon()
        for child in clip:
            region = shapely.union(region, self._clip_child(child, base, matrix, (*stack, str(ref))))
        own_clip = own_style(clip, self.sheet).get("clip-path", "none").strip()
        if own_clip != "none":
            outer = self.clip_region(own_clip, matrix, content, (*stack, str(ref)))
            if outer is not None:
                region = shapely.intersection(region, outer)
        self._clips[key] = region
        return region

    def _clip_child(self, child: ET.Element, base: dict[str, str], matrix: FloatArray,
                    stack: tuple[str, ...]) -> BaseGeometry:
        empty = shapely.Polygon()
        tag = local(child.tag)
        own = own_style(child, self.sheet)
        style = inherit(base, own)
        if own.get("display", "").strip() == "none" or style.get("visibility", "visible").strip() != "visible":
            return empty
        matrix = then(matrix, self.own_transform(child))
        if flattens(matrix):
            return empty
        if tag == "use":
            ref = self._href(child)
            target = self.ids.get(ref) if ref else None
            if target is None or local(target.tag) not in SHAPES | UNDRAWABLE:
                return empty
            moved = then(matrix, translate(length(child.get("x"), 0.0), length(child.get("y"), 0.0)))
            return self._clip_child(target, style, moved, stack)
        if tag in UNDRAWABLE:
            self.unsupported["text in a clip path cannot be drawn: it was left out of the clip"] += 1
            return empty
        if tag not in SHAPES:
            return empty
        rings = [np.vstack([s.points, s.points[:1]]) for s in self.subpaths(child, tag, matrix, (0.0, 0.0))
                 if len(s.points) >= 3]
        region = area_of_rings(rings, style.get("clip-rule", "nonzero").strip())
        inner = own.get("clip-path", "none").strip()
        if inner != "none":
            content = list(rings) or [np.zeros((1, 2))]
            limit = self.clip_region(inner, matrix, content, stack)
            if limit is not None:
                region = shapely.intersection(region, limit)
        return region
