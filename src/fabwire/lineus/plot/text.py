"""Text in a single-stroke Hershey font: each line of strokes drawn once, no outlines to retrace.

Hershey fonts hold ASCII only. Other letters are built the way type designers compose them (Unicode canonical
decomposition): the base glyph plus accent strokes placed over or under it (é = e + ´, Å = A + ˚); letters that do
not decompose fall back to their usual spelling (ß → ss, æ → ae) or their compatibility form (ﬁ → fi). Every
character drawn differently, or not at all, is named in the notes.
"""

from __future__ import annotations

import functools
import math
import unicodedata
from dataclasses import dataclass

import numpy as np
from HersheyFonts import HersheyFonts

from fabwire.errors import InputError
from fabwire.lineus.plot.geometry import FloatArray, Polylines

DEFAULT_FONT = "futural"
LINE_SPACING = 1.4
"""Baseline distance as a multiple of the font's cap height."""
ACCENT_HEIGHT = 0.28
"""Height of an accent as a share of the cap height; it sits this far above the letter's top, a third of it apart."""


def _circle(cx: float, cy: float, r: float, n: int = 12) -> list[tuple[float, float]]:
    return [(cx + r * math.cos(2 * math.pi * k / n), cy + r * math.sin(2 * math.pi * k / n)) for k in range(n + 1)]


@dataclass(frozen=True)
class _Mark:
    """Accent strokes in a box: x from -0.5 to 0.5 of the accent width, y from 0 (near the letter) to 1, y up;
    `place` is 'above', 'below' (hanging from the baseline) or 'over' (across the letter's own box)."""

    strokes: tuple[tuple[tuple[float, float], ...], ...]
    place: str = "above"


_MARKS: dict[str, _Mark] = {
    "\u0300": _Mark((((0.2, 0.0), (-0.2, 1.0)),)),  # grave
    "\u0301": _Mark((((-0.2, 0.0), (0.2, 1.0)),)),  # acute
    "\u0302": _Mark((((-0.45, 0.0), (0.0, 1.0), (0.45, 0.0)),)),  # circumflex
    "\u0303": _Mark((((-0.5, 0.2), (-0.25, 0.8), (0.0, 0.5), (0.25, 0.2), (0.5, 0.8)),)),  # tilde
    "\u0304": _Mark((((-0.45, 0.5), (0.45, 0.5)),)),  # macron
    "\u0306": _Mark((((-0.45, 1.0), (-0.3, 0.3), (0.0, 0.0), (0.3, 0.3), (0.45, 1.0)),)),  # breve
    "\u0307": _Mark((tuple(_circle(0.0, 0.5, 0.14)),)),  # dot above
    "\u0308": _Mark((tuple(_circle(-0.3, 0.5, 0.14)), tuple(_circle(0.3, 0.5, 0.14)))),  # diaeresis
    "\u030a": _Mark((tuple(_circle(0.0, 0.5, 0.4)),)),  # ring above
    "\u030b": _Mark((((-0.4, 0.0), (-0.1, 1.0)), ((0.1, 0.0), (0.4, 1.0)))),  # double acute
    "\u030c": _Mark((((-0.45, 1.0), (0.0, 0.0), (0.45, 1.0)),)),  # caron
    "\u0327": _Mark((((0.0, 1.0), (0.15, 0.5), (-0.25, 0.0)),), "below"),  # cedilla
    "\u0328": _Mark((((0.3, 1.0), (0.0, 0.5), (0.4, 0.0)),), "below"),  # ogonek
    "\u0337": _Mark((((-0.35, 0.35), (0.35, 0.65)),), "over"),  # short solidus overlay (ł)
    "\u0338": _Mark((((-0.5, -0.05), (0.5, 1.05)),), "over"),  # long solidus overlay (ø)
    "\u0335": _Mark((((-0.3, 0.6), (0.3, 0.6)),), "over"),  # short stroke overlay (đ, ħ)
}
_FALLBACK = {
    "ß": "ss", "ẞ": "SS", "æ": "ae", "Æ": "AE", "œ": "oe", "Œ": "OE", "þ": "th", "Þ": "Th", "ð": "d\u0335",
    "Ð": "D\u0335", "đ": "d\u0335", "Đ": "D\u0335", "ħ": "h\u0335", "Ħ": "H\u0335", "ø": "o\u0338", "Ø": "O\u0338",
    "ł": "l\u0337", "Ł": "L\u0337", "ı": "i", "‘": "'", "’": "'", "‚": ",", "“": '"', "”": '"', "„": '"',
    "–": "-", "—": "-", "‐": "-", "−": "-", "…": "...", "«": "<<", "»": ">>", "\u00a0": " ", "€": "EUR",
    "£": "GBP", "©": "(c)", "®": "(R)", "™": "TM", "×": "x", "·": ".",
}


def font_names() -> list[str]:
    return list(HersheyFonts().default_font_names)


@functools.lru_cache(maxsize=8)
def _font(name: str) -> HersheyFonts:
    font = HersheyFonts()
    if name not in font.default_font_names:
        raise InputError(f"unknown font {name!r}; choose one of: {', '.join(font.default_font_names)}")
    font.load_default_font(name)
    return font


