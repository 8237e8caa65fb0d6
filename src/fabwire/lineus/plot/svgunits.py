"""SVG geometry attributes read as browsers read them: lengths, `viewBox`, `preserveAspectRatio` and transform
lists, with their error handling. An attribute in error is ignored (its initial value applies), a size of zero
disables rendering, and a transform that flattens the plane makes its element show nothing.

Sources: SVG 1.1 §7.6 (transform list grammar), §7.7 (viewBox: "a negative value is an error and invalidates the
viewBox; a value of zero disables rendering"), §7.8 (preserveAspectRatio), §7.10 (units), §F.2 (error processing:
an attribute in error is as if not given). Browsers hold these numbers in single precision: a number beyond
FLOAT32_MAX does not parse, so the attribute holding it is in error (as Chromium renders it).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from fabwire.errors import excerpt
from fabwire.lineus.plot.geometry import FloatArray

FLOAT32_MAX = float(np.finfo(np.float32).max)
"""The largest number a browser's SVG attribute parser takes (single precision)."""
IDENTITY: FloatArray = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

_NUMBER = r"(?>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"
_COMMA_WSP = r"(?>\s*,\s*|\s+)"
_VIEW_BOX = re.compile(rf"\s*({_NUMBER}){_COMMA_WSP}({_NUMBER}){_COMMA_WSP}({_NUMBER}){_COMMA_WSP}({_NUMBER})\s*")
_ASPECT = re.compile(r"\s*(none|x(?:Min|Mid|Max)Y(?:Min|Mid|Max))(?:\s+(meet|slice))?\s*")
_FUNCTION = rf"(matrix|translate|scale|rotate|skewX|skewY)\s*\(\s*((?:{_NUMBER}(?:{_COMMA_WSP}?{_NUMBER})*)?)\s*\)"
_TRANSFORM_LIST = re.compile(rf"\s*{_FUNCTION}(?:[\s,]*+{_FUNCTION})*\s*")
_TRANSFORM_ONE = re.compile(_FUNCTION)
_UNITS = "px|pt|pc|mm|cm|in|q|em|ex|rem|ch|cap|ic|lh|rlh|vw|vh|vi|vb|vmin|vmax|%"
_ARITY = {"matrix": (6,), "translate": (1, 2), "scale": (1, 2), "rotate": (1, 3), "skewX": (1,), "skewY": (1,)}


def translate(x: float, y: float) -> FloatArray:
    return np.array([[1.0, 0.0, x], [0.0, 1.0, y]])


ROOT_FONT_SIZE = 16.0
"""The font size of the document root, px, when the root sets none (a browser's default medium)."""

FONT_METRICS: tuple[tuple[tuple[str, ...], float, float, float, float, float, float], ...] = (
    # (family names, ex, ch, cap, ascent, descent, ic) in em: the font-relative units of CSS Values 4 §6.1.1 as
    # Chromium resolves them with the faces Debian installs for these families (fonts-noto-core,
    # fonts-dejavu-core): ex = OS/2 sxHeight, cap = OS/2 sCapHeight, ch = advance of "0", ascent and descent from
    # hhea (lh, `line-height: normal`, is their sum, each rounded to whole px as Chromium does; no line gap), ic =
    # advance of U+6C34 (1 em, the fallback when no face holds it). Sources: the fonts' OS/2 and hhea tables
    # (OpenType spec), checked by getBBox() of rects sized in each unit in Chromium.
    (("sans-serif", "noto sans", "arial", "helvetica", "liberation sans", "system-ui", "times new roman"),
     0.536, 0.572, 0.714, 1.069, 0.293, 1.0),
    (("serif", "noto serif"), 0.536, 0.559, 0.714, 1.069, 0.293, 1.0),
    (("dejavu sans",), 0.5469, 0.6362, 0.7291, 1901 / 2048, 483 / 2048, 1.0),
    (("dejavu serif",), 0.5119, 0.6362, 0.7219, 1901 / 2048, 483 / 2048, 1.0),
    (("monospace", "dejavu sans mono"), 0.5469, 0.6021, 0.7291, 1901 / 2048, 483 / 2048, 1.0),
)
"""Font-relative length units per family; a family not listed falls back to the first row, as a browser falls
back to its default face (Noto Sans on Debian). Below about 100 px Chromium grid-fits the x-height and cap
height of the hinted DejaVu faces to whole px: ex and cap may then differ from a browser's by up to 1 px."""
_FONT_UNITS = ("ex", "ch", "cap", "lh", "ic")
_METRICS = ("ex", "ch", "cap", "ascent", "descent", "ic")


