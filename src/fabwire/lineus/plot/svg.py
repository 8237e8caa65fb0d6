"""SVG documents to the pen lines a browser shows: every visible stroke along its path (dashed as drawn; a wide
one along the border of the band it paints), every solid fill along the border of the part a browser shows,
pattern fills as their own lines inside the shape, text in single-stroke letters; transforms, viewports and clip
paths applied, curves flattened to a chord tolerance.
Output is in CSS px of the page (y down).

What a pen draws for a filled shape is the outline of what a browser shows of it: a fill cut by a clip path or a
viewport is outlined along the cut too, an open subpath is closed for its fill, and a fill the colour of the paper
draws nothing (so matplotlib's white figure background neither frames the plot nor drives fitting). Shapes
painted over others do not hide what lies under them (a pen cannot unpaint): that, masks, filters and
gradients' colours are what the plan does not show as a browser does, and each is named in `notes`.

FEATURES below lists every class of SVG the reader renders as a browser does, with its source; each row names the
case of the browser comparison test (tests/lineus/test_plot_svg_conformance.py) that draws it in Chromium and
compares the ink with the plan.
"""

from __future__ import annotations

import io
import math
import re
import xml.etree.ElementTree as ET
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from fabwire.cancelling import check_cancelled
from fabwire.errors import InputError, excerpt
from fabwire.lineus.plot.clip import TooComplex, area_of_rings, cut, cut_edge
from fabwire.lineus.plot.geometry import FloatArray, Polylines, affine, dash_count, dashed
from fabwire.lineus.plot.geometry import compose as then
from fabwire.lineus.plot.gradient import Stop, shown_intervals, shown_region
from fabwire.lineus.plot.stroke import Pen, pen_of, stroke_area
from fabwire.lineus.plot.svgpath import (
    PathBuilder,
    PathDataError,
    Subpath,
    TooManyPoints,
    ellipse,
    is_straight,
    line,
    numbers,
    path_data,
    polyline,
    rect,
    straight_paths,
)
from fabwire.lineus.plot.svgstyle import (
    GEOMETRY,
    StyleSheet,
    fallback_in_error,
    inherit,
    iri,
    local,
    number,
    opaque_fill,
    opaque_stop,
    own_style,
    paints,
    same_colour,
    same_paint_value,
    solid_colour,
    stop_paint,
)
from fabwire.lineus.plot.svgtext import TEXT_MODES, TextLayout
from fabwire.lineus.plot.svgunits import (
    IDENTITY,
    ROOT_FONT_SIZE,
    Font,
    about,
    angle,
    beyond_single,
    css_transform,
    flattens,
    length,
    read_view_box,
    size_is_zero,
    transform,
    transform_origin,
    translate,
    viewport_matrix,
)

SVG_NS = "http://www.w3.org/2000/svg"
XLINK_HREF = "{http://www.w3.org/1999/xlink}href"
RELATIVE_TOLERANCE = 2e-4
"""Chord tolerance as a share of the page diagonal when none is given."""
MAX_USE_COPIES = 200_000
"""Shapes `<use>` may add by copying: a bound on expansion (a few KB can otherwise ask for 2^30 copies)."""
MAX_POINTS = 2_000_000
"""Points in one drawing: days of drawing for a Line-us, and about 32 MB of coordinates (their working copies a
few times that); curves are held to it as they are flattened (`PathBuilder.room`)."""
MAX_DEPTH = 200
"""Nesting of elements and `<use>` references."""
MAX_PATTERN_TILES = 20_000
"""Pattern tiles one fill may repeat at most; a finer pattern is drawn as the shape's outline, with a note."""
MAX_CUT_CELLS = 5_000
"""Fills of pattern tiles (tiles times the fills of one) outlined where the shape's edge cuts them; beyond, the
cut edges are left out, with a note."""
MAX_DRAWING_DASHES = 200_000
"""Dashes stroke-dasharray may cut one drawing's lines into: about half a day of pen strokes for a Line-us, and a
bound on the time and memory of cutting them (a few bytes of "0.0001 0.0001" otherwise ask for tens of millions)."""
MAX_OCCLUSION_CHECKS = 50_000_000
"""Earlier lines that opaque fills are checked against at most; beyond, later fills no longer hide lines."""
READ_AHEAD_CHARS = 100_000
"""Path data up to this length is read ahead with all the others; longer data is read on its own, in place."""
WIDE_STROKE_SHARE = 0.02
"""A stroke wider than this share of the page diagonal (about 2 mm where the page fills a Line-us's drawing area,
several pen widths) is drawn as the outline of the band it paints, caps and joins included, as a fill is; a thinner
one along its centre line."""
GRADIENTS = ("linearGradient", "radialGradient")
"""The paint servers whose colours vary over the shape (gradient.py reads where they mark the paper)."""
MAX_HREF_CHAIN = 64
"""Paint servers one pattern or gradient may take attributes and content from through `href`, itself included."""
MAX_GRADIENT_POINTS = 300_000
"""Vertices of the shown regions of gradients (gradient.shown_region) a drawing may make; beyond, gradient paints
are drawn whole, with a note."""
MAX_BAND_POINTS = 200_000
"""Points of the centre lines of wide strokes one drawing may outline at most; past that, wide strokes are drawn
along their centre lines (outlining costs GEOS buffering and union per stroke)."""
USER_LANGUAGES = ("en",)
"""The reader's languages for `systemLanguage` (a browser's default English locale), primary subtags."""

SHAPES = frozenset({"path", "rect", "circle", "ellipse", "line", "polyline", "polygon"})
CONTAINERS = frozenset({"svg", "g", "a", "switch", "use"})
UNDRAWABLE = frozenset({"text", "image", "foreignObject"})
EFFECTS = frozenset({"clip-path", "mask", "filter"})
MARKERS = frozenset({"marker", "marker-start", "marker-mid", "marker-end"})
BASIC_SHAPE = re.compile(r"\s*(circle|ellipse|inset|polygon)\(([^()]*)\)", re.IGNORECASE)
"""A clip-path that is a CSS basic shape, with its arguments; a reference box may follow."""
CONTEXT_PAINTS = {"context-fill": "fill", "context-stroke": "stroke"}
MARKABLE = frozenset({"path", "line", "polyline", "polygon"})
"""Shapes markers are drawn on (SVG 2 §13.7: markable elements)."""
MAX_MARKERS = 10_000
"""Elements marker copies may draw in one drawing at most (each vertex of a long path places a copy of every
element in its marker); past that, further markers are left out with a note."""

FEATURES: tuple[tuple[str, str, str], ...] = (
    # (feature class, source, browser comparison case)
    ("basic shapes and path data", "SVG 1.1 §8, §9", "shapes"),
    ("arcs and curves flattened within the tolerance", "SVG 1.1 §8.3, F.6", "curves and arcs"),
    ("rect rx/ry auto, clamped, negative in error", "SVG 2 §10.2", "rect rx auto"),
    ("transform attribute lists", "SVG 1.1 §7.6", "nested transforms"),
    ("CSS transform property with units", "CSS Transforms 1 §13", "css transform"),
    ("transform-origin, keywords and percentages", "CSS Transforms 1 §7", "transform-origin"),
    ("viewBox and preserveAspectRatio", "SVG 1.1 §7.7, §7.8", "viewbox aspect"),
    ("nested svg viewports clip unless overflow is visible", "SVG 1.1 §7.9, §14.3.3", "nested svg clip"),
    ("use of symbol and svg, x y kept", "SVG 1.1 §5.6, §5.8.4", "use of svg x y"),
    ("use reference cycles leave out the looping reference", "SVG 2 §5.6.3", "use cycle"),
    ("style sheets: combinators, specificity, !important", "CSS Cascade 4 §6, Selectors 3", "css cascade"),
    ("presentation attributes below style sheets", "SVG 2 §6.6", "presentation attributes"),
    ("inherit and inherited properties", "CSS Cascade 4 §7", "inherit"),
    ("em from the inherited font size", "CSS Values 3 §6.1", "em units"),
    ("display, visibility, opacity hide", "SVG 1.1 §14.5, CSS 2.1 §9.2.4", "hidden parts"),
    ("switch with systemLanguage, requiredExtensions", "SVG 1.1 §5.8", "switch language"),
    ("stroke-dasharray and dashoffset, dots for round caps, measured along pathLength",
     "SVG 1.1 §11.4, SVG 2 §13.6, §9.3.3 (pathLength)", "dashes"),
    ("markers on path, line, polyline and polygon vertices: orient, markerUnits, viewBox, refX/refY, clip",
     "SVG 2 §13.7", "markers"),
    ("context-fill and context-stroke from the use or the marked shape; none without one", "SVG 2 §13.3",
     "context paint"),
    ("strokes wider than 2 % of the page diagonal outlined with their caps, joins and miter limit, as one shape "
     "with the element's fill", "SVG 2 §13.5, §13.6", "wide stroke joins"),
    ("fill cut by a clip path outlined along the cut", "SVG 1.1 §14.3", "clipped fill"),
    ("clip-path on the root svg", "SVG 1.1 §14.3.5", "root clip-path"),
    ("clip-path basic shapes circle(), ellipse(), inset(), polygon() on fill-, stroke- or view-box",
     "CSS Masking 1 §6.1, CSS Shapes 1 §3.1", "clip-path basic shapes"),
    ("clip path cycles leave out the looping reference", "SVG 1.1 §14.3.5", "clip cycle"),
    ("filled open subpaths close for the fill", "SVG 1.1 §11.3", "open fill"),
    ("fills the colour of the paper, or too faint at their opacity and their groups', draw nothing",
     "SVG 1.1 §11.2 (paint), §14.5 (opacity), CSS Color 4", "white fill"),
    ("pattern fills drawn inside the shape, their cells outlined where the shape's edge cuts them; tiles an "
     "opaque paint covers whole show no seams, and the shape's border", "SVG 1.1 §13.3", "pattern fill"),
    ("opaque fills of one colour that meet or overlap show one shape: no edge between them",
     "SVG 1.1 §3.3 (painter's model)", "fills of one colour meeting show one shape"),
    ("opaque fills hide the lines painted before them", "SVG 1.1 §3.3 (painter's model)", "white box over lines"),
    ("gradients whose stops are all opaque hide what lies under them", "SVG 1.1 §13.2.4, §3.3",
     "opaque gradient hides what lies under it"),
    ("the stretch of a gradient that fades into the paper draws nothing: linear and radial (focus, fr), "
     "objectBoundingBox or user space, gradientTransform, pad, repeat and reflect, on fills and strokes",
     "SVG 1.1 §13.2, SVG 2 §14.3.3", "gradient from white"),
    ("a stroke of the fill's own opaque paint (equal colours, or the same gradient) shows only the fill's border",
     "SVG 1.1 §11.3, §3.3 (painter's model)", "stroke of the fill's own colour"),
    ("text in single-stroke letters: position, size, anchor; runs without paint, or of the paper's colour, draw "
     "nothing", "SVG 1.1 §10.4, §10.9.1, §11.2", "text"),
    ("font-relative units ex, ch, cap, ic, lh from the face's metrics; rem, rlh of the root",
     "CSS Values 4 §6.1.1 (FONT_METRICS)", "font-relative units"),
    ("viewport units vw, vh, vi, vb, vmin, vmax of the page", "CSS Values 4 §6.1.2", "viewport units"),
    ("a length with an unknown unit or trailing text is in error", "CSS Values 4 §6, SVG 1.1 §F.2",
     "length in error"),
    ("paint servers under display none or failed conditions paint nothing (fallback colour)",
     "SVG 2 §13.2, §5.8.1; CSS Display 3 §2.7", "paint server not rendered"),
    ("hidden, transparent and unpainted shapes count for the group's bounding box", "SVG 2 §8.10",
     "bbox of hidden children"),
    ("a clipPath's transform and transform-origin apply in user space, outside objectBoundingBox units",
     "SVG 1.1 §14.3.5, CSS Transforms 1 §7", "clip path transform by bounding box"),
    ("a clipped group's opaque fills, once clipped, hide what lies under the group", "SVG 1.1 §14.3, §3.3",
     "clipped opaque fill hides what lies under the group"),
    ("fills in a group with opacity hide that group's earlier lines only (in a clipped group, until clipped)",
     "SVG 1.1 §14.5, Compositing and Blending 1 §3.3", "fill hides lines within a translucent group"),
)