def _glyph(face: HersheyFonts, char: str) -> object | None:
    found = list(face.glyphs_for_text(char)) if len(char) == 1 else []
    return found[0] if found else None


def _spell(face: HersheyFonts, char: str, depth: int = 0) -> list[tuple[str, list[str]]] | None:
    """`char` as (base letter the font has, accent marks) pairs, or None when it cannot be built."""
    if _glyph(face, char) is not None:
        return [(char, [])]
    if depth > 3:
        return None
    if char in _FALLBACK:
        return _spell_text(face, _FALLBACK[char], depth + 1)
    decomposed = unicodedata.normalize("NFD", char)
    if len(decomposed) > 1 and _glyph(face, decomposed[0]) is not None:
        marks = list(decomposed[1:])
        if all(m in _MARKS for m in marks):
            return [(decomposed[0], marks)]
    compatible = unicodedata.normalize("NFKD", char)
    if compatible != char:
        return _spell_text(face, compatible, depth + 1)
    return None


def _spell_text(face: HersheyFonts, text: str, depth: int) -> list[tuple[str, list[str]]] | None:
    out: list[tuple[str, list[str]]] = []
    for char in text:
        if char in _MARKS and out:
            out[-1][1].append(char)
            continue
        part = _spell(face, char, depth)
        if part is None:
            return None
        out.extend(part)
    return out


def _mark_strokes(mark: _Mark, box: tuple[float, float, float, float], cap: float, baseline: float) -> Polylines:
    """A mark's strokes placed for a glyph whose drawn box is (x0, top, x1, bottom), glyph units, y down."""
    x0, top, x1, bottom = box
    cx = (x0 + x1) / 2
    if mark.place == "over":
        w, h, y0 = max(x1 - x0, cap * 0.3), bottom - top, bottom
    else:
        h = cap * ACCENT_HEIGHT
        w = max(min(x1 - x0, cap * 0.6), cap * 0.3)
        y0 = top - h / 3 if mark.place == "above" else baseline + h
    out: Polylines = []
    for stroke in mark.strokes:
        pts = np.array(stroke, dtype=float)
        out.append(np.column_stack([cx + pts[:, 0] * w, y0 - pts[:, 1] * h]))
    return out


def text_lines(text: str, *, font: str = DEFAULT_FONT, cap_height: float = 1.0,
               notes: list[str] | None = None) -> Polylines:
    """Strokes of `text` with y up, the first baseline at y = 0, letters `cap_height` tall.

    Characters built from a base letter and accents, or spelled another way, and characters that cannot be drawn
    at all, are named in `notes`. InputError when nothing at all can be drawn.
    """
    if not text.strip():
        raise InputError("the text is empty")
    face = _font(font)
    top, baseline = _cap_span(face)
    cap = baseline - top
    scale = cap_height / cap
    result: Polylines = []
    missing: list[str] = []
    respelled: list[str] = []
    for row, line in enumerate(text.split("\n")):
        x = 0.0
        for char in line:
            spelled = _spell(face, char)
            if spelled is None:
                missing.append(char)
                continue
            if spelled != [(char, [])]:
                respelled.append(char)
            for base, marks in spelled:
                glyph = _glyph(face, base)
                shift = np.array([x - glyph.left_offset, 0.0])  # type: ignore[attr-defined]
                strokes = [np.array(s, dtype=float) + shift for s in glyph.strokes if len(s)]  # type: ignore[attr-defined]
                if strokes:
                    allp = np.concatenate(strokes)
                    box = (float(allp[:, 0].min()), float(allp[:, 1].min()), float(allp[:, 0].max()),
                           float(allp[:, 1].max()))
                else:
                    box = (x, top, x + glyph.char_width, baseline)  # type: ignore[attr-defined]
                for mark in marks:
                    strokes.extend(_mark_strokes(_MARKS[mark], box, cap, baseline))
                for poly in strokes:
                    placed: FloatArray = poly * scale
                    # Hershey glyphs run y down from the cap line; flip so y is up with the baseline at 0.
                    placed[:, 1] = (baseline * scale - placed[:, 1]) - row * LINE_SPACING * cap_height
                    result.append(placed)
                x += float(glyph.char_width)  # type: ignore[attr-defined]
    if not result:
        raise InputError(f"font {font!r} has no strokes for {text!r}")
    if notes is not None:
        if respelled:
            notes.append(f"built from letters and accent strokes, or spelled out: {_listing(respelled)}")
        if missing:
            notes.append(f"font {font!r} cannot draw {_listing(missing)}: left out")
    return result


def _listing(chars: list[str]) -> str:
    unique = list(dict.fromkeys(chars))
    return ", ".join(f"{c!r} (U+{ord(c):04X})" for c in unique[:20]) + (" …" if len(unique) > 20 else "")


def _cap_span(face: HersheyFonts) -> tuple[float, float]:
    """(cap line, baseline) y of the font, measured on 'H' (y down)."""
    ys = [float(p[1]) for seg in face.lines_for_text("H") for p in seg]
    if not ys or max(ys) <= min(ys):
        return (0.0, 1.0)
    return (min(ys), max(ys))
