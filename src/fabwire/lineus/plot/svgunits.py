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
import svgelements as se

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
_UNITS = "px|pt|pc|mm|cm|in|q|em|ex|rem|ch|vw|vh|vmin|vmax|%"
_ARITY = {"matrix": (6,), "translate": (1, 2), "scale": (1, 2), "rotate": (1, 3), "skewX": (1,), "skewY": (1,)}


def translate(x: float, y: float) -> FloatArray:
    return np.array([[1.0, 0.0, x], [0.0, 1.0, y]])


def length(value: str | None, relative_to: float, *, default: float = 0.0) -> float:
    """A length in user units (CSS px at 96 per inch); percentages of `relative_to`; `default` when absent, in
    error or not finite."""
    if value is None or not value.strip():
        return default
    try:
        result = se.Length(value.strip()).value(ppi=96.0, relative_length=relative_to, font_size=16.0)
        result = float(result)
    except (ValueError, TypeError, AttributeError, ZeroDivisionError, OverflowError):
        return default
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
