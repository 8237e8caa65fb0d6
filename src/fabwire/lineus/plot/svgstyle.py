"""The SVG style cascade a browser applies, reduced to the properties that decide what a pen draws: paint,
opacity, visibility, display, dashes, line caps, clipping, transforms, fonts.

Style sheets are parsed by tinycss2 and their selectors matched by cssselect2 (WeasyPrint's and CairoSVG's CSS
engine), so every CSS 3 selector (descendant, child, sibling, attribute, :first-child, :not() …) applies.
Cascade order (CSS Cascade 4 §6, SVG 2 §6.6 presentation attributes): presentation attributes < style sheet
rules by specificity then order < the `style` attribute < `!important` sheet rules < `!important` in `style`.
Inheritance (CSS Cascade 4 §7): inherited properties flow to children, `inherit` takes the parent's value for any
property. `@media print` rules are not applied (a browser shows the screen media); other `@media` and `@supports`
blocks are. Font sizes are computed to px as they inherit, so `em` lengths use the inherited size (CSS Values 3
§6.1).

Sources: SVG 1.1 §6 (styling), SVG 2 §6.6 (presentation attributes), §11.2 (paint), CSS 2.1 §6.4.3
(specificity), CSS Fonts 3 §3.5 (absolute and relative size keywords).
"""

from __future__ import annotations

import functools
import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from typing import Any

import cssselect2
import tinycss2
import tinycss2.color4

from fabwire.errors import InputError
from fabwire.lineus.plot.svgunits import length

INHERITED = frozenset({
    "fill", "stroke", "fill-opacity", "stroke-opacity", "stroke-width", "stroke-linecap", "visibility",
    "clip-rule", "fill-rule", "marker-start", "marker-mid", "marker-end", "marker", "stroke-dasharray",
    "stroke-dashoffset", "font-size", "font-family", "font-style", "font-weight", "text-anchor", "color",
    "letter-spacing", "word-spacing", "stroke-linejoin", "stroke-miterlimit",
})
NOT_INHERITED = frozenset({"display", "opacity", "clip-path", "mask", "filter", "overflow", "transform",
                           "transform-origin", "transform-box", "stop-color", "stop-opacity"})
GEOMETRY = frozenset({"x", "y", "width", "height", "cx", "cy", "r", "rx", "ry", "d"})
"""Geometry properties (SVG 2 §10.2-10.4): a style sheet or `style` attribute may set them; the attributes of
the same names are read with the shape."""
PROPERTIES = INHERITED | NOT_INHERITED | GEOMETRY
PRESENTATION_ATTRIBUTES = PROPERTIES - {"transform", "marker"} - GEOMETRY
"""Properties that may be given as attributes too; the `transform` attribute has its own (SVG 1.1) grammar and is
read apart from the CSS property; the `marker` shorthand is a property only (SVG 2 §13.7.4)."""
INITIAL = {"fill": "black", "stroke": "none", "fill-opacity": "1", "stroke-opacity": "1", "stroke-width": "1",
           "stroke-linecap": "butt", "stroke-linejoin": "miter", "stroke-miterlimit": "4", "visibility": "visible",
           "clip-rule": "nonzero", "fill-rule": "nonzero",
           "font-size": "16", "color": "black"}
FONT_SIZE_KEYWORDS = {"xx-small": 9.0, "x-small": 10.0, "small": 13.0, "medium": 16.0, "large": 18.0,
                      "x-large": 24.0, "xx-large": 32.0, "xxx-large": 48.0}
"""Absolute font-size keywords in px as browsers compute them (CSS Fonts 4 §2.5, Chromium's table for 16 px)."""
RELATIVE_FONT_STEP = 1.2
"""`larger` and `smaller` scale the parent's font size by this factor (CSS Fonts 3 §3.5, as browsers do)."""
PAPER = (255, 255, 255)
"""The colour of the sheet the pen draws on."""
PAPER_TOLERANCE = 6
"""A paint whose colour, laid over the paper at its opacity, comes within this of the paper in every channel
(of 255) leaves no visible mark."""

_IRI = re.compile(r"url\(\s*['\"]?#([^'\")\s]+)['\"]?\s*\)")