def font_metrics(family: str) -> dict[str, float]:
    """The ex, ch, cap, ascent, descent and ic of the first family of a `font-family` list that FONT_METRICS
    knows, in em."""
    for name in (n.strip().strip("'\"").lower() for n in family.split(",")):
        for names, *values in FONT_METRICS:
            if name in names:
                return dict(zip(_METRICS, values, strict=True))
    return dict(zip(_METRICS, FONT_METRICS[0][1:], strict=True))


def line_height(size: float, family: str) -> float:
    """`line-height: normal` in px of a font of `size` px: ascent and descent, each rounded to whole px."""
    metrics = font_metrics(family)
    return float(round(size * metrics["ascent"]) + round(size * metrics["descent"]))


@dataclass(frozen=True)
class Font:
    """What font-relative and viewport-relative lengths are of: the element's font size (px) and `font-family`,
    the root element's, and the viewport of the page (px; (0, 0) when unknown, then vw/vh/... are in error)."""

    size: float = ROOT_FONT_SIZE
    family: str = ""
    root_size: float = ROOT_FONT_SIZE
    root_family: str = ""
    viewport: tuple[float, float] = (0.0, 0.0)

    def unit(self, name: str) -> float | None:
        """px per one `name` unit (lower case), or None for a unit not relative to the font or viewport."""
        if name == "em":
            return self.size
        if name == "rem":
            return self.root_size
        if name == "lh":
            return line_height(self.size, self.family)
        if name == "rlh":
            return line_height(self.root_size, self.root_family)
        if name in _FONT_UNITS:
            return self.size * font_metrics(self.family)[name]
        w, h = self.viewport
        if w <= 0 or h <= 0:
            return None
        # horizontal writing: the inline axis is x, the block axis y (CSS Values 4 §6.1.2)
        return {"vw": w, "vi": w, "vh": h, "vb": h, "vmin": min(w, h), "vmax": max(w, h)}.get(name, 0.0) / 100 \
            if name in ("vw", "vi", "vh", "vb", "vmin", "vmax") else None


ABSOLUTE_UNITS = {"": 1.0, "px": 1.0, "in": 96.0, "cm": 96 / 2.54, "mm": 96 / 25.4, "q": 96 / 101.6, "pt": 96 / 72,
                  "pc": 16.0}
"""CSS px per absolute unit (CSS Values 4 §6.2; a bare number is px, as SVG user units)."""
_LENGTH = re.compile(rf"\s*({_NUMBER})([a-zA-Z]*|%)\s*")


def length(value: str | None, relative_to: float, *, default: float = 0.0, font_size: float | Font = 16.0) -> float:
    """A length in user units (CSS px at 96 per inch): absolute units, percentages of `relative_to`, font-relative
    units (em, ex, ch, cap, ic, lh, rem, rlh) and viewport units (vw, vh, vi, vb, vmin, vmax) of `font_size` (px, or
    a Font); `default` when absent, in error (an unknown unit, trailing text) or not finite."""
    match = _LENGTH.fullmatch(value) if value is not None else None
    if match is None:
        return default
    font = font_size if isinstance(font_size, Font) else Font(font_size)
    unit = match.group(2).lower()
    scale = relative_to / 100 if unit == "%" else ABSOLUTE_UNITS.get(unit, font.unit(unit))
    if scale is None:
        return default
    result = float(match.group(1)) * scale
    return result if math.isfinite(result) else default


def size_is_zero(value: str | None) -> bool:
    """Whether a viewport `width` or `height` is a length of zero, in any unit or as a percentage: that disables
    rendering of the viewport (SVG 1.1 §7.9, §5.1.2). A value in error is not zero (it falls back to auto)."""
    if value is None or not value.strip():
        return False
    match = re.fullmatch(rf"\s*({_NUMBER})(?:{_UNITS})?\s*", value, re.IGNORECASE)
    return match is not None and _single(match.group(1)) == 0