@dataclass
class SvgDrawing:
    lines: Polylines
    skipped: dict[str, int] = field(default_factory=dict)
    """Visible elements that hold nothing a pen can draw (images; text with `text="outline"`), by tag."""
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


def _box(points: FloatArray) -> list[float]:
    return [*points.min(axis=0).tolist(), *points.max(axis=0).tolist()]


class _Fill:
    """The area a solid fill covers, in output units, from its closed rings by its fill rule (made on demand)."""

    __slots__ = ("_area", "box", "opaque", "paint", "rings", "rule")

    def __init__(self, rings: Polylines, rule: str, area: BaseGeometry | None = None, *,
                 opaque: bool = False, paint: str | None = None) -> None:
        self.rings = rings
        self.rule = rule
        self.opaque = opaque
        """Whether the paint has no transparency, so it hides what lies under it."""
        self.paint = paint
        """The solid colour it paints as written (svgstyle.solid_colour), None for any other paint."""
        self._area = area
        self.box = _box(np.concatenate(rings)) if rings else (
            shapely.bounds(area).tolist() if area is not None and not area.is_empty else [0.0, 0.0, -1.0, -1.0])
        """(x0, y0, x1, y1); an empty fill's box holds nothing."""

    @property
    def area(self) -> BaseGeometry:
        if self._area is None:
            self._area = area_of_rings(self.rings, self.rule)
        return self._area


_NO_BOXES = np.zeros((0, 4))


class _Boxes:
    """A growing (n, 4) array of boxes, amortised O(1) per box added."""

    __slots__ = ("array", "count")

    def __init__(self) -> None:
        self.array = _NO_BOXES
        self.count = 0

    def add(self, boxes: list[list[float]]) -> None:
        if not boxes:
            return
        need = self.count + len(boxes)
        if need > len(self.array):
            grown = np.zeros((max(need, 2 * len(self.array), 16), 4))
            grown[:self.count] = self.array[:self.count]
            self.array = grown
        self.array[self.count:need] = boxes
        self.count = need

    def view(self) -> FloatArray:
        return self.array[:self.count]


class Ink(list[FloatArray]):
    """Pen lines, with the solid fills they outline (so that a cut can outline a fill along the cut), and the
    boxes of both for finding what lies under a later fill."""

    def __init__(self, lines: Polylines | None = None) -> None:
        super().__init__(lines or [])
        self.fills: list[_Fill] = []
        self.extent: list[list[float]] = []
        """Boxes (x0, y0, x1, y1) of geometry that shows nothing but counts for the bounding box of the group
        (hidden, fully transparent or unpainted shapes: SVG 2 §8.10 takes every rendered element's geometry)."""
        self.bands: set[int] = set()
        """ids of the lines that outline a wide stroke's band: they lie beyond the shape's geometry, so the
        bounding box leaves them out (its geometry is in `extent`)."""
        self._boxes = _Boxes()
        self._fill_boxes = _Boxes()

    def take(self, other: Ink) -> None:
        self.extend(other)
        self.fills.extend(other.fills)
        self.extent.extend(other.extent)
        self.bands |= other.bands

    def boxes(self) -> FloatArray:
        """(x0, y0, x1, y1) of every line (lines are never changed in place, only added or replaced)."""
        if self._boxes.count > len(self):
            self._boxes = _Boxes()
        self._boxes.add([_box(line) for line in self[self._boxes.count:]])
        return self._boxes.view()

    def fill_boxes(self) -> FloatArray:
        """(x0, y0, x1, y1) of every fill (fills are only added, or replaced one by one with `set_fill`)."""
        if self._fill_boxes.count > len(self.fills):
            self._fill_boxes = _Boxes()
        self._fill_boxes.add([fill.box for fill in self.fills[self._fill_boxes.count:]])
        return self._fill_boxes.view()

    def set_fill(self, index: int, fill: _Fill) -> None:
        self.fills[index] = fill
        if index < self._fill_boxes.count:
            self._fill_boxes.array[index] = fill.box

    def replace(self, lines: Polylines) -> None:
        self[:] = lines
        self._boxes = _Boxes()

    def drop(self, indices: list[int]) -> None:
        """Take out the lines at `indices`, moving the last ones into their places (order is not kept)."""
        boxes = self.boxes()
        for k in sorted(indices, reverse=True):
            last = len(self) - 1
            self[k] = self[last]
            boxes[k] = boxes[last]
            self.pop()
            self._boxes.count -= 1


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
        tag = excerpt(local(root.tag), 40)[1:-1]
        raise InputError(f"{name}: not a readable SVG (the root element is <{tag}>, not <svg>)")
    return root, name