def local(tag: object) -> str:
    """An element's tag without its namespace ('' for comments and processing instructions)."""
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def _declarations(tokens: object) -> list[tuple[str, str, bool]]:
    """(name, value, important) of known properties in a rule body or style attribute."""
    out: list[tuple[str, str, bool]] = []
    for item in tinycss2.parse_blocks_contents(tokens, skip_whitespace=True, skip_comments=True):
        if item.type == "declaration" and item.lower_name in PROPERTIES:
            out.append((item.lower_name, tinycss2.serialize(item.value).strip(), bool(item.important)))
    return out


def declarations(text: str) -> dict[str, str]:
    """`name: value; …` pairs of a style attribute, lower-case names, known properties only."""
    return {name: value for name, value, _ in _declarations(text)}


MAX_SELECTOR_CHECKS = 10_000_000
"""Selectors times elements matched at most: a style sheet of thousands of rules over thousands of elements would
take the planner minutes (each pair costs a selector test), far beyond any real drawing's."""


@dataclass
class StyleSheet:
    """The rules of a document's `<style>` elements, matched to its elements."""

    matched: dict[int, list[tuple[bool, tuple[int, int, int], int, str, str]]] = field(default_factory=dict)
    """Per element (by id()): (important, specificity, order, property, value) of every matching declaration."""
    ignored: list[str] = field(default_factory=list)
    """Selectors and at-rules that could not be read."""

    @classmethod
    def of(cls, root: ET.Element) -> StyleSheet:
        """Parse every `<style>` of the document and match its rules against all elements."""
        sheet = cls()
        matcher = cssselect2.Matcher()
        elements = sum(1 for _ in root.iter())
        budget = MAX_SELECTOR_CHECKS // max(elements, 1)  # selectors the document's size allows
        count = 0
        for el in root.iter():
            if local(el.tag) == "style" and el.text and (el.get("type") or "text/css").strip() == "text/css":
                count += sheet._add(matcher, tinycss2.parse_stylesheet(el.text, skip_comments=True,
                                                                       skip_whitespace=True), budget - count)
                if count > budget:
                    raise InputError(f"the drawing's style sheets hold more than {budget:,} selectors for its "
                                     f"{elements:,} elements, more matching than a drawing needs (at most "
                                     f"{MAX_SELECTOR_CHECKS:,} pairs); refusing it")
        if not count:
            return sheet
        for wrapper in cssselect2.ElementWrapper.from_xml_root(root).iter_subtree():
            found = matcher.match(wrapper)
            if found:
                sheet.matched[id(wrapper.etree_element)] = [
                    (important, specificity, order, name, value)
                    for specificity, order, _, body in found for name, value, important in body]
        return sheet

    def _add(self, matcher: cssselect2.Matcher, rules: list[Any], room: int) -> int:
        """Add `rules`' selectors to `matcher`; the count added, stopping once past `room`."""
        count = 0
        for rule in rules:
            if count > room:
                break
            kind = getattr(rule, "type", "")
            if kind == "at-rule":
                keyword = rule.lower_at_keyword
                prelude = tinycss2.serialize(rule.prelude).lower()
                if keyword in ("media", "supports") and rule.content is not None \
                        and not (keyword == "media" and "print" in prelude and "screen" not in prelude):
                    count += self._add(matcher, tinycss2.parse_rule_list(
                        rule.content, skip_comments=True, skip_whitespace=True), room - count)
                elif keyword not in ("media", "import", "charset", "namespace", "font-face", "keyframes"):
                    self.ignored.append(f"@{keyword}")
                continue
            if kind != "qualified-rule":
                continue
            body = _declarations(rule.content)
            try:
                selectors = cssselect2.compile_selector_list(rule.prelude)
            except cssselect2.SelectorError:
                self.ignored.append(tinycss2.serialize(rule.prelude).strip())
                continue
            for selector in selectors:
                if selector.pseudo_element is None and body:
                    matcher.add_selector(selector, body)
                    count += 1
        return count