def beyond_single(value: str | None) -> bool:
    """Whether a length's number is beyond single precision: browsers hold it as infinite (a `<use>` placed
    there shows nothing), where this reader's `length` would take it as absent."""
    match = re.fullmatch(rf"\s*({_NUMBER})(?:{_UNITS})?\s*", value or "", re.IGNORECASE)
    return match is not None and math.isinf(_single(match.group(1)))


def _single(text: str) -> float:
    """A number as a browser holds it: rounded to single precision; inf when beyond it."""
    value = float(text)
    if abs(value) > FLOAT32_MAX:
        return math.copysign(math.inf, value)
    return float(np.float32(value))


@dataclass(frozen=True)
class ViewBox:
    """A `viewBox` as read: `box` (min-x, min-y, width, height) when usable; `error` says why the attribute is
    ignored; `empty` when its width or height is zero, which disables rendering."""

    box: tuple[float, float, float, float] | None = None
    error: str = ""
    empty: bool = False


def read_view_box(value: str | None) -> ViewBox:
    """The `viewBox` attribute: four numbers without units, separated by white space and/or a comma."""
    if value is None:
        return ViewBox()
    match = _VIEW_BOX.fullmatch(value)
    if match is None:
        return ViewBox(error="it is not four plain numbers")
    numbers = [_single(part) for part in match.groups()]
    if not all(math.isfinite(n) for n in numbers):
        return ViewBox(error="a number in it is beyond what a browser can hold")
    x, y, w, h = numbers
    for name, size in (("width", w), ("height", h)):
        if size < 0:
            return ViewBox(error=f"its {name} is negative")
    if w == 0 or h == 0:
        return ViewBox(empty=True, error=f"{'width' if w == 0 else 'height'} is 0")
    return ViewBox((x, y, w, h))


def aspect_ratio(value: str | None) -> tuple[str, bool]:
    """`preserveAspectRatio` as (align, slice); a value in error is the initial 'xMidYMid meet' (SVG 1.1 §7.8)."""
    match = _ASPECT.fullmatch(value) if value is not None else None
    if match is None:
        return "xMidYMid", False
    return match.group(1), match.group(2) == "slice"


def viewport_matrix(box: tuple[float, float, float, float] | None, x: float, y: float, width: float,
                    height: float, aspect: str | None) -> FloatArray:
    """Map a viewBox onto the viewport (x, y, width, height) as `preserveAspectRatio` says (SVG 1.1 §7.8)."""
    if box is None:
        return translate(x, y)
    bx, by, bw, bh = box
    sx, sy = width / bw, height / bh
    align, slice_ = aspect_ratio(aspect)
    if align != "none":
        s = max(sx, sy) if slice_ else min(sx, sy)
        sx = sy = s
    tx, ty = x - bx * sx, y - by * sy
    if align != "none":
        share = {"Min": 0.0, "Mid": 0.5, "Max": 1.0}
        tx += (width - bw * sx) * share[align[1:4]]
        ty += (height - bh * sy) * share[align[5:8]]
    return np.array([[sx, 0.0, tx], [0.0, sy, ty]])


def transform(value: str | None) -> FloatArray:
    """The `transform` attribute as a 2x3 matrix; the identity when absent. ValueError (with the reason) when the
    list breaks the grammar or holds a number a browser cannot hold: browsers then ignore the attribute."""
    if value is None or not value.strip() or value.strip() == "none":
        return IDENTITY
    if _TRANSFORM_LIST.fullmatch(value) is None:
        raise ValueError("it breaks the transform list grammar")
    out = IDENTITY
    for name, args in _TRANSFORM_ONE.findall(value):
        numbers = [_single(n) for n in re.findall(_NUMBER, args)]
        if len(numbers) not in _ARITY[name]:
            raise ValueError(f"{name}() takes {' or '.join(map(str, _ARITY[name]))} numbers, not {len(numbers)}")
        if not all(math.isfinite(n) for n in numbers):
            raise ValueError("a number in it is beyond what a browser can hold")
        out = out @ np.vstack([_function_matrix(name, numbers), [0.0, 0.0, 1.0]])
    return np.asarray(out[:2], dtype=float)


