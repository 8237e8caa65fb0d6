"""SVG `<text>` laid out as a browser places it, drawn in the single-stroke Hershey fonts of `lineus text`: each
letter once, not its outline twice around every stroke.

Layout (SVG 1.1 §10.4-§10.5, §10.9.1, §10.15): `x`, `y`, `dx`, `dy` lists position characters (an absolute `x`
or `y` starts a new text chunk), `text-anchor` aligns each chunk (start, middle, end), `<tspan>` and `<a>`
children carry their own style and positions, white space collapses unless `xml:space="preserve"`. The font size
is the em box: letters are CAP_HEIGHT_PER_EM of it tall, as the capitals of common sans-serif fonts are; the
advance of each letter is the Hershey font's own, so a line of text is about as long as in a browser but not
exactly. Generic and common font families choose a Hershey face (FONT_FAMILIES); the transform of the text and
its ancestors applies.
"""

from __future__ import annotations

import functools
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from fabwire.errors import InputError
from fabwire.lineus.plot.geometry import Polylines
from fabwire.lineus.plot.svgstyle import StyleSheet, inherit, local, number, own_style, paints
from fabwire.lineus.plot.svgunits import length
from fabwire.lineus.plot.text import DEFAULT_FONT, text_lines

TEXT_MODES = ("hershey", "outline")
"""How SVG text is drawn: in single-stroke letters, or left out (to be converted to outlines beforehand)."""
CAP_HEIGHT_PER_EM = 0.72
"""Capital height of the letters as a share of the font size (Arial 0.716, DejaVu Sans 0.729, Helvetica 0.717)."""
XML_SPACE = "{http://www.w3.org/XML/1998/namespace}space"
FONT_FAMILIES: tuple[tuple[tuple[str, ...], tuple[str, str, str, str], float, float], ...] = (
    # (family names, Hershey faces regular / bold / italic / bold italic, width, space) - CSS Fonts 4 §4.2 generic
    # families and common faces. Width scales the Hershey letters across so a word is as long as in the browser's
    # face, measured on a pangram against Noto Sans, Noto Serif and DejaVu Sans Mono at 30 px; space is the
    # advance of a space in em, from those fonts' metrics (Hershey spaces are far wider).
    (("serif", "times", "times new roman", "georgia", "garamond", "dejavu serif", "liberation serif",
      "noto serif"), ("timesr", "timesrb", "timesi", "timesib"), 0.84, 0.26),
    (("cursive", "comic sans ms", "brush script mt", "script"), ("scripts", "scriptc", "scripts", "scriptc"), 1.12,
     0.26),
    (("fantasy", "fraktur", "old english text mt"), ("gothiceng", "gothiceng", "gothicita", "gothicita"), 0.93,
     0.26),
    (("monospace", "courier", "courier new", "dejavu sans mono", "liberation mono"),
     (DEFAULT_FONT, "futuram", DEFAULT_FONT, "futuram"), 1.03, 0.6),
    (("sans-serif", "arial", "helvetica", "verdana", "dejavu sans", "liberation sans", "noto sans", "system-ui"),
     (DEFAULT_FONT, "futuram", DEFAULT_FONT, "futuram"), 0.91, 0.26),
)
"""Hershey faces for CSS font families; the first listed family known here chooses (else the last row)."""

_WORDS = re.compile(r"( +)")


def hershey_face(style: dict[str, str]) -> tuple[str, float, float]:
    """The Hershey face, width factor and space advance (em) for the style's font-family, -weight and -style."""
    bold = style.get("font-weight", "normal").strip().lower() in ("bold", "bolder", "600", "700", "800", "900")
    italic = style.get("font-style", "normal").strip().lower() in ("italic", "oblique")
    pick = (2 if italic else 0) + (1 if bold else 0)
    for name in (n.strip().strip("'\"").lower() for n in style.get("font-family", "").split(",")):
        for names, faces, width, space in FONT_FAMILIES:
            if name in names:
                return faces[pick], width, space
    _, faces, width, space = FONT_FAMILIES[-1]
    return faces[pick], width, space


MAX_TEXT_CHARS = 5_000
"""Characters of SVG text in one file: more than a Line-us area holds legibly; each costs the planner strokes."""


@functools.lru_cache(maxsize=4096)
def _strokes(text: str, face: str, cap: float) -> tuple[tuple[np.ndarray, ...], float, tuple[str, ...]]:
    """(strokes with y up from the baseline at x = 0, advance width, notes) of one run of text."""
    notes: list[str] = []
    try:
        lines = text_lines(text, font=face, cap_height=cap, notes=notes) if text.strip() else []
    except InputError as exc:
        notes.append(str(exc))
        lines = []
    mark = text_lines("H", font=face, cap_height=cap)
    after = text_lines(text + "H", font=face, cap_height=cap)[-len(mark):]
    advance = float(min(p[:, 0].min() for p in after) - min(p[:, 0].min() for p in mark))
    return tuple(lines), advance, tuple(notes)


@dataclass
class _Char:
    char: str
    style: dict[str, str]
    x: float | None = None
    y: float | None = None
    dx: float = 0.0
    dy: float = 0.0