def parse_svg(source: str | Path | bytes, *, tolerance: float | None = None, text: str = "hershey") -> SvgDrawing:
    """Read an SVG file, SVG bytes or text starting with '<' into the pen lines a browser would show.

    `tolerance` is the largest chord error in page px (default: a share of the page diagonal). `text` is
    'hershey' (draw `<text>` in single-stroke letters) or 'outline' (leave text out, counted in `skipped`).
    Raises InputError for unreadable files and expansions past MAX_USE_COPIES or MAX_POINTS.
    """
    if tolerance is not None and not tolerance > 0:
        raise InputError(f"curve tolerance must be positive, got {tolerance}")
    if text not in TEXT_MODES:
        raise InputError(f"SVG text mode must be one of {', '.join(TEXT_MODES)}, got {text!r}")
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
    reader = _Reader(root, name, tolerance, text)
    reader.wide_stroke = WIDE_STROKE_SHARE * math.hypot(width, height)
    if vb.error:
        reader.unsupported[f"the viewBox {excerpt(root.get('viewBox', ''), 60)} is in error ({vb.error}): ignored, as "
                           "browsers do"] += 1
    try:
        reader.check_expansion()
        matrix = viewport_matrix(box, 0.0, 0.0, width, height, root.get("preserveAspectRatio"))
        own = own_style(root, reader.sheet)
        style = inherit({}, own)
        # viewport units are of the window showing the document: the page when it has a size of its own
        reader.root_font = Font(viewport=(width, height))
        reader.root_font = reader.font(style)
        if _opacity(style) > 0:  # `display` on the root of a standalone document is ignored, as in browsers
            inner = (box[2], box[3]) if box else (width, height)
            reader.user_viewport = inner
            placed = then(matrix, reader.placement(root, own, style, inner))
            drawn = Ink()
            reader.below(drawn)
            reader.children(root, style, placed, inner, drawn, 0, ())
            reader.clip(root, own, placed, drawn, ())
            reader.lines.take(drawn)
        if page:  # a standalone document shows its root's box only, whatever its overflow
            reader.clip_to_page(width, height)
    except RecursionError as exc:
        raise InputError(f"{name}: elements nested too deeply to read") from exc
    except TooComplex as exc:
        raise InputError(f"{name}: {exc}") from exc
    except TooManyPoints:
        raise InputError(f"{name}: its curves make more than {MAX_POINTS:,} points, more than a drawing may have; "
                         "refusing it") from None
    except (ValueError, TypeError, ZeroDivisionError, shapely.errors.ShapelyError) as exc:
        raise InputError(f"{name}: malformed SVG geometry ({excerpt(' '.join(str(exc).split()), 120)})") from exc
    return SvgDrawing(list(reader.lines), dict(reader.skipped), reader.report(), reader.hidden, reader.curved,
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


def _length(lines: Polylines) -> float:
    return float(sum(np.hypot(*np.diff(line, axis=0).T).sum() for line in lines))


def _border(fill: _Fill, rings: Polylines) -> Polylines | None:
    """The border of a fill's area when its closed `rings` cross or overlap (so some of them lie inside the
    fill, where a browser shows no edge); None when the rings are that border already."""
    if len(rings) == 1 and shapely.is_simple(shapely.LinearRing(rings[0])):
        return None
    if shapely.is_simple(shapely.MultiLineString(rings)):  # no ring crosses or touches another, nor itself
        if fill.rule == "evenodd":
            return None  # nested rings alternate: every ring is a border
        boxes = np.array([_box(ring) for ring in rings])
        inside = ((boxes[:, None, 0] >= boxes[None, :, 0]) & (boxes[:, None, 1] >= boxes[None, :, 1])
                  & (boxes[:, None, 2] <= boxes[None, :, 2]) & (boxes[:, None, 3] <= boxes[None, :, 3]))
        np.fill_diagonal(inside, False)
        if not inside.any():
            return None  # side by side: every ring is a border
    border = _outline(fill.area)
    drawn = _length(rings)
    return border if abs(_length(border) - drawn) > 1e-6 * drawn else None


def _stretch(matrix: FloatArray) -> float:
    return math.sqrt(abs(float(np.linalg.det(matrix[:, :2]))))


POSITION_KEYWORDS = {"left": ("x", 0.0), "right": ("x", 1.0), "top": ("y", 0.0), "bottom": ("y", 1.0),
                     "center": ("", 0.5)}


def _position(words: list[str], w: float, h: float) -> tuple[float, float]:
    """A CSS <position> of one or two parts (keywords, lengths, percentages) in the box of size w x h."""
    if not words:
        return w / 2, h / 2
    if len(words) > 2:
        raise ValueError("positions of more than two parts are not read")
    if len(words) == 2 and (POSITION_KEYWORDS.get(words[0], ("",))[0] == "y"
                            or POSITION_KEYWORDS.get(words[1], ("",))[0] == "x"):
        words = words[::-1]
    if len(words) == 1:
        axis = POSITION_KEYWORDS.get(words[0], ("x",))[0]
        words = ["center", words[0]] if axis == "y" else [words[0], "center"]
    values = []
    for word, size in zip(words, (w, h), strict=True):
        if word in POSITION_KEYWORDS:
            values.append(POSITION_KEYWORDS[word][1] * size)
        else:
            values.append(_box_length(word, size))
    return values[0], values[1]


def _box_length(word: str, size: float) -> float:
    value = length(word, size, default=math.nan)
    if math.isnan(value):
        raise ValueError(f"{word!r} is not a length")
    return value


def _radius(word: str, near: float, far: float, size: float) -> float:
    if word == "closest-side":
        return near
    if word == "farthest-side":
        return far
    value = _box_length(word, size)
    if value < 0:
        raise ValueError("a negative radius")
    return value


def _basic_shape(name: str, args: str, box: tuple[float, float, float, float], tolerance: float) -> BaseGeometry:
    """A basic shape's area in the user units of its reference box (x, y, width, height); ValueError when the
    arguments are in error."""
    x, y, w, h = box
    if name == "polygon":
        parts = [p.strip() for p in args.split(",")]
        if parts and parts[0] in ("nonzero", "evenodd"):
            parts = parts[1:]
        points = []
        for part in parts:
            words = part.split()
            if len(words) != 2:
                raise ValueError("a polygon vertex needs two lengths")
            points.append((x + _box_length(words[0], w), y + _box_length(words[1], h)))
        if len(points) < 3:
            return shapely.Polygon()
        return shapely.make_valid(shapely.Polygon(points))
    if name == "inset":
        words = args.split()
        if "round" in words:
            words = words[:words.index("round")]
        if not 1 <= len(words) <= 4:
            raise ValueError("inset() takes one to four lengths")
        order = {1: (0, 0, 0, 0), 2: (0, 1, 0, 1), 3: (0, 1, 2, 1), 4: (0, 1, 2, 3)}[len(words)]
        top, right, bottom, left = (words[k] for k in order)
        t, b = _box_length(top, h), _box_length(bottom, h)
        r, left_ = _box_length(right, w), _box_length(left, w)
        if left_ + r >= w or t + b >= h:
            return shapely.Polygon()
        return shapely.box(x + left_, y + t, x + w - r, y + h - b)
    words = args.split()
    at = words.index("at") if "at" in words else len(words)
    cx, cy = _position(words[at + 1:], w, h)
    radii = words[:at]
    sides_x = (min(cx, w - cx), max(cx, w - cx))
    sides_y = (min(cy, h - cy), max(cy, h - cy))
    if name == "circle":
        if len(radii) > 1:
            raise ValueError("circle() takes one radius")
        word = radii[0] if radii else "closest-side"
        near, far = min(sides_x[0], sides_y[0]), max(sides_x[1], sides_y[1])
        rx = ry = _radius(word, near, far, math.hypot(w, h) / math.sqrt(2))
    else:
        if len(radii) not in (0, 2):
            raise ValueError("ellipse() takes two radii")
        rx = _radius(radii[0] if radii else "closest-side", *sides_x, w)
        ry = _radius(radii[1] if radii else "closest-side", *sides_y, h)
    if rx <= 0 or ry <= 0:
        return shapely.Polygon()
    steps = max(8, math.ceil(math.pi / math.acos(max(-1.0, 1 - tolerance / max(rx, ry)))))
    turn = np.linspace(0, 2 * math.pi, steps + 1)
    return shapely.Polygon(np.column_stack([x + cx + rx * np.cos(turn), y + cy + ry * np.sin(turn)]))


def _direction(step: FloatArray) -> float:
    return math.degrees(math.atan2(float(step[1]), float(step[0])))


def _marker_places(subs: list[Subpath], inverse: FloatArray) -> list[tuple[FloatArray, float]]:
    """Each vertex of the subpaths in user units (`inverse` undoes their placement), in order, with the direction
    a marker with orient auto takes there, degrees: the mean of the directions in and out (SVG 2 §13.7.3), the
    one there is at an open end; a closed subpath's first and last vertices take its closing direction in."""
    places: list[tuple[FloatArray, float]] = []
    for sub in subs:
        pts = affine([sub.points], inverse)[0]
        if not np.isfinite(pts).all():
            continue
        steps = np.diff(pts, axis=0)
        moving = np.flatnonzero(np.hypot(steps[:, 0], steps[:, 1]) > 0)
        indices = list(sub.vertices) if sub.vertices is not None else list(range(len(pts)))
        first = steps[moving[0]] if len(moving) else None
        last = steps[moving[-1]] if len(moving) else None
        for i in indices:
            before = moving[moving < i]
            after = moving[moving >= i]
            into = steps[before[-1]] if len(before) else (last if sub.closed else None)
            out = steps[after[0]] if len(after) else (first if sub.closed else None)
            if into is not None and out is not None:
                a, b = _direction(into), _direction(out)
                if abs(b - a) > 180:
                    b += 360 if b < a else -360
                turn = (a + b) / 2
            elif into is not None or out is not None:
                turn = _direction(into if into is not None else out)  # type: ignore[arg-type]
            else:
                turn = 0.0
            places.append((pts[i], turn))
    return places


def _placed(area: BaseGeometry, matrix: FloatArray) -> BaseGeometry:
    """`area` moved by the 2x3 `matrix`."""
    moved: BaseGeometry = shapely.transform(area, lambda xy: affine([xy], matrix)[0])
    return moved


def _outline(area: BaseGeometry) -> Polylines:
    """The rings bounding an area: each polygon's exterior and holes."""
    return [np.asarray(ring.coords, dtype=float)[:, :2] for polygon in shapely.get_parts(area)
            if polygon.geom_type == "Polygon" and not polygon.is_empty
            for ring in (polygon.exterior, *polygon.interiors)]


def _namespace(el: ET.Element) -> str:
    """An element's namespace (SVG for elements without one; '' for comments)."""
    if not isinstance(el.tag, str):
        return ""
    return el.tag[1:].split("}")[0] if el.tag.startswith("{") else SVG_NS


def _invert(matrix: FloatArray) -> FloatArray:
    return np.asarray(np.linalg.inv(np.vstack([matrix, [0.0, 0.0, 1.0]]))[:2], dtype=float)


def _language_matches(value: str) -> bool:
    """`systemLanguage`: true when one of its comma-separated tags has a user language as its primary subtag
    (SVG 1.1 §5.8.5; an empty value is false)."""
    tags = [t.strip().lower() for t in value.split(",") if t.strip()]
    return any(t.split("-")[0] in USER_LANGUAGES for t in tags)


def conditions_hold(el: ET.Element) -> bool:
    """Conditional processing (SVG 2 §5.8): `systemLanguage` matches a user language and `requiredExtensions`
    names none (no extension is supported; an empty list is false). `requiredFeatures` is always true, as in
    SVG 2 and browsers."""
    language = el.get("systemLanguage")
    if language is not None and not _language_matches(language):
        return False
    return el.get("requiredExtensions") is None


class _Reader:
    def __init__(self, root: ET.Element, name: str, tolerance: float, text: str) -> None:
        self.root = root
        self.name = name
        self.tolerance = tolerance
        self.text_mode = text
        self.ids = {el.get("id"): el for el in root.iter() if el.get("id")}
        self.parents = {child: el for el in root.iter() for child in el}
        self.sheet = StyleSheet.of(root)
        self.lines = Ink()
        self.hidden: Polylines = []
        self.skipped: Counter[str] = Counter()
        self.unsupported: Counter[str] = Counter()
        self.text_chars = 0
        """Characters of SVG text read so far, in the whole file (bounded by svgtext.MAX_TEXT_CHARS)."""
        self.curved = False
        self.points = 0
        self.dashes = 0
        self.band_points = 0
        """Points of the centre lines of wide strokes so far (bounded by MAX_BAND_POINTS)."""
        self.alpha = 1.0
        """The product of the opacity of the element being drawn and of its ancestors: paint this faint on the
        paper may leave no mark (svgstyle.paints)."""
        self.gradient_points = 0
        """Vertices of the gradients' shown regions so far (bounded by MAX_GRADIENT_POINTS)."""
        self._chains: dict[int, list[ET.Element]] = {}
        """Each paint server's `href` chain, by the element's id()."""
        self._stop_elements: dict[int, list[ET.Element]] = {}
        """Each gradient's stop elements, by the element's id()."""
        self._shown: dict[tuple[int, float], list[tuple[float, float]]] = {}
        """Each gradient's stretches that mark the paper at an opacity (gradient.shown_intervals)."""
        self._opaque_stops: dict[int, bool] = {}
        """Whether each gradient's stops are all opaque, by the element's id()."""
        self.wide_stroke = math.inf
        """Strokes wider than this on the page (px) are drawn as the outline of the band they paint."""
        """Dashes stroke-dasharray cut the lines into so far (bounded by MAX_DRAWING_DASHES)."""
        self._clips: dict[tuple[int, bytes], BaseGeometry] = {}
        self._read_ahead = self._read_straight_paths()
        self._patterns: tuple[str, ...] = ()
        self._below: list[Ink] = []
        """What is painted so far, innermost last: opaque fills hide the parts of these lines under them."""
        self._shaded = 0
        """Enclosing elements that make a fill's hiding unsure (masks, filters, what is drawn only to be measured)."""
        self._floor = 0
        """The first of `_below` a fill hides lines in: the innermost group composited on its own (group opacity,
        a clip path, a viewport's clip) takes its content as one picture, so a fill in it hides what the group
        painted before it, but not what lies under the group (SVG 1.1 §14.5, Compositing 1 §3.3 groups)."""
        self._blend_floor = 0
        """The first of `_below` whose fills a new fill's colour meets as the same colour: below a group that
        blends (opacity, filters, masks) colours differ; a clip alone changes no colour."""
        self._occlusion_checks = 0
        self._context: dict[str, str] | None = None
        """fill and stroke of the element context-fill and context-stroke take theirs from (the `<use>` or the
        marked shape being drawn; None outside both: those paints are then none, SVG 2 §13.3)."""
        self._markers: tuple[ET.Element, ...] = ()
        """Markers being drawn, innermost last: a marker is not drawn inside itself."""
        self.marker_count = 0
        self.user_viewport = (0.0, 0.0)
        """The root viewport in user units: the reference box of transform-origin where no nearer one is known."""
        self.root_font = Font()
        """The root element's font and the page's size: what rem, rlh and vw/vh/vi/vb/vmin/vmax are of."""

    def font(self, style: dict[str, str]) -> Font:
        """What font- and viewport-relative lengths of an element with the computed `style` are of."""
        return Font(number(style.get("font-size"), ROOT_FONT_SIZE), style.get("font-family", ""),
                    self.root_font.size, self.root_font.family, self.root_font.viewport)

    # -- limits -----------------------------------------------------------------------------------------------

    def check_expansion(self) -> None:
        """Count the shape copies `<use>` makes before drawing any, refusing fan-out bombs."""
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
                if target is not None and ref and ref not in stack:  # a looping reference draws nothing
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
                 and 0 < len(el.get("d") or "") <= READ_AHEAD_CHARS and is_straight(el.get("d") or "")
                 and (el.get("d") or "").lstrip()[:1] in ("M", "m")]
        if len(paths) < 2:
            return {}
        read = straight_paths([el.get("d") or "" for el in paths])
        return {id(el): subs for el, subs in zip(paths, read, strict=True)} if read is not None else {}

    def own_transform(self, el: ET.Element) -> FloatArray:
        """The element's `transform` attribute; one in error is ignored (with a note), as browsers ignore it."""
        value = el.get("transform")
        try:
            return transform(value)
        except ValueError as exc:
            self.unsupported[f"the transform {excerpt((value or ''), 60)} on <{local(el.tag)}> is in error ({exc}): "
                             "ignored, as browsers do"] += 1
            return IDENTITY

    def placement(self, el: ET.Element, own: dict[str, str], style: dict[str, str],
                  viewport: tuple[float, float]) -> FloatArray:
        """The element's transform: the CSS `transform` property when set and valid, else the attribute, about
        its `transform-origin` (CSS Transforms 1 §6; the reference box is the viewport unless `transform-box`
        names the element's own box)."""
        font = self.font(style)
        matrix = IDENTITY
        css = own.get("transform")
        if css is not None:
            try:
                matrix = css_transform(css, viewport, font)
            except ValueError as exc:
                self.unsupported[f"the CSS transform {excerpt(css, 60)} is in error ({exc}): the transform "
                                 "attribute applies, as browsers do"] += 1
                css = None
        if css is None:
            matrix = self.own_transform(el)
        origin = own.get("transform-origin")
        if origin is None or matrix is IDENTITY:
            return matrix
        box = (0.0, 0.0, *viewport)
        if own.get("transform-box", "").strip() in ("fill-box", "stroke-box", "content-box", "border-box"):
            box = self.bounding_box(el, local(el.tag), viewport, style) or box
        return about(matrix, transform_origin(origin, box, font))

    def bounding_box(self, el: ET.Element, tag: str, viewport: tuple[float, float],
                     style: dict[str, str]) -> tuple[float, float, float, float] | None:
        """The shape's box in its own user units (x, y, width, height), or None for other elements."""
        if tag not in SHAPES:
            return None
        subs = [s.points for s in self.subpaths(el, tag, IDENTITY, viewport, self.font(style), keep=True)]
        if not subs:
            return None
        pts = np.concatenate(subs)
        (x0, y0), (x1, y1) = pts.min(axis=0), pts.max(axis=0)
        return (float(x0), float(y0), float(x1 - x0), float(y1 - y0))

    def clip_to_page(self, width: float, height: float) -> None:
        """Cut the drawing to the page, (0, 0)-(width, height) px, as a browser shows no more of it."""
        page = shapely.box(0.0, 0.0, width, height)
        if self.lines:
            starts = np.cumsum([0] + [len(line) for line in self.lines[:-1]])
            points = np.concatenate(self.lines)
            low = np.minimum.reduceat(points, starts)
            high = np.maximum.reduceat(points, starts)
            inside = (low >= 0).all(axis=1) & (high[:, 0] <= width) & (high[:, 1] <= height)
        else:
            inside = np.zeros(0, dtype=bool)
        edges: Polylines = []
        for fill in self.lines.fills:
            x0, y0, x1, y1 = fill.box
            if x1 >= x0 and (x0 < 0 or y0 < 0 or x1 > width or y1 > height) and not fill.area.is_empty:
                edges.extend(cut_edge(fill.area, page)[0])
        if inside.all() and not edges:
            return
        crossing = np.flatnonzero(~inside).tolist()
        kept, hidden = cut([self.lines[k] for k in crossing], page)
        lines = Ink([line for line, keep in zip(self.lines, inside.tolist(), strict=True) if keep] + kept + edges)
        self.lines = lines
        self.hidden.extend(hidden)
        self.unsupported[f"lines outside the {width:g} x {height:g} px page are hidden, as a browser hides them"] += 1

    def report(self) -> list[str]:
        notes = [f"{what} ({count}x)" if count > 1 else what for what, count in sorted(self.unsupported.items())]
        if self.sheet.ignored:
            shown = ", ".join(sorted(set(self.sheet.ignored))[:5])
            notes.append(f"CSS rules a browser cannot read were ignored: {shown}")
        return notes

    def computed_style(self, el: ET.Element) -> dict[str, str]:
        """The computed style of an element drawn away from its place (a pattern, a clip path): inherited from
        its ancestors in the document."""
        chain = [el]
        while chain[-1] in self.parents:
            chain.append(self.parents[chain[-1]])
        style: dict[str, str] = {}
        for ancestor in reversed(chain):
            style = inherit(style, own_style(ancestor, self.sheet))
        return style

    # -- walking ----------------------------------------------------------------------------------------------

    @staticmethod
    def _href(el: ET.Element) -> str | None:
        href = (el.get("href") or el.get(XLINK_HREF) or "").strip()
        return href[1:] if href.startswith("#") else (href or None)

    def children(self, el: ET.Element, style: dict[str, str], matrix: FloatArray, viewport: tuple[float, float],
                 out: Ink, depth: int, uses: tuple[str, ...]) -> None:
        kids: Iterator[ET.Element] = iter(el)
        if local(el.tag) == "switch":  # the first child whose conditions hold (SVG 1.1 §5.8.2)
            kids = iter([k for k in el if _namespace(k) == SVG_NS and conditions_hold(k)][:1])
        for child in kids:
            self.element(child, style, matrix, viewport, out, depth + 1, uses)

    def element(self, el: ET.Element, parent: dict[str, str], matrix: FloatArray, viewport: tuple[float, float],
                out: Ink, depth: int, uses: tuple[str, ...]) -> None:
        check_cancelled()  # a drawing read for someone who has gone stops here, between two elements
        tag = local(el.tag)
        if _namespace(el) != SVG_NS or not (tag in SHAPES or tag in CONTAINERS or tag in UNDRAWABLE):
            return
        if not conditions_hold(el):
            return
        own = own_style(el, self.sheet)
        style = inherit(parent, own)
        if own.get("display", "").strip() == "none":
            return
        if _opacity(own) <= 0:
            self.extent_of(el, own, style, matrix, viewport, out, depth, uses)
            return
        own_matrix = self.placement(el, own, style, viewport)
        if own_matrix is not IDENTITY:
            matrix = then(matrix, own_matrix)
        if flattens(matrix):
            return  # scaled to a line or a point: nothing of it shows
        effects = [k for k in own.keys() & EFFECTS if own[k].strip() != "none"]
        outer_alpha = self.alpha
        self.alpha *= min(1.0, _opacity(own))
        try:
            if tag in SHAPES and not effects:
                self.shape(el, tag, style, matrix, viewport, out)  # nothing of its own to apply afterwards
                return
            target = Ink()
            blended = bool(set(effects) - {"clip-path"}) or _opacity(own) < 1
            with self.painting(target, shaded=bool(set(effects) - {"clip-path"}),
                               isolated=bool(effects) or _opacity(own) < 1, blended=blended):
                self.draw(el, tag, style, matrix, viewport, target, depth, uses)
        finally:
            self.alpha = outer_alpha
        self.clip(el, own, matrix, target, ())
        if effects == ["clip-path"] and _opacity(own) >= 1:
            self.hide_under_clipped(target)
        out.take(target)

    def hide_under_clipped(self, drawn: Ink) -> None:
        """What shows of the opaque fills of a clipped group, once clipped, hides what lies under the group (they
        could hide only the group's own lines while it was drawn, before the clip was known)."""
        if self._shaded or not self._below:
            return
        for fill in drawn.fills:
            if fill.opaque:
                self.hide_under(fill)

    def extent_of(self, el: ET.Element, own: dict[str, str], style: dict[str, str], matrix: FloatArray,
                  viewport: tuple[float, float], out: Ink, depth: int, uses: tuple[str, ...]) -> None:
        """Add the box of a fully transparent element to `out`'s extent: it shows nothing, and hides nothing,
        but its geometry counts for its group's bounding box (SVG 2 §8.10)."""
        matrix = then(matrix, self.placement(el, own, style, viewport))
        if flattens(matrix):
            return
        scratch = Ink()
        with self.painting(scratch, shaded=True):
            self.draw(el, local(el.tag), {**style, "visibility": "visible", "opacity": "1"}, matrix, viewport,
                      scratch, depth, uses)
        boxes = np.vstack([scratch.boxes(), np.asarray(scratch.extent, dtype=float).reshape(-1, 4)])
        if len(boxes):
            out.extent.append([*boxes[:, :2].min(axis=0).tolist(), *boxes[:, 2:].max(axis=0).tolist()])

    def below(self, ink: Ink) -> None:
        """Start a drawing whose earlier paint is `ink`."""
        self._below = [ink]
        self._floor = self._blend_floor = 0

    @contextmanager
    def painting(self, target: Ink, *, shaded: bool = False, isolated: bool = False,
                 blended: bool = False) -> Iterator[None]:
        """Draw into `target`, painted over what is below: `isolated` for a group composited on its own (its
        fills hide only its own earlier lines), `shaded` where fills hide nothing at all, `blended` for a group
        whose colours change as it is composited (opacity, effects)."""
        floor, blend_floor = self._floor, self._blend_floor
        self._below.append(target)
        self._shaded += shaded
        if isolated:
            self._floor = len(self._below) - 1
        if blended:
            self._blend_floor = len(self._below) - 1
        try:
            yield
        finally:
            self._below.pop()
            self._shaded -= shaded
            self._floor, self._blend_floor = floor, blend_floor

    def draw(self, el: ET.Element, tag: str, style: dict[str, str], matrix: FloatArray,
             viewport: tuple[float, float], target: Ink, depth: int, uses: tuple[str, ...]) -> None:
        if tag in SHAPES:
            self.shape(el, tag, style, matrix, viewport, target)
        elif tag == "text":
            if self.text_mode == "outline":
                if style.get("visibility", "visible") == "visible":
                    self.skipped["text"] += 1
            else:
                self.text(el, style, matrix, viewport, target)
        elif tag in UNDRAWABLE:
            if style.get("visibility", "visible") == "visible":
                self.skipped["image" if tag == "image" else tag] += 1
        elif tag == "use":
            self.use(el, style, matrix, viewport, target, depth, uses)
        elif tag == "svg":
            self.viewport(el, el, style, matrix, viewport, target, depth, uses, None, None)
        else:
            self.children(el, style, matrix, viewport, target, depth, uses)

    def same_colour_areas(self, fill: _Fill) -> list[BaseGeometry]:
        """What shows of the earlier opaque fills of `fill`'s own colour that it meets, across clips but not
        across a group that blends: no edge shows between them."""
        if fill.paint is None:
            return []
        x0, y0, x1, y1 = fill.box
        found: list[BaseGeometry] = []
        for ink in self._below[self._blend_floor:]:
            if not ink.fills:
                continue
            self._occlusion_checks += len(ink.fills)
            if self._occlusion_checks > MAX_OCCLUSION_CHECKS:
                return found
            boxes = ink.fill_boxes()
            near = (boxes[:, 0] <= x1) & (boxes[:, 2] >= x0) & (boxes[:, 1] <= y1) & (boxes[:, 3] >= y0)
            for k in np.flatnonzero(near).tolist():
                earlier = ink.fills[k]
                if earlier.opaque and same_colour(earlier.paint, fill.paint) and shapely.intersects(earlier.area,
                                                                                                     fill.area):
                    found.append(earlier.area)
        return found

    def hide_under(self, fill: _Fill) -> None:
        """An opaque fill covers its area: the parts of earlier lines under it are hidden (SVG 1.1 §3.3 painter's
        model), and earlier fills shrink to what still shows."""
        x0, y0, x1, y1 = fill.box
        for ink in self._below[self._floor:]:
            if not ink and not ink.fills:
                continue
            self._occlusion_checks += len(ink) + len(ink.fills)
            if self._occlusion_checks > MAX_OCCLUSION_CHECKS:
                self.unsupported["too many overlapping fills to work out which lines they hide: some lines "
                                 "under fills are drawn"] += 1
                return
            boxes = ink.boxes()
            under = (boxes[:, 0] <= x1) & (boxes[:, 2] >= x0) & (boxes[:, 1] <= y1) & (boxes[:, 3] >= y0)
            if under.any():
                hit = np.flatnonzero(under).tolist()
                hidden, shown = cut([ink[k] for k in hit], fill.area)
                ink.drop(hit)
                ink.extend(shown)
                self.hidden.extend(hidden)
            if ink.fills:
                fills = ink.fill_boxes()
                near = (fills[:, 0] <= x1) & (fills[:, 2] >= x0) & (fills[:, 1] <= y1) & (fills[:, 3] >= y0)
                for k in np.flatnonzero(near).tolist():
                    earlier = ink.fills[k]
                    if shapely.intersects(earlier.area, fill.area):
                        ink.set_fill(k, _Fill([], earlier.rule, shapely.difference(earlier.area, fill.area),
                                              opaque=earlier.opaque, paint=earlier.paint))

    def clip(self, el: ET.Element, own: dict[str, str], matrix: FloatArray, target: Ink,
             stack: tuple[str, ...]) -> None:
        """Apply the element's clip path to what it drew, in place; name masks and filters it leaves out."""
        if own.get("mask", "none").strip() != "none":
            self.unsupported["masks are not applied: masked elements are drawn whole"] += 1
        if own.get("filter", "none").strip() != "none":
            self.unsupported["filters (blur, shadows and the like) are not applied"] += 1
        value = own.get("clip-path", "none").strip()
        if value == "none" or not (target or target.fills):
            return
        if BASIC_SHAPE.match(value):
            region = self.basic_shape(el, value, matrix, target)
        else:
            region = self.clip_region(value, matrix, target, stack)
        if region is not None:
            self.cut_ink(target, region)

    def cut_ink(self, target: Ink, region: BaseGeometry) -> None:
        """Cut lines and fills to `region`, in place: a fill is outlined along the cut as well."""
        kept, hidden = cut(list(target), region)
        fills: list[_Fill] = []
        for fill in target.fills:
            edges, area = cut_edge(fill.area, region)
            kept.extend(edges)
            if not area.is_empty:
                fills.append(_Fill([], fill.rule, area, opaque=fill.opaque, paint=fill.paint))
        target.replace(kept)
        target.fills = fills
        self.hidden.extend(hidden)

    def _encloses(self, outer: ET.Element, el: ET.Element) -> bool:
        """Whether `outer` is `el` or one of its ancestors (a `<use>` of it is a circular reference)."""
        at: ET.Element | None = el
        while at is not None:
            if at is outer:
                return True
            at = self.parents.get(at)
        return False

    def in_context(self, style: dict[str, str]) -> dict[str, str]:
        """`style` with context-fill and context-stroke replaced by the context element's paint."""
        found = {k: v for k in ("fill", "stroke") if (v := style.get(k, "").strip()) in CONTEXT_PAINTS}
        if not found:
            return style
        context = self._context or {}
        return {**style, **{k: context.get(CONTEXT_PAINTS[v], "none") for k, v in found.items()}}

    @contextmanager
    def context(self, style: dict[str, str]) -> Iterator[None]:
        """Draw with the element of (resolved) `style` as the context element."""
        outer = self._context
        self._context = {"fill": style.get("fill", "black"), "stroke": style.get("stroke", "none")}
        try:
            yield
        finally:
            self._context = outer

    def use(self, el: ET.Element, style: dict[str, str], matrix: FloatArray, viewport: tuple[float, float],
            out: Ink, depth: int, uses: tuple[str, ...]) -> None:
        style = self.in_context(style)
        with self.context(style):
            self._use(el, style, matrix, viewport, out, depth, uses)

    def _use(self, el: ET.Element, style: dict[str, str], matrix: FloatArray, viewport: tuple[float, float],
             out: Ink, depth: int, uses: tuple[str, ...]) -> None:
        ref = self._href(el)
        target = self.ids.get(ref) if ref else None
        if target is None:
            self.unsupported[f"<use> of {ref or 'nothing'!r}, which is not in this file, draws nothing"] += 1
            return
        if ref in uses or depth > MAX_DEPTH or self._encloses(target, el):
            self.unsupported[f"<use> of #{ref} refers back to itself: that reference draws nothing, as in "
                             "browsers"] += 1
            return
        if beyond_single(el.get("x")) or beyond_single(el.get("y")):
            return  # placed at infinity: nothing of the copy is on the page
        vw, vh = viewport
        font = self.font(style)
        matrix = then(matrix, translate(length(el.get("x"), vw, font_size=font),
                                        length(el.get("y"), vh, font_size=font)))
        kind = local(target.tag)
        if kind in ("symbol", "svg"):
            own = own_style(target, self.sheet)
            inner = inherit(style, own)
            if own.get("display", "").strip() == "none" and kind == "svg":
                return
            drawn = Ink()
            with self.painting(drawn, isolated=own.get("clip-path", "none").strip() != "none"):
                self.viewport(target, el, inner, matrix, viewport, drawn, depth, (*uses, str(ref)),
                              el.get("width"), el.get("height"))
            self.clip(target, own, matrix, drawn, ())
            out.take(drawn)
        else:
            self.element(target, style, matrix, viewport, out, depth + 1, (*uses, str(ref)))

    def viewport(self, el: ET.Element, placed_by: ET.Element, style: dict[str, str], matrix: FloatArray,
                 viewport: tuple[float, float], out: Ink, depth: int, uses: tuple[str, ...],
                 width: str | None, height: str | None) -> None:
        """A nested `<svg>` (drawn or used: its x and y place it) or a used `<symbol>`: a viewport its viewBox
        maps onto, clipping unless overflow is visible (SVG 1.1 §7.9, §14.3.3)."""
        vw, vh = viewport
        font = self.font(style)
        own_place = local(el.tag) == "svg"
        x = length(el.get("x"), vw, font_size=font) if own_place else 0.0
        y = length(el.get("y"), vh, font_size=font) if own_place else 0.0
        w = length(width if width is not None else el.get("width"), vw, default=vw, font_size=font)
        h = length(height if height is not None else el.get("height"), vh, default=vh, font_size=font)
        vb = read_view_box(el.get("viewBox"))
        if w <= 0 or h <= 0 or vb.empty:
            return
        if vb.error:
            self.unsupported[f"the viewBox {excerpt(el.get('viewBox', ''), 60)} on <{local(el.tag)}> is in error "
                             f"({vb.error}): ignored, as browsers do"] += 1
        box = vb.box
        inner = then(matrix, viewport_matrix(box, x, y, w, h, el.get("preserveAspectRatio")))
        if local(el.tag) == "symbol":  # SVG 2 §5.5: a symbol's transform applies inside its viewport
            inner = then(inner, self.own_transform(el))
        drawn = Ink()
        clips = style.get("overflow", "hidden").strip() in ("hidden", "scroll")
        with self.painting(drawn, isolated=clips):
            self.children(el, style, inner, (box[2], box[3]) if box else (w, h), drawn, depth, uses)
        if clips and (drawn or drawn.fills):
            corners = np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h], [x, y]])
            ring = corners @ matrix[:, :2].T + matrix[:, 2]
            self.cut_ink(drawn, shapely.Polygon(ring))
        out.take(drawn)

    def subpaths(self, el: ET.Element, tag: str, matrix: FloatArray, viewport: tuple[float, float],
                 font: float | Font = 16.0, *, keep: bool = False) -> list[Subpath]:
        """The element's subpaths placed by `matrix`; `keep` leaves a read-ahead path for a later call."""
        ahead = self._read_ahead.get(id(el)) if tag == "path" else None
        if ahead is not None:
            if not keep:
                self._read_ahead.pop(id(el), None)
            placed = affine([sub.points for sub in ahead], matrix)
            return [Subpath(points, sub.closed, sub.segments, sub.vertices)
                    for points, sub in zip(placed, ahead, strict=True)]
        builder = PathBuilder(matrix, self.tolerance, room=MAX_POINTS - self.points)
        vw, vh = viewport
        diag = math.hypot(vw, vh) / math.sqrt(2)

        styled = self._geometry(el)

        def get(name: str, relative: float, default: float = 0.0) -> float:
            return length(styled.get(name, el.get(name)), relative, default=default, font_size=font)

        def radius(name: str, relative: float) -> float | None:
            """rx or ry: None for auto (absent, negative, or in error in CSS); an attribute in error (`auto`
            included) is 0, as Chromium reads it."""
            value = get(name, relative, math.nan)
            if math.isnan(value):
                return 0.0 if name not in styled and el.get(name) is not None else None
            return value if value >= 0 else None

        try:
            if tag == "path":
                d = styled.get("d", el.get("d") or "")
                if d.startswith("path("):
                    d = d[5:].rstrip(")").strip().strip("'\"")
                if d.strip() and d.lstrip()[0] not in "Mm":
                    raise PathDataError("it does not start with a moveto")
                path_data(builder, d)
            elif tag == "rect":
                rect(builder, get("x", vw), get("y", vh), get("width", vw), get("height", vh),
                     radius("rx", vw), radius("ry", vh))
            elif tag == "circle":
                r = get("r", diag)
                ellipse(builder, get("cx", vw), get("cy", vh), r, r)
            elif tag == "ellipse":
                rx, ry = radius("rx", vw), radius("ry", vh)
                rx = ry if rx is None else rx
                ry = rx if ry is None else ry
                ellipse(builder, get("cx", vw), get("cy", vh), rx or 0.0, ry or 0.0)
            elif tag == "line":
                line(builder, get("x1", vw), get("y1", vh), get("x2", vw), get("y2", vh))
            else:
                polyline(builder, numbers(el.get("points") or ""), close=(tag == "polygon"))
        except ValueError as exc:
            why = f" ({exc})" if isinstance(exc, PathDataError) else ""
            self.unsupported[f"<{tag}> data with an error{why} is drawn up to the error, as browsers do"] += 1
        self.curved = self.curved or builder.curved
        return builder.subpaths

    def _geometry(self, el: ET.Element) -> dict[str, str]:
        """Geometry properties a style sheet or the `style` attribute sets on the element (they win over the
        attributes of the same names)."""
        if id(el) not in self.sheet.matched and not el.get("style"):
            return {}
        return {k: v for k, v in own_style(el, self.sheet).items() if k in GEOMETRY}

    def _count_dashes(self, el: ET.Element, tag: str, count: int) -> None:
        self.dashes += count
        if self.dashes > MAX_DRAWING_DASHES:
            name = f"<{tag} id={excerpt(el.get('id', ''), 40)}>" if el.get("id") else f"a <{tag}>"
            raise InputError(f"{self.name}: stroke-dasharray of {name} cuts it into {count:,} dashes, "
                             f"{self.dashes:,} in the drawing, more than the {MAX_DRAWING_DASHES:,} allowed; "
                             "refusing it")

    def _count(self, points: int) -> None:
        self.points += points
        if self.points > MAX_POINTS:
            raise InputError(f"{self.name}: the drawing has more than {MAX_POINTS:,} points; refusing it")

    def _paint_kind(self, style: dict[str, str], which: str = "fill") -> tuple[str, ET.Element | None]:
        """('none' | 'solid' | 'pattern', the pattern element): how the fill or stroke paints. A `url()` to
        nothing, or to an element that is no paint server, takes its fallback colour, else none (SVG 1.1 §11.2);
        a gradient paints like a solid colour."""
        if not paints(style, which, self.alpha):
            return "none", None
        value = style.get(which, "").strip()
        ref = iri(value)
        if ref is None:
            return "solid", None
        target = self.ids.get(ref)
        if (target is None or local(target.tag) not in ("pattern", *GRADIENTS)
                or not self._server_exists(target)):
            fallback = value[value.find(")") + 1:].strip()
            if fallback and paints({**style, which: fallback}, which, self.alpha):
                return "solid", None
            return "none", None
        if local(target.tag) == "pattern":
            return "pattern", target
        return ("solid", None) if self._has_stops(target) else ("none", None)

    def _server_exists(self, server: ET.Element) -> bool:
        """Whether a paint server can paint: not when it or an ancestor has `display: none`, nor when an ancestor
        fails its conditions (`systemLanguage`, `requiredExtensions`), as Chromium makes no paint server out of
        such an element and the reference falls back as if it named nothing (SVG 2 §13.2, §5.8.1; CSS Display 3
        §2.7). Conditions on the server itself are not processed (it is not a rendered element)."""
        at: ET.Element | None = server
        while at is not None:
            if own_style(at, self.sheet).get("display", "").strip() == "none":
                return False
            if at is not server and not conditions_hold(at):
                return False
            at = self.parents.get(at)
        return True

    def _stops(self, gradient: ET.Element) -> list[ET.Element]:
        """A gradient's stops, or those of the one it takes them from through `href` (SVG 1.1 §13.2.4); read
        once per gradient."""
        key = id(gradient)
        if key not in self._stop_elements:
            self._stop_elements[key] = next(
                (found for at in self._server_chain(gradient)
                 if (found := [child for child in at if local(child.tag) == "stop"])), [])
        return self._stop_elements[key]

    def opaque(self, style: dict[str, str], which: str) -> bool:
        """Whether the fill or stroke paints without any transparency, so it hides what lies under it: a solid
        colour (white too), or a gradient all of whose stops are opaque."""
        if opaque_fill(style, which):
            return True
        ref = iri(style.get(which, ""))
        server = self.ids.get(ref) if ref else None
        if (server is None or local(server.tag) not in GRADIENTS
                or self._paint_kind(style, which)[0] != "solid" or number(style.get(f"{which}-opacity"), 1.0) < 1):
            return False
        key = id(server)
        if key not in self._opaque_stops:
            stops = self._stops(server)
            self._opaque_stops[key] = bool(stops) and all(opaque_stop(self.computed_style(s)) for s in stops)
        return self._opaque_stops[key]

    def _server_chain(self, el: ET.Element) -> list[ET.Element]:
        """The paint server and those of its kind (pattern, or either gradient) it takes attributes and content
        from through `href` (SVG 1.1 §13.2, §13.3), at most MAX_HREF_CHAIN long; read once per server."""
        key = id(el)
        if key not in self._chains:
            kinds = GRADIENTS if local(el.tag) in GRADIENTS else (local(el.tag),)
            chain, seen = [el], {key}
            while len(chain) < MAX_HREF_CHAIN:
                ref = self._href(chain[-1])
                nxt = self.ids.get(ref) if ref else None
                if nxt is None or local(nxt.tag) not in kinds or id(nxt) in seen:
                    break
                chain.append(nxt)
                seen.add(id(nxt))
            else:
                self.unsupported[f"paint servers that refer on through more than {MAX_HREF_CHAIN} others take "
                                 "nothing from those further on"] += 1
            self._chains[key] = chain
        return self._chains[key]

    def shown_area(self, style: dict[str, str], which: str, subs: list[Subpath], matrix: FloatArray,
                   viewport: tuple[float, float], reach: float = 0.0) -> BaseGeometry | None:
        """Where the fill's or stroke's gradient leaves a mark on the paper (output units), for an element whose
        output subpaths are `subs` and whose paint reaches `reach` user units beyond them (a stroke's); None when
        it leaves one wherever it paints, or the paint is no gradient."""
        ref = iri(style.get(which, ""))
        server = self.ids.get(ref) if ref else None
        if (server is None or local(server.tag) not in GRADIENTS or self._paint_kind(style, which)[0] != "solid"
                or fallback_in_error(style.get(which, ""))):
            return None
        chain = self._server_chain(server)
        opacity = min(1.0, max(0.0, number(style.get(f"{which}-opacity"), 1.0))) * self.alpha
        if (id(server), opacity) not in self._shown:
            stops: list[Stop] = []
            for stop in self._stops(server):
                at = min(1.0, max(0.0, number(stop.get("offset"), 0.0), stops[-1].offset if stops else 0.0))
                rgb, alpha = stop_paint(self.computed_style(stop))
                stops.append(Stop(at, rgb, alpha))
            self._shown[id(server), opacity] = shown_intervals(stops, opacity)
        shown = self._shown[id(server), opacity]
        points = [sub.points for sub in subs if len(sub.points) and np.isfinite(sub.points).all()]
        if not points or flattens(matrix):
            return None
        user = affine([np.concatenate(points)], _invert(matrix))[0]
        (x0, y0), (x1, y1) = user.min(axis=0), user.max(axis=0)
        scale = math.sqrt(abs(float(np.linalg.det(matrix[:, :2]))))
        if self.gradient_points >= MAX_GRADIENT_POINTS:
            self.unsupported[f"gradients past {MAX_GRADIENT_POINTS:,} points are outlined whole, their "
                             "paper-coloured stretches too"] += 1
            return None
        try:
            region = shown_region(local(server.tag),
                                  lambda name: next((g.get(name) for g in chain if g.get(name) is not None), None),
                                  shown, (float(x0), float(y0), float(x1), float(y1)), viewport,
                                  self.tolerance / scale, reach)
        except shapely.errors.GEOSException:
            return None  # geometry the library cannot combine: the whole paint is taken as shown
        if region is None:
            return None
        if not shapely.is_valid(region):
            region = shapely.make_valid(region)  # bands so close they touch
        self.gradient_points += int(shapely.get_num_coordinates(region))
        return _placed(region, matrix)

    def same_paint(self, style: dict[str, str]) -> bool:
        """Whether the stroke paints exactly what the fill under it paints, both without transparency (the same
        colour, or the same gradient over the same bounding box): a pen then shows only the fill's border."""
        return same_paint_value(style) and self.opaque(style, "fill") and self.opaque(style, "stroke")

    def _has_stops(self, gradient: ET.Element) -> bool:
        """Whether a gradient, or one it takes its stops from through `href`, has stops: one without paints
        nothing (SVG 1.1 §13.2.4)."""
        return bool(self._stops(gradient))

    def _dash_pattern(self, style: dict[str, str], viewport: tuple[float, float]) -> tuple[list[float], float]:
        """(dash and gap lengths, offset) in user units; no lengths for a solid stroke (none, or in error:
        a negative length, or all zero)."""
        value = style.get("stroke-dasharray", "none").strip()
        if value in ("none", ""):
            return [], 0.0
        diag = math.hypot(*viewport) / math.sqrt(2)
        font = self.font(style)
        parts = [p for p in value.replace(",", " ").split() if p]
        lengths = [length(p, diag, default=-1.0, font_size=font) for p in parts]
        if not lengths or any(v < 0 for v in lengths) or sum(lengths) <= 0:
            return [], 0.0
        offset = length(style.get("stroke-dashoffset"), diag, default=0.0, font_size=font)
        return lengths, offset

    def shape(self, el: ET.Element, tag: str, style: dict[str, str], matrix: FloatArray,
              viewport: tuple[float, float], out: Ink) -> None:
        """Draw a shape's fill and stroke, then its markers."""
        style = self.in_context(style)
        markers = self._marker_refs(style) if tag in MARKABLE else {}
        if not markers:
            self._paint(el, tag, style, matrix, viewport, out)
            return
        subs = self.subpaths(el, tag, matrix, viewport, self.font(style), keep=True)
        self._paint(el, tag, style, matrix, viewport, out)
        places = _marker_places(subs, _invert(matrix))
        width = self._stroke_width(style, viewport)
        with self.context(style):
            for k, (point, direction) in enumerate(places):
                where = "start" if k == 0 else "end" if k == len(places) - 1 else "mid"
                for which in (where, "end") if len(places) == 1 else (where,):
                    marker = markers.get(which)
                    if marker is not None:
                        self.marker(marker, which, point, direction, width, matrix, viewport, out)

    def _marker_refs(self, style: dict[str, str]) -> dict[str, ET.Element]:
        """The `<marker>` elements marker-start, -mid and -end (or the `marker` shorthand) name."""
        found: dict[str, ET.Element] = {}
        for where in ("start", "mid", "end"):
            value = style.get(f"marker-{where}", "").strip() or style.get("marker", "").strip()
            ref = iri(value) if value.startswith("url(") else None
            target = self.ids.get(ref) if ref else None
            if target is not None and local(target.tag) == "marker" and _namespace(target) == SVG_NS:
                found[where] = target
        return found

    def marker(self, marker: ET.Element, where: str, point: FloatArray, direction: float, stroke_width: float,
               matrix: FloatArray, viewport: tuple[float, float], out: Ink) -> None:
        """Draw one marker at `point` (user units of the shape placed by `matrix`), turned by its orient
        (`direction`, degrees, for auto), scaled by the stroke width unless markerUnits is userSpaceOnUse, its
        viewBox mapped onto markerWidth x markerHeight with (refX, refY) on the point, clipped to that box unless
        its overflow is visible (SVG 2 §13.7.2)."""
        if marker in self._markers:
            return
        self.marker_count += sum(1 for _ in marker.iter())  # each copy draws every element in it again
        if self.marker_count > MAX_MARKERS:
            self.unsupported[f"markers past {MAX_MARKERS:,} copied elements in one drawing are left out"] += 1
            return
        vw, vh = viewport
        style = self.computed_style(marker)
        font = self.font(style)
        mw = length(marker.get("markerWidth"), vw, default=3.0, font_size=font)
        mh = length(marker.get("markerHeight"), vh, default=3.0, font_size=font)
        vb = read_view_box(marker.get("viewBox"))
        if mw <= 0 or mh <= 0 or vb.empty:
            return
        box = vb.box
        orient = (marker.get("orient") or "0").strip()
        if orient == "auto":
            turn = direction
        elif orient == "auto-start-reverse":
            turn = direction + (180.0 if where == "start" else 0.0)
        else:
            try:
                turn = angle(orient)
            except ValueError:
                turn = 0.0
        scale = 1.0 if (marker.get("markerUnits") or "").strip() == "userSpaceOnUse" else stroke_width
        inner = viewport_matrix(box, 0.0, 0.0, mw, mh, marker.get("preserveAspectRatio"))
        size = (box[2], box[3]) if box else (mw, mh)
        ref = affine([np.array([[length(marker.get("refX"), vw, font_size=font),
                                 length(marker.get("refY"), vh, font_size=font)]])], inner)[0][0]
        c, s = math.cos(math.radians(turn)), math.sin(math.radians(turn))
        place = np.array([[c * scale, -s * scale, 0.0], [s * scale, c * scale, 0.0]])
        place[:, 2] = point - place[:, :2] @ ref
        placed = then(matrix, place)
        if flattens(placed):
            return
        drawn = Ink()
        # hidden by the browsers' default style sheet; `inherit` with no value above it is the initial visible
        given = "overflow" in own_style(marker, self.sheet)
        clips = style.get("overflow", "visible" if given else "hidden").strip() in ("hidden", "scroll")
        self._markers += (marker,)
        try:
            with self.painting(drawn, isolated=clips):  # a clipped marker hides what is under it once clipped
                self.children(marker, style, then(placed, inner), size, drawn, 0, ())
        finally:
            self._markers = self._markers[:-1]
        if clips and (drawn or drawn.fills):
            corners = np.array([[0.0, 0.0], [mw, 0.0], [mw, mh], [0.0, mh], [0.0, 0.0]])
            self.cut_ink(drawn, shapely.Polygon(affine([corners], placed)[0]))
            self.hide_under_clipped(drawn)
        out.take(drawn)

    def _paint(self, el: ET.Element, tag: str, style: dict[str, str], matrix: FloatArray,
               viewport: tuple[float, float], out: Ink) -> None:
        stroke_kind, stroke_pattern = self._paint_kind(style, "stroke")
        stroke = stroke_kind != "none"
        fill, pattern = self._paint_kind(style)
        covers = not self._shaded and bool(self._below) and self.opaque(style, "fill")
        if style.get("visibility", "visible").strip() != "visible" or (not (stroke or covers) and fill == "none"):
            points = [sub.points for sub in self.subpaths(el, tag, matrix, viewport, self.font(style))]
            if points:
                out.extent.append(_box(np.concatenate(points)))  # shows nothing, but has a bounding box
            return
        caps = style.get("stroke-linecap", "butt").strip() in ("round", "square")
        dashes, offset = self._dash_pattern(style, viewport) if stroke else ([], 0.0)
        subs = self.subpaths(el, tag, matrix, viewport, self.font(style))
        half = self._stroke_width(style, viewport) / 2 if stroke else 0.0
        scale = math.sqrt(abs(float(np.linalg.det(matrix[:, :2]))))
        wide = stroke and 2 * half * scale > self.wide_stroke and self._band_room(subs)
        stroke, dots = stroke and not wide, stroke and not wide and caps
        band: list[tuple[FloatArray, bool]] = []
        """The centre lines of a wide stroke, in user units, with whether each is closed."""
        inverse = _invert(matrix) if dashes or wide else matrix
        if dashes and (author := number(el.get("pathLength"), 0.0)) > 0:  # dashes measured along pathLength
            real = _length(affine([sub.points for sub in subs if sub.segments], inverse))
            if real > 0:
                dashes, offset = [dash * real / author for dash in dashes], offset * real / author
        rings: Polylines = []
        final, out = out, Ink()  # its own lines, added once its fill has hidden what lies under it
        for sub in subs:
            if sub.segments == 0:
                continue  # a lone moveto is never stroked
            pts = sub.points
            if not np.isfinite(pts).all():
                self.unsupported["subpaths with coordinates that are not finite numbers are left out"] += 1
                continue
            if wide:
                local_pts = affine([pts], inverse)[0]
                if dashes:
                    self._count_dashes(el, tag, dash_count(local_pts, dashes))
                    band.extend((piece, False) for piece in dashed(local_pts, dashes, offset))
                else:
                    band.append((local_pts, sub.closed))
            flat = (fill != "none" or covers or not stroke) and _without_area(pts)
            if (fill != "none" or covers) and not flat:
                rings.append(pts)
            if not stroke and (flat or fill != "solid"):
                continue  # a fill with no area shows nothing; a pattern shows only its own lines
            if bool((pts == pts[0]).all()):
                if dots:
                    out.append(pts[:1].copy())
                    self._count(1)
                continue
            if fill == "solid" and not sub.closed and not flat:
                pts = np.vstack([pts, pts[:1]])  # the fill's border closes the subpath
            if stroke and dashes and (fill != "solid" or flat):  # a solid fill's border shows whole between dashes
                local_pts = affine([pts], inverse)[0]
                self._count_dashes(el, tag, dash_count(local_pts, dashes))
                pieces = affine(dashed(local_pts, dashes, offset), matrix)
                for piece in pieces:
                    if len(piece) > 1 or caps:
                        out.append(piece)
                        self._count(len(piece))
                continue
            self._count(len(pts))
            out.append(pts)
        fill_shown = self.shown_area(style, "fill", subs, matrix, viewport) if fill == "solid" and rings else None
        miter = max(1.0, number(style.get("stroke-miterlimit"), 4.0))
        stroke_shown = self.shown_area(style, "stroke", subs, matrix, viewport, half * miter + 1) \
            if stroke or band else None
        if stroke and stroke_shown is not None and not (fill == "solid" and rings):
            out.replace(cut(list(out), stroke_shown)[0])  # the stroke's paper-coloured stretches draw nothing
        if rings:
            closed = [np.vstack([r, r[:1]]) for r in rings]
            rule = style.get("fill-rule", "nonzero").strip()
            own = _Fill(closed, rule, opaque=covers or self.opaque(style, "fill"),
                        paint=solid_colour(style, "fill") if fill == "solid" else None)
            hidden_stroke = stroke and fill == "solid" and len(out) == len(rings) and self.same_paint(style)
            stroke = stroke and not hidden_stroke  # inside the fill, a stroke of the fill's own paint shows nothing
            if fill == "solid" and not stroke and out:
                border = _border(own, closed)
                if border is not None:  # subpaths that cross or overlap: the pen draws only the fill's border
                    out.replace(border)
            if fill == "solid" and not stroke and own.opaque and not self._shaded:
                same = self.same_colour_areas(own)  # before hiding: what shows of them now
                if same:  # no edge shows where it meets its own colour
                    out.replace(cut(list(out), shapely.union_all(same).buffer(self.tolerance))[1])
            if covers:
                self.hide_under(own)
            if fill_shown is not None:  # a gradient's paper-coloured stretch draws nothing: outline what shows
                own = _Fill([], rule, shapely.intersection(own.area, fill_shown), opaque=own.opaque)
                border = _outline(own.area)
                if stroke:
                    kept = cut(list(out), stroke_shown)[0] if stroke_shown is not None else list(out)
                    drawn = [line for line in kept if len(line) > 1]  # dots (round caps) cover no border
                    border = cut(border, shapely.MultiLineString(drawn).buffer(self.tolerance))[1] + kept \
                        if drawn else border + kept
                self._count(sum(len(line) for line in border))
                out.replace(border)
            if fill == "solid":
                out.fills.append(own)
            elif pattern is not None:
                self.pattern(pattern, matrix, closed, rule, viewport, out, bordered=stroke)
        if band and stroke_pattern is not None:
            self.pattern_band(band, pen_of(style, half, self.tolerance / scale), stroke_pattern, matrix, viewport,
                              out)
        elif band:
            self.stroke_band(band, pen_of(style, half, self.tolerance / scale), style, matrix, out,
                             own if rings and fill == "solid" else None, stroke_shown)
        final.take(out)

    def _stroke_width(self, style: dict[str, str], viewport: tuple[float, float]) -> float:
        """stroke-width in user units (a percentage of the viewport's normalised diagonal); negative or in error
        is the initial 1."""
        width = length(style.get("stroke-width"), math.hypot(*viewport) / math.sqrt(2), default=1.0,
                       font_size=self.font(style))
        return width if width >= 0 else 1.0

    def _band_room(self, subs: list[Subpath]) -> bool:
        """Whether the wide strokes of the drawing so far and `subs` stay within MAX_BAND_POINTS (beyond, wide
        strokes are drawn along their centre lines, with a note)."""
        self.band_points += sum(len(sub.points) for sub in subs)
        if self.band_points <= MAX_BAND_POINTS:
            return True
        self.unsupported[f"wide strokes past {MAX_BAND_POINTS:,} points are drawn along their centre lines, not "
                         "as the outline of the band they paint"] += 1
        return False

    def pattern_band(self, lines: list[tuple[FloatArray, bool]], pen: Pen, server: ET.Element, matrix: FloatArray,
                     viewport: tuple[float, float], out: Ink) -> None:
        """Draw a wide stroke painted with a pattern as a pattern fill is drawn: the pattern's own lines inside
        the band (`lines` in user units placed by `matrix`)."""
        area = _placed(stroke_area(lines, pen), matrix)
        if not area.is_empty:
            self.pattern(server, matrix, _outline(area), "nonzero", viewport, out)

    def stroke_band(self, lines: list[tuple[FloatArray, bool]], pen: Pen, style: dict[str, str],
                    matrix: FloatArray, out: Ink, fill: _Fill | None, shown: BaseGeometry | None = None) -> None:
        """Draw a wide stroke as a fill is drawn: the outline of the band it paints (`lines` in user units placed
        by `matrix`), added to the element's own lines `out`; an opaque band hides what lies under it. With the
        element's solid `fill` (the last of `out.fills`, its border the lines of `out`), the pen draws the border
        of both together: one element's paint is one shape, whatever the colours of its fill and stroke. Only the
        part of the band inside `shown` (where its gradient leaves a mark) is outlined."""
        area = _placed(stroke_area(lines, pen), matrix)
        if area.is_empty:
            return
        band = _Fill([], "nonzero", area, opaque=self.opaque(style, "stroke"))
        if not self._shaded and self._below and band.opaque:
            self.hide_under(band)
        if shown is not None:
            area = shapely.intersection(area, shown)
            band = _Fill([], "nonzero", area, opaque=band.opaque)
        if fill is not None:
            band = _Fill([], "nonzero", shapely.union(fill.area, area), opaque=band.opaque and fill.opaque)
            out.fills.pop()
            out.replace([])
        border = _outline(band.area)
        self._count(sum(len(line) for line in border))
        out.extend(border)
        out.bands.update(id(line) for line in border)
        out.fills.append(band)
        centres = np.concatenate([points for points, _ in lines])
        out.extent.append(_box(affine([centres], matrix)[0]))

    # -- patterns -----------------------------------------------------------------------------------------------

    def pattern(self, el: ET.Element, matrix: FloatArray, rings: Polylines, rule: str,
                viewport: tuple[float, float], out: Ink, *, bordered: bool = False) -> None:
        """Draw a pattern's tiles over the shape whose output `rings` bound it, cut to the fill's area. A tile
        whose opaque paint covers it whole shows one colour across the seams between tiles: the seams draw
        nothing, and the shape's border is drawn (unless `bordered`: its stroke draws it already)."""
        chain = self._server_chain(el)

        def attr(name: str) -> str | None:
            return next((p.get(name) for p in chain if p.get(name) is not None), None)

        content = next((p for p in chain if len(p)), chain[0])
        ref = el.get("id") or ""
        if ref in self._patterns:
            self.unsupported[f"pattern #{ref} refers back to itself: that reference draws nothing"] += 1
            return
        inverse = _invert(matrix)
        user = np.concatenate(affine(rings, inverse))
        (bx, by), (bx1, by1) = user.min(axis=0), user.max(axis=0)
        bw, bh = bx1 - bx, by1 - by
        vw, vh = viewport
        if (attr("patternUnits") or "").strip() == "userSpaceOnUse":
            x, y = length(attr("x"), vw), length(attr("y"), vh)
            w, h = length(attr("width"), vw), length(attr("height"), vh)
        else:
            x, y = bx + number(attr("x"), 0.0) * bw, by + number(attr("y"), 0.0) * bh
            w, h = number(attr("width"), 0.0) * bw, number(attr("height"), 0.0) * bh
        if not (w > 0 and h > 0):
            return
        try:
            space = about(transform(attr("patternTransform")),
                          transform_origin(attr("transform-origin"), (0.0, 0.0, vw, vh)))
        except ValueError:
            space = IDENTITY
        if flattens(space):
            return
        corners = affine([np.array([[bx, by], [bx1, by], [bx1, by1], [bx, by1]])], _invert(space))[0]
        (px0, py0), (px1, py1) = corners.min(axis=0), corners.max(axis=0)
        i0, i1 = math.floor((px0 - x) / w), math.ceil((px1 - x) / w)
        j0, j1 = math.floor((py0 - y) / h), math.ceil((py1 - y) / h)
        if (i1 - i0) * (j1 - j0) > MAX_PATTERN_TILES:
            self.unsupported[f"pattern #{ref} repeats more than {MAX_PATTERN_TILES:,} times over a shape: the "
                             "shape's outline is drawn instead"] += 1
            out.extend(rings)
            return
        vb = read_view_box(attr("viewBox"))
        if vb.box is not None:
            inside = viewport_matrix(vb.box, 0.0, 0.0, w, h, attr("preserveAspectRatio"))
        elif (attr("patternContentUnits") or "").strip() == "objectBoundingBox":
            inside = np.array([[bw, 0.0, 0.0], [0.0, bh, 0.0]])
        else:
            inside = IDENTITY
        tile = Ink()
        self._patterns = (*self._patterns, ref)
        outside, floor, blend_floor = self._below, self._floor, self._blend_floor
        self._below, self._floor, self._blend_floor = [tile], 0, 0
        try:
            self.children(content, self.computed_style(content), inside,
                          (vb.box[2], vb.box[3]) if vb.box else (w, h), tile, 0, ())
        finally:
            self._patterns = self._patterns[:-1]
            self._below, self._floor, self._blend_floor = outside, floor, blend_floor
        whole = shapely.box(0.0, 0.0, w, h)
        cells = [fill.area for fill in tile.fills]
        if (self.computed_style(el).get("overflow") or "hidden").strip() in ("hidden", "scroll"):
            seamless = any(fill.opaque and fill.area.covers(whole) for fill in tile.fills)
            kept, _ = cut(list(tile), whole)
            if seamless:  # one colour across the seams: what lies along the tile's border is no edge
                kept = cut(kept, whole.exterior.buffer(self.tolerance * 2))[1]
            tile = Ink(kept)
            cells = [shapely.intersection(cell, whole) for cell in cells]
        else:
            seamless = False
        area = area_of_rings(rings, rule)
        if seamless and not bordered:
            border = _outline(area)
            self._count(sum(len(line) for line in border))
            out.extend(border)
        if not tile:
            return
        shapely.prepare(area)
        places = [then(matrix, then(space, translate(x + i * w, y + j * h))) for i in range(i0, i1)
                  for j in range(j0, j1)]
        placed = [line for at in places for line in affine(tile, at)]
        kept, _ = cut(placed, area)
        if not seamless and not bordered and cells:  # the tiles' fills the shape's edge cuts show that edge
            if len(places) * len(cells) <= MAX_CUT_CELLS:
                for at in places:
                    for cell in cells:
                        kept.extend(cut_edge(_placed(cell, at), area)[0])
            else:
                self.unsupported[f"pattern fills of more than {MAX_CUT_CELLS:,} cells are not outlined along the "
                                 "shape's edge"] += 1
        self._count(sum(len(k) for k in kept))
        out.extend(kept)

    # -- text -------------------------------------------------------------------------------------------------

    def text(self, el: ET.Element, style: dict[str, str], matrix: FloatArray, viewport: tuple[float, float],
             out: Ink) -> None:
        """A `<text>` in single-stroke letters (see svgtext)."""
        layout = TextLayout(viewport, self.sheet, read_before=self.text_chars, opacity=self.alpha)
        drawn = layout.draw(el, style)
        self.text_chars = layout.read
        for lines in drawn:
            placed = affine(lines, matrix)
            self._count(sum(len(p) for p in placed))
            out.extend(placed)
        for note in layout.notes:
            self.unsupported[note] += 1
        self.unsupported["text is drawn in single-stroke letters, not in the file's font"] += 1

    # -- clipping ---------------------------------------------------------------------------------------------

    def _geometry_box(self, content: Ink, matrix: FloatArray) -> tuple[float, float, float, float] | None:
        """The bounding box (x0, y0, x1, y1) of what `content` draws, in the user units `matrix` places."""
        corners = [np.array([[x0, y0], [x0, y1], [x1, y1], [x1, y0]]) for x0, y0, x1, y1 in content.extent]
        geometry = [line for line in content if id(line) not in content.bands]
        if not geometry and not corners:
            return None
        user = affine([np.concatenate([*geometry, *corners])], _invert(matrix))[0]
        (x0, y0), (x1, y1) = user.min(axis=0), user.max(axis=0)
        return float(x0), float(y0), float(x1), float(y1)

    def basic_shape(self, el: ET.Element, value: str, matrix: FloatArray, content: Ink) -> BaseGeometry | None:
        """The area a CSS basic shape lets through (CSS Masking 1 §6.1, CSS Shapes 1 §3.1: circle(), ellipse(),
        inset(), polygon()) on its reference box: fill-box, stroke-box (the initial one, for border-box and
        margin-box as well) or view-box; None (and a note) for one in error."""
        match = BASIC_SHAPE.match(value)
        assert match is not None
        name, args, rest = match.group(1).lower(), match.group(2).strip(), value[match.end():].strip().lower()
        box = self._geometry_box(content, matrix)
        if box is None:
            return shapely.Polygon()
        x0, y0, x1, y1 = box
        if rest in ("", "border-box", "margin-box", "stroke-box"):
            style = self.computed_style(el)
            if self._paint_kind(style, "stroke")[0] != "none":
                half = self._stroke_width(style, self.user_viewport) / 2
                x0, y0, x1, y1 = x0 - half, y0 - half, x1 + half, y1 + half
        elif rest == "view-box":
            x0, y0, (x1, y1) = 0.0, 0.0, self.user_viewport
        elif rest not in ("fill-box", "content-box", "padding-box"):
            self.unsupported[f"clip-path {excerpt(value, 60)!r} is in error: drawn unclipped"] += 1
            return None
        w, h = x1 - x0, y1 - y0
        try:
            area = _basic_shape(name, args, (x0, y0, w, h), self.tolerance / max(_stretch(matrix), 1e-12))
        except ValueError:
            self.unsupported[f"clip-path {excerpt(value, 60)!r} is in error: drawn unclipped"] += 1
            return None
        return _placed(area, matrix)

    def clip_region(self, value: str, matrix: FloatArray, content: Ink,
                    stack: tuple[str, ...]) -> BaseGeometry | None:
        """The area `clip-path: value` lets through, in output units; None (and a note) when it can't be used."""
        ref = iri(value)
        clip = self.ids.get(ref) if ref else None
        if clip is None or local(clip.tag) != "clipPath":
            self.unsupported[f"clip-path {value!r} does not name a clipPath here: drawn unclipped"] += 1
            return None
        if own_style(clip, self.sheet).get("display", "").strip() == "none":
            return None  # Chromium draws what refers to a clip path that is not displayed unclipped
        if ref in stack:
            self.unsupported[f"clip path #{ref} refers back to itself: that reference is left out, as in "
                             "browsers"] += 1
            return None
        if len(stack) > MAX_DEPTH:
            raise InputError(f"{self.name}: clip paths nested deeper than {MAX_DEPTH}")
        by_box = clip.get("clipPathUnits", "").strip() == "objectBoundingBox"
        # the clip path's transform is in the user space of the element it clips, outside the bounding box's
        # units (SVG 1.1 §14.3.5: "the user coordinate system ... is established using the bounding box" after
        # the transform on the clipPath element)
        own_place = self.placement(clip, own_style(clip, self.sheet), self.computed_style(clip), self.user_viewport)
        if by_box:
            corners = [np.array([[x0, y0], [x0, y1], [x1, y1], [x1, y0]]) for x0, y0, x1, y1 in content.extent]
            geometry = [line for line in content if id(line) not in content.bands]
            if not geometry and not corners:
                return shapely.Polygon()
            pts = np.concatenate([*geometry, *corners])
            user = affine([pts], _invert(matrix))[0]
            (x0, y0), (x1, y1) = user.min(axis=0), user.max(axis=0)
            matrix = then(then(matrix, own_place), np.array([[x1 - x0, 0.0, x0], [0.0, y1 - y0, y0]]))
        else:
            matrix = then(matrix, own_place)
        key = (id(clip), matrix.tobytes())
        if key in self._clips and not by_box:
            return self._clips[key]
        base = self.computed_style(clip)
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
        if not conditions_hold(child):
            return empty
        own = own_style(child, self.sheet)
        style = inherit(base, own)
        if own.get("display", "").strip() == "none" or style.get("visibility", "visible").strip() != "visible":
            return empty
        matrix = then(matrix, self.placement(child, own, style, (0.0, 0.0)))
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
        rings = [np.vstack([s.points, s.points[:1]]) for s in self.subpaths(child, tag, matrix, (0.0, 0.0),
                                                                            self.font(style), keep=True)
                 if len(s.points) >= 3]
        region = area_of_rings(rings, style.get("clip-rule", "nonzero").strip())
        inner = own.get("clip-path", "none").strip()
        if inner != "none":
            content = Ink(list(rings) or [np.zeros((1, 2))])
            limit = self.clip_region(inner, matrix, content, stack)
            if limit is not None:
                region = shapely.intersection(region, limit)
        return region