def _function_matrix(name: str, n: list[float]) -> FloatArray:
    if name == "matrix":
        a, b, c, d, e, f = n
        return np.array([[a, c, e], [b, d, f]])
    if name == "translate":
        return translate(n[0], n[1] if len(n) > 1 else 0.0)
    if name == "scale":
        return np.array([[n[0], 0.0, 0.0], [0.0, n[1] if len(n) > 1 else n[0], 0.0]])
    if name == "rotate":
        a = math.radians(n[0])
        cos, sin = math.cos(a), math.sin(a)
        cx, cy = (n[1], n[2]) if len(n) == 3 else (0.0, 0.0)
        return np.array([[cos, -sin, cx - cos * cx + sin * cy], [sin, cos, cy - sin * cx - cos * cy]])
    skew = math.tan(math.radians(n[0]))
    return np.array([[1.0, skew, 0.0], [0.0, 1.0, 0.0]] if name == "skewX" else [[1.0, 0.0, 0.0], [skew, 1.0, 0.0]])


def flattens(matrix: FloatArray) -> bool:
    """Whether the transform maps the plane onto a line or a point (determinant 0, or not finite): what it
    draws has no extent, and browsers show nothing of it."""
    det = float(matrix[0, 0] * matrix[1, 1] - matrix[0, 1] * matrix[1, 0])
    return not (math.isfinite(det) and det != 0)


ANGLE_UNITS = {"deg": 1.0, "grad": 0.9, "rad": 180 / math.pi, "turn": 360.0, "": 1.0}
"""Degrees per unit of a CSS angle (CSS Values 3 §7.1); a bare number is taken as degrees, as in SVG."""
_CSS_FUNCTION = re.compile(r"\s*([a-zA-Z]+)\s*\(([^()]*)\)\s*")
_CSS_ARG = re.compile(rf"\s*({_NUMBER})\s*([a-zA-Z%]*)\s*")
_CSS_TRANSLATE_AXES = {"translate": "xy", "translatex": "x", "translatey": "y"}
_CSS_SCALE_AXES = {"scale": "xy", "scalex": "x", "scaley": "y"}


def css_transform(value: str, viewport: tuple[float, float], font_size: float | Font = 16.0) -> FloatArray:
    """The CSS `transform` property (CSS Transforms 1 §13: 2D functions with units) as a 2x3 matrix; `none` is
    the identity. Lengths take CSS units (a bare number is px, as SVG allows); percentages are of the viewport
    (`transform-box: view-box`, the initial box of SVG elements). ValueError when the value is in error."""
    text = value.strip()
    if not text or text.lower() == "none":
        return IDENTITY
    out = np.eye(3)
    at = 0
    while at < len(text):
        match = _CSS_FUNCTION.match(text, at)
        if match is None:
            raise ValueError("it breaks the CSS transform grammar")
        at = match.end()
        name = match.group(1).lower()
        args = [a for a in re.split(r"\s*,\s*|\s+", match.group(2).strip()) if a]
        matrix = _css_function(name, args, viewport, font_size)
        with np.errstate(invalid="ignore", over="ignore"):  # a product beyond floats flattens: `flattens` says so
            out = out @ np.vstack([matrix, [0.0, 0.0, 1.0]])
    return np.asarray(out[:2], dtype=float)


def angle(text: str) -> float:
    """A CSS angle (a number with deg, grad, rad or turn, or none for degrees) in degrees; ValueError otherwise."""
    match = _CSS_ARG.fullmatch(text)
    if match is None or match.group(2).lower() not in ANGLE_UNITS:
        raise ValueError(f"{excerpt(text, 40)} is not an angle")
    return float(match.group(1)) * ANGLE_UNITS[match.group(2).lower()]