@dataclass
class TextLayout:
    """Lays out `<text>` elements of one viewport (width, height in user units), styles from `sheet`."""

    viewport: tuple[float, float]
    sheet: StyleSheet
    read_before: int = 0
    """Characters of text the file had before this element (the bound is on the whole file)."""
    opacity: float = 1.0
    """The opacity of the text element and its groups: paint this faint may leave no mark (svgstyle.paints)."""
    notes: list[str] = field(default_factory=list)
    _pen: tuple[float, float] = field(default=(0.0, 0.0), init=False)
    """Where the next chunk without a position of its own starts."""
    read: int = field(default=0, init=False)
    """Characters read so far, `read_before` included (bounded by MAX_TEXT_CHARS)."""

    def __post_init__(self) -> None:
        self.read = self.read_before

    def draw(self, el: ET.Element, style: dict[str, str]) -> list[Polylines]:
        """The text's letters in its user units (y down), one list of strokes per run of letters."""
        chars = self._characters(el, style)
        out: list[Polylines] = []
        for chunk in self._chunks(chars):
            out.extend(self._chunk(chunk))
        return out

    def _characters(self, root: ET.Element, style: dict[str, str]) -> list[_Char]:
        chars: list[_Char] = []

        def lengths(el: ET.Element, name: str, relative: float, font: float) -> list[float]:
            return [length(v, relative, font_size=font) for v in (el.get(name) or "").replace(",", " ").split()]

        def walk(el: ET.Element, style: dict[str, str], preserve: bool) -> None:
            font = number(style.get("font-size"), 16.0)
            vw, vh = self.viewport
            lists = {name: lengths(el, name, vw if name in ("x", "dx") else vh, font)
                     for name in ("x", "y", "dx", "dy")}
            if el.get("rotate") or el.get("textLength"):
                self.notes.append("text rotate and textLength are not applied: letters are drawn upright, at their "
                                  "own width")
            start = len(chars)
            preserve = (el.get(XML_SPACE) or ("preserve" if preserve else "default")) == "preserve"

            def add(text: str | None, style: dict[str, str]) -> None:
                if not text:
                    return
                text = text.replace("\t", " ") if preserve else text.replace("\n", "").replace("\t", " ")
                text = text.replace("\r", "").replace("\n", " ")
                self.read += len(text)
                if self.read > MAX_TEXT_CHARS:
                    raise InputError(f"the drawing's text holds more than {MAX_TEXT_CHARS:,} characters, more "
                                     "than a Line-us page takes; refusing it (convert the text to paths, or "
                                     "split it)")
                chars.extend(_Char(c, style) for c in text)

            add(el.text, style)
            for child in el:
                tag = local(child.tag)
                if tag in ("tspan", "a", "textPath"):
                    own = own_style(child, self.sheet)
                    inner = inherit(style, own)
                    if own.get("display", "").strip() != "none":
                        if tag == "textPath":
                            self.notes.append("text on a path is drawn on a straight line")
                        walk(child, inner, preserve)
                add(child.tail, style)
            for index, char in enumerate(chars[start:]):
                for name in ("x", "y", "dx", "dy"):
                    values = lists[name]
                    if index < len(values) and (getattr(char, name) in (None, 0.0)):
                        setattr(char, name, values[index])

        walk(root, style, False)
        if (root.get(XML_SPACE) or "default") != "preserve":
            chars = self._collapse(chars)
        return [c for c in chars if c.style.get("visibility", "visible").strip() == "visible" or c.x is not None
                or c.y is not None]

    @staticmethod
    def _collapse(chars: list[_Char]) -> list[_Char]:
        """Default white space handling: no leading or trailing spaces, runs of spaces as one."""
        out: list[_Char] = []
        for char in chars:
            if char.char == " " and (not out or out[-1].char == " "):
                continue
            out.append(char)
        while out and out[-1].char == " ":
            out.pop()
        return out

    @staticmethod
    def _chunks(chars: list[_Char]) -> list[list[_Char]]:
        chunks: list[list[_Char]] = []
        for char in chars:
            if not chunks or char.x is not None or char.y is not None:
                chunks.append([])
            chunks[-1].append(char)
        return chunks

    def _chunk(self, chunk: list[_Char]) -> list[Polylines]:
        """One text chunk: runs of letters with one style, placed along the baseline, then anchored."""
        runs: list[tuple[float, float, Polylines]] = []
        x = chunk[0].x if chunk[0].x is not None else self._pen[0]
        y = chunk[0].y if chunk[0].y is not None else self._pen[1]
        start = x
        index = 0
        while index < len(chunk):
            first = chunk[index]
            x, y = x + first.dx, y + first.dy
            end = index + 1
            while end < len(chunk) and chunk[end].style is first.style and not (chunk[end].dx or chunk[end].dy):
                end += 1
            text = "".join(c.char for c in chunk[index:end])
            size = number(first.style.get("font-size"), 16.0)
            face, width, space = hershey_face(first.style)
            # white, unpainted or too faint text shows nothing
            shown = first.style.get("visibility", "visible").strip() == "visible" and (
                paints(first.style, "fill", self.opacity) or paints(first.style, "stroke", self.opacity))
            for word in _WORDS.split(text):
                if word.startswith(" "):
                    x += len(word) * space * size
                    continue
                if not word:
                    continue
                lines, advance, notes = _strokes(word, face, size * CAP_HEIGHT_PER_EM)
                self.notes.extend(notes)
                if shown:
                    runs.append((x, y, [np.column_stack([p[:, 0] * width + x, y - p[:, 1]]) for p in lines]))
                x += advance * width
            index = end
        self._pen = (x, y)
        anchor = chunk[0].style.get("text-anchor", "start").strip()
        shift = {"middle": -(x - start) / 2, "end": -(x - start)}.get(anchor, 0.0)
        return [[line + np.array([shift, 0.0]) for line in lines] for _, _, lines in runs]
