"""The SVG style cascade a browser applies, reduced to the properties that decide what a pen draws: paint,
opacity, visibility, display, line caps, clipping. Also lengths, transforms and viewBox → viewport mapping.

Sources: SVG 1.1 §6 (styling: presentation attributes < style sheets < the `style` attribute; inheritance),
§7.7-7.8 (viewBox, preserveAspectRatio), §7.10 (units), §11.2 (paint), CSS 2.1 §6.4.3 (specificity).
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np
import svgelements as se

from fabwire.lineus.plot.geometry import FloatArray, compose

INHERITED = frozenset({
    "fill", "stroke", "fill-opacity", "stroke-opacity", "stroke-width", "stroke-linecap", "visibility",
    "clip-rule", "fill-rule", "marker-start", "marker-mid", "marker-end", "marker",
})
NOT_INHERITED = frozenset({"display", "opacity", "clip-path", "mask", "filter", "overflow"})
PROPERTIES = INHERITED | NOT_INHERITED
INITIAL = {"fill": "black", "stroke": "none", "fill-opacity": "1", "stroke-opacity": "1", "stroke-width": "1",
           "stroke-linecap": "butt", "visibility": "visible", "clip-rule": "nonzero", "fill-rule": "nonzero"}

_RULE = re.compile(r"([^{}]+)\{([^{}]*)\}")
_COMMENT = re.compile(r"/\*.*?\*/", re.DOTALL)
_SIMPLE_SELECTOR = re.compile(r"^(\*|[A-Za-z][\w-]*)?((?:[.#][\w-]+)*)$")
_IRI = re.compile(r"url\(\s*['\"]?#([^'\")\s]+)['\"]?\s*\)")


def local(tag: object) -> str:
    """An element's tag without its namespace ('' for comments and processing instructions)."""
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def declarations(text: str) -> dict[str, str]:
    """`name: value; …` pairs of a style attribute or rule body, lower-case names, known properties only."""
    out: dict[str, str] = {}
    for part in text.split(";"):
        name, sep, value = part.partition(":")
        name = name.strip().lower()
        if sep and name in PROPERTIES:
            out[name] = value.replace("!important", "").strip()
    return out


@dataclass
class StyleSheet:
    """The `<style>` rules with simple selectors (type, #id, .class, combined); others are reported."""

    rules: list[tuple[tuple[int, int, int], int, str | None, str | None, frozenset[str], dict[str, str]]] = \
        field(default_factory=list)
    ignored: list[str] = field(default_factory=list)

    def add(self, css: str) -> None:
        for match in _RULE.finditer(_COMMENT.sub("", css)):
            body = declarations(match.group(2))
            for selector in match.group(1).split(","):
                selector = selector.strip()
                parsed = _SIMPLE_SELECTOR.match(selector)
                if not selector or selector.startswith("@"):
                    continue
                if parsed is None or not (parsed.group(1) or parsed.group(2)):
                    self.ignored.append(selector)
                    continue
                tag = parsed.group(1) if parsed.group(1) not in (None, "*") else None
                parts = re.findall(r"[.#][\w-]+", parsed.group(2))
                ident = next((p[1:] for p in parts if p[0] == "#"), None)
                classes = frozenset(p[1:] for p in parts if p[0] == ".")
                specificity = (1 if ident else 0, len(classes), 1 if tag else 0)
                if body:
                    self.rules.append((specificity, len(self.rules), tag, ident, classes, body))
        self.rules.sort(key=lambda rule: (rule[0], rule[1]))

    def matching(self, element: ET.Element) -> dict[str, str]:
        out: dict[str, str] = {}
        if not self.rules:
            return out
        tag = local(element.tag)
        ident = element.get("id")
        classes = set((element.get("class") or "").split())
        for _, _, r_tag, r_id, r_classes, body in self.rules:
            if (r_tag is None or r_tag == tag) and (r_id is None or r_id == ident) and r_classes <= classes:
                out.update(body)
        return out


def own_style(element: ET.Element, sheet: StyleSheet) -> dict[str, str]:
    """The properties `element` sets itself, cascade applied (attribute < sheet < style attribute)."""
    out = {name: value.strip() for name, value in element.attrib.items() if name in PROPERTIES}
    out.update(sheet.matching(element))
    style = element.get("style")
    if style:
        out.update(declarations(style))
    return {k: v for k, v in out.items() if v != "inherit"}


def inherit(parent: dict[str, str], own: dict[str, str]) -> dict[str, str]:
    """The computed properties of a child: inherited ones from `parent`, then its own."""
    out = {k: v for k, v in parent.items() if k in INHERITED}
    out.update(own)
    return out