def own_style(element: ET.Element, sheet: StyleSheet) -> dict[str, str]:
    """The properties `element` sets itself, the cascade applied; `inherit` values are kept for `inherit()`."""
    out = {name: value.strip() for name, value in element.attrib.items() if name in PRESENTATION_ATTRIBUTES}
    rules = sheet.matched.get(id(element))
    style = element.get("style")
    if not rules and not style:
        return out
    inline = _declarations(style) if style else []
    rules = rules or []
    for _, _, _, name, value in sorted((r for r in rules if not r[0]), key=lambda r: (r[1], r[2])):
        out[name] = value
    out.update((name, value) for name, value, important in inline if not important)
    for _, _, _, name, value in sorted((r for r in rules if r[0]), key=lambda r: (r[1], r[2])):
        out[name] = value
    out.update((name, value) for name, value, important in inline if important)
    return out


def inherit(parent: dict[str, str], own: dict[str, str]) -> dict[str, str]:
    """The computed properties of a child: inherited ones from `parent`, then its own (`inherit` takes the
    parent's value of any property; a font size becomes px of the parent's)."""
    out = {k: v for k, v in parent.items() if k in INHERITED}
    for name, value in own.items():
        if value == "inherit":
            if name in parent:
                out[name] = parent[name]
            else:
                out.pop(name, None)
        elif name == "font-size":
            out[name] = repr(font_size(value, float(parent.get("font-size", INITIAL["font-size"]))))
        else:
            out[name] = value
    return out


def font_size(value: str, parent: float) -> float:
    """A `font-size` value in px, given the parent's (em and % are of it); the parent's when in error."""
    text = value.strip().lower()
    if text in FONT_SIZE_KEYWORDS:
        return FONT_SIZE_KEYWORDS[text]
    if text == "larger":
        return parent * RELATIVE_FONT_STEP
    if text == "smaller":
        return parent / RELATIVE_FONT_STEP
    size = length(text, parent, default=-1.0, font_size=parent)
    return size if size >= 0 else parent


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


def written(style: dict[str, str], key: str, default: str | None = None) -> str:
    """A paint or colour property of `style` as written, lower case, with `currentColor` read as the `color` it
    stands for (CSS Color 4 §4.4); `default` when absent (the property's initial value unless given)."""
    value = style.get(key, INITIAL[key] if default is None else default).strip().lower()
    return style.get("color", INITIAL["color"]).strip().lower() if value == "currentcolor" else value


def paints(style: dict[str, str], which: str, opacity: float = 1.0) -> bool:
    """Whether the fill or stroke paint of `style` leaves a mark on the paper: not none, not transparent, not
    the paper's colour (a white fill on white paper shows nothing), nor so faint at its opacity times `opacity`
    (the element's and its groups') that it comes within PAPER_TOLERANCE of the paper."""
    value = style.get(which, INITIAL[which]).strip().lower()
    if value in ("none", "transparent", ""):
        return False
    alpha = min(1.0, max(0.0, number(style.get(f"{which}-opacity"), 1.0))) * min(1.0, max(0.0, opacity))
    if alpha <= 0:
        return False
    if which == "stroke" and length(style.get("stroke-width"), 1.0, default=1.0) == 0:
        return False  # a negative width is in error: the initial 1 applies
    if value.startswith("url("):
        return True
    return _marks(written(style, which), alpha)


def opaque_fill(style: dict[str, str], which: str = "fill") -> bool:
    """Whether the fill (or the stroke, `which`) paints a solid colour without any transparency (white too), so it
    hides what is under it."""
    value = written(style, which)
    if value in ("none", "transparent", "") or value.startswith("url(") or number(style.get(f"{which}-opacity"),
                                                                                  1.0) < 1:
        return False
    return _alpha(value) >= 1


def opaque_stop(style: dict[str, str]) -> bool:
    """Whether a gradient stop of this computed style has no transparency (stop-color black and stop-opacity 1
    unless given)."""
    if number(style.get("stop-opacity"), 1.0) < 1:
        return False
    return _alpha(written(style, "stop-color", "black")) >= 1


