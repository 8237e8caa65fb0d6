"""The SVG style cascade a browser applies, reduced to the properties that decide what a pen draws: paint,
opacity, visibility, display, line caps, clipping.

Sources: SVG 1.1 §6 (styling: presentation attributes < style sheets < the `style` attribute; inheritance),
§11.2 (paint), CSS 2.1 §6.4.3 (specificity).
"""

from __future__ import annotations

import functools
import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import svgelements as se

from fabwire.lineus.plot.svgunits import length

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
    """A plain number or a percentage (as a fraction), such as an opacity; `default` when absent or in error."""
    if value is None:
        return default
    try:
        text = value.strip()
        result = float(text[:-1]) / 100 if text.endswith("%") else float(text)
    except ValueError:
        return default
    return result if math.isfinite(result) else default


def paints(style: dict[str, str], which: str) -> bool:
    """Whether the fill or stroke paint of `style` puts anything on the page (not none, not transparent)."""
    value = style.get(which, INITIAL[which]).strip().lower()
    if value in ("none", "transparent", ""):
        return False
    if number(style.get(f"{which}-opacity"), 1.0) <= 0:
        return False
    if which == "stroke" and length(style.get("stroke-width"), 1.0, default=1.0) == 0:
        return False  # a negative width is in error: the initial 1 applies
    return value.startswith("url(") or _opaque(value)


@functools.lru_cache(maxsize=256)
def _opaque(color: str) -> bool:
    """Whether a colour puts ink on the page (its alpha is not 0); one that does not parse is taken as ink."""
    try:
        return bool(se.Color(color).alpha != 0)
    except (ValueError, TypeError):
        return True


def iri(value: str | None) -> str | None:
    """The id in `url(#id)`, or None."""
    if not value:
        return None
    match = _IRI.search(value)
    return match.group(1) if match else None