def number(value: str | None, default: float) -> float:
    if value is None:
        return default
    try:
        text = value.strip()
        result = float(text[:-1]) / 100 if text.endswith("%") else float(text)
    except ValueError:
        return default
    return result if np.isfinite(result) else default


def paints(style: dict[str, str], which: str) -> bool:
    """Whether the fill or stroke paint of `style` puts anything on the page (not none, not transparent)."""
    value = style.get(which, INITIAL[which]).strip().lower()
    if value in ("none", "transparent", ""):
        return False
    if number(style.get(f"{which}-opacity"), 1.0) <= 0:
        return False
    if which == "stroke" and length(style.get("stroke-width"), 1.0, default=1.0) <= 0:
        return False
    if value.startswith("url("):
        return True
    try:
        return bool(se.Color(value).alpha != 0)
    except (ValueError, TypeError):
        return True


def length(value: str | None, relative_to: float, *, default: float = 0.0) -> float:
    """A length in user units (CSS px at 96 per inch); percentages of `relative_to`."""
    if value is None or not value.strip():
        return default
    try:
        result = se.Length(value.strip()).value(ppi=96.0, relative_length=relative_to, font_size=16.0)
        result = float(result)
    except (ValueError, TypeError, AttributeError, ZeroDivisionError):
        return default
    return result if np.isfinite(result) else default


def transform(value: str | None) -> FloatArray:
    """The `transform` attribute as a 2x3 matrix (identity when absent); ValueError when it holds numbers that
    are not finite, which no viewer can place."""
    if not value or not value.strip():
        return np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    m = se.Matrix(value)
    out = np.array([[m.a, m.c, m.e], [m.b, m.d, m.f]], dtype=float)
    if not np.isfinite(out).all():
        raise ValueError(f"transform {value.strip()[:60]!r} is not finite")
    return out


def translate(x: float, y: float) -> FloatArray:
    return np.array([[1.0, 0.0, x], [0.0, 1.0, y]])


def view_box(value: str | None) -> tuple[float, float, float, float] | None:
    """(min-x, min-y, width, height), or None when absent or not usable (width or height not positive)."""
    if not value:
        return None
    parts = re.split(r"[\s,]+", value.strip())
    try:
        x, y, w, h = (float(p) for p in parts)
    except ValueError:
        return None
    return (x, y, w, h) if w > 0 and h > 0 and np.isfinite([x, y, w, h]).all() else None


def renders_nothing(width: str | None, height: str | None, view_box_value: str | None) -> bool:
    """Whether a viewport's width, height or viewBox size is zero, which disables its rendering (SVG 1.1 §7.7,
    §7.9, §14.3.3): a browser shows nothing of it. A negative one is an error and is ignored instead."""
    sizes = [width, height]
    if view_box_value:
        sizes.extend(re.split(r"[\s,]+", view_box_value.strip())[2:4])
    for text in sizes:
        try:
            if text is not None and float(text.strip().removesuffix("px")) == 0:
                return True
        except ValueError:
            continue
    return False


def viewport_matrix(box: tuple[float, float, float, float] | None, x: float, y: float, width: float,
                    height: float, aspect: str | None) -> FloatArray:
    """Map a viewBox onto the viewport (x, y, width, height) as `preserveAspectRatio` says (SVG 1.1 §7.8)."""
    if box is None:
        return translate(x, y)
    bx, by, bw, bh = box
    sx, sy = width / bw, height / bh
    words = (aspect or "xMidYMid meet").split()
    align = words[0] if words else "xMidYMid"
    if align != "none":
        s = max(sx, sy) if "slice" in words[1:] else min(sx, sy)
        sx = sy = s
    tx, ty = x - bx * sx, y - by * sy
    if align != "none":
        if "xMid" in align:
            tx += (width - bw * sx) / 2
        elif "xMax" in align:
            tx += width - bw * sx
        if "YMid" in align:
            ty += (height - bh * sy) / 2
        elif "YMax" in align:
            ty += height - bh * sy
    return np.array([[sx, 0.0, tx], [0.0, sy, ty]])


def iri(value: str | None) -> str | None:
    """The id in `url(#id)`, or None."""
    if not value:
        return None
    match = _IRI.search(value)
    return match.group(1) if match else None


def then(outer: FloatArray, inner: FloatArray) -> FloatArray:
    """`inner` applied first, then `outer` (nested coordinate systems)."""
    return compose(outer, inner)