def _css_function(name: str, args: list[str], viewport: tuple[float, float], font_size: float | Font) -> FloatArray:
    def size(text: str, axis: int) -> float:
        result = length(text, viewport[axis], default=math.nan, font_size=font_size)
        if not math.isfinite(result):
            raise ValueError(f"{excerpt(text, 40)} is not a length")
        return result

    if name in _CSS_TRANSLATE_AXES and 1 <= len(args) <= len(_CSS_TRANSLATE_AXES[name]):
        axes = _CSS_TRANSLATE_AXES[name]
        moved = {axis: size(arg, "xy".index(axis)) for axis, arg in zip(axes, args, strict=False)}
        return translate(moved.get("x", 0.0), moved.get("y", 0.0))
    if name in _CSS_SCALE_AXES and 1 <= len(args) <= len(_CSS_SCALE_AXES[name]):
        factors = [number_or_percent(a) for a in args]
        sx, sy = {"scale": (factors[0], factors[-1]), "scalex": (factors[0], 1.0),
                  "scaley": (1.0, factors[0])}[name]
        return np.array([[sx, 0.0, 0.0], [0.0, sy, 0.0]])
    if name == "rotate" and len(args) == 1:
        return _function_matrix("rotate", [angle(args[0])])
    if name in ("skew", "skewx", "skewy") and 1 <= len(args) <= (2 if name == "skew" else 1):
        ax = angle(args[0]) if name != "skewy" else 0.0
        ay = angle(args[-1]) if name == "skewy" or len(args) == 2 else 0.0
        return np.array([[1.0, math.tan(math.radians(ax)), 0.0], [math.tan(math.radians(ay)), 1.0, 0.0]])
    if name == "matrix" and len(args) == 6:
        return _function_matrix("matrix", [number_or_percent(a) for a in args])
    raise ValueError(f"{name}() with {len(args)} arguments is not a 2D CSS transform function")


def number_or_percent(text: str) -> float:
    """A plain number, or a percentage as a fraction; ValueError otherwise."""
    match = _CSS_ARG.fullmatch(text)
    if match is None or match.group(2) not in ("", "%"):
        raise ValueError(f"{excerpt(text, 40)} is not a number")
    return float(match.group(1)) / (100.0 if match.group(2) else 1.0)


ORIGIN_KEYWORDS = {"left": (0, 0.0), "right": (0, 1.0), "top": (1, 0.0), "bottom": (1, 1.0), "center": (-1, 0.5)}
"""`transform-origin` keywords: the axis each names (-1 either) and the share of the reference box."""


def transform_origin(value: str | None, box: tuple[float, float, float, float],
                     font_size: float | Font = 16.0) -> tuple[float, float]:
    """The point `transform-origin` names (CSS Transforms 1 §7), in user units; percentages and keywords are of
    `box` (x, y, width, height), the element's reference box, and lengths are offsets from its corner. (0, 0) of
    user space when absent or in error (the initial value for SVG elements)."""
    parts = (value or "").split()[:2]
    if not parts:
        return (0.0, 0.0)
    if len(parts) == 2 and (ORIGIN_KEYWORDS.get(parts[0].lower(), (-1, 0))[0] == 1
                            or ORIGIN_KEYWORDS.get(parts[1].lower(), (-1, 0))[0] == 0):
        parts.reverse()  # "top left": the vertical keyword given first
    if len(parts) == 1:
        keyword = ORIGIN_KEYWORDS.get(parts[0].lower())
        parts = ["center", parts[0]] if keyword and keyword[0] == 1 else [parts[0], "center"]
    out = []
    for axis, part in enumerate(parts):
        keyword = ORIGIN_KEYWORDS.get(part.lower())
        offset, extent = box[axis], box[axis + 2]
        if keyword is not None and keyword[0] in (-1, axis):
            out.append(offset + keyword[1] * extent)
            continue
        point = length(part, extent, default=math.nan, font_size=font_size)
        if not math.isfinite(point):
            return (0.0, 0.0)
        out.append(offset + point)
    return (out[0], out[1])


def about(matrix: FloatArray, origin: tuple[float, float]) -> FloatArray:
    """`matrix` applied about `origin` instead of (0, 0): translate(origin) · matrix · translate(-origin)."""
    if origin == (0.0, 0.0):
        return matrix
    out = matrix.copy()
    ox, oy = origin
    out[:, 2] += np.array([ox, oy]) - matrix[:, :2] @ np.array([ox, oy])
    return out