def stop_paint(style: dict[str, str]) -> tuple[tuple[float, float, float], float]:
    """A gradient stop's colour as sRGB channels 0..1 and its alpha 0..1 (the colour's own alpha times
    stop-opacity) from its computed style; stop-color is black unless given, and one that does not parse is
    black too (SVG 1.1 §13.2.4)."""
    r, g, b, own = srgba(written(style, "stop-color", "black")) or (0.0, 0.0, 0.0, 1.0)
    opacity = min(1.0, max(0.0, number(style.get("stop-opacity"), 1.0)))
    return (r, g, b), own * opacity


@functools.lru_cache(maxsize=1024)
def srgba(colour: str) -> tuple[float, float, float, float] | None:
    """A CSS Color 4 colour as sRGB channels and alpha, each 0..1 (channels clipped to the sRGB gamut); None when
    it does not parse. A colour in a space the parser cannot convert to sRGB (`lab()`, `oklch()`,
    `color(display-p3 …)`) counts as black at its alpha: it is ink, drawn like any dark paint."""
    parsed = tinycss2.color4.parse_color(colour)
    if parsed is None or not hasattr(parsed, "to"):
        return None
    try:
        r, g, b, a = (float(v) for v in parsed.to("srgb"))
    except NotImplementedError:
        r, g, b, a = 0.0, 0.0, 0.0, float(parsed.alpha)
    r, g, b = (min(1.0, max(0.0, v)) if math.isfinite(v) else 0.0 for v in (r, g, b))
    return r, g, b, min(1.0, max(0.0, a)) if math.isfinite(a) else 1.0


def _alpha(color: str) -> float:
    """A colour's own alpha (0 for a colour that does not parse)."""
    found = srgba(color)
    return 0.0 if found is None else found[3]


@functools.lru_cache(maxsize=256)
def _marks(color: str, alpha: float) -> bool:
    """Whether a colour (CSS Color 4) at `alpha` leaves a mark on the paper; one that does not parse is ink."""
    found = srgba(color)
    if found is None:
        return True
    *channels, own_alpha = found
    share = alpha * own_alpha
    return any(abs(share * 255 * c + (1 - share) * p - p) > PAPER_TOLERANCE
               for c, p in zip(channels, PAPER, strict=True))


def solid_colour(style: dict[str, str], which: str) -> str | None:
    """The fill's (or stroke's) colour as written (lower case, `currentColor` resolved), None for a paint server;
    `same_colour` tells whether two such spellings are one colour."""
    value = written(style, which)
    return None if value.startswith("url(") else value


def same_colour(first: str | None, second: str | None) -> bool:
    """Whether two colours of `solid_colour` are one colour in sRGB (`navy`, `#000080`, `rgb(0 0 128)` alike)."""
    if first is None or second is None:
        return False
    if first == second:
        return True
    spelled = _spelled(first)
    return spelled is not None and spelled == _spelled(second)


def _spelled(colour: str) -> str | None:
    """A CSS colour spelled `rgb(r g b / a)` in sRGB; None when it does not parse."""
    found = srgba(colour)
    return None if found is None else "rgb({} {} {} / {})".format(*(round(v, 6) for v in found))


def same_paint_value(style: dict[str, str]) -> bool:
    """Whether the fill and stroke of `style` name the same paint: the same paint server, or colours equal in
    sRGB (`black`, `#000`, `rgb(0 0 0)` alike; `currentColor` as the colour it stands for)."""
    fill, stroke = written(style, "fill"), written(style, "stroke")
    return fill == stroke or same_colour(fill, stroke)


def fallback_in_error(value: str) -> bool:
    """Whether what follows `url(...)` in a paint is neither nothing, `none`, `currentColor` nor one colour (so
    Chromium drops the whole declaration, as for `url(#g) green icc-color(...)`; SVG 2 §13.3, CSS Color 4)."""
    rest = value[value.find(")") + 1:].strip().lower() if ")" in value else ""
    if rest in ("", "none", "currentcolor"):
        return False
    parsed = tinycss2.color4.parse_color(rest)
    return parsed is None


def iri(value: str | None) -> str | None:
    """The id in `url(#id)`, or None."""
    if not value:
        return None
    match = _IRI.search(value)
    return match.group(1) if match else None
