"""Text in a single-stroke Hershey font: each line of strokes drawn once, no outlines to retrace."""

from __future__ import annotations

import functools

import numpy as np
from HersheyFonts import HersheyFonts

from fabwire.errors import InputError
from fabwire.lineus.plot.geometry import FloatArray, Polylines

DEFAULT_FONT = "futural"
LINE_SPACING = 1.4
"""Baseline distance as a multiple of the font's cap height."""


def font_names() -> list[str]:
    return list(HersheyFonts().default_font_names)


@functools.lru_cache(maxsize=8)
def _font(name: str) -> HersheyFonts:
    font = HersheyFonts()
    if name not in font.default_font_names:
        raise InputError(f"unknown font {name!r}; choose one of: {', '.join(font.default_font_names)}")
    font.load_default_font(name)
    return font


def _chain(segments: list[tuple[tuple[float, float], tuple[float, float]]]) -> Polylines:
    """Join consecutive segments that share an end into polylines."""
    out: list[list[tuple[float, float]]] = []
    for a, b in segments:
        if out and out[-1][-1] == a:
            out[-1].append(b)
        else:
            out.append([a, b])
    return [np.asarray(line, dtype=float) for line in out]


def text_lines(text: str, *, font: str = DEFAULT_FONT, cap_height: float = 1.0) -> Polylines:
    """Strokes of `text` with y up, the first baseline at y = 0, letters `cap_height` tall."""
    if not text.strip():
        raise InputError("the text is empty")
    face = _font(font)
    top, baseline = _cap_span(face)
    scale = cap_height / (baseline - top)
    result: Polylines = []
    for row, line in enumerate(text.split("\n")):
        segments = [((float(a[0]), float(a[1])), (float(b[0]), float(b[1]))) for a, b in face.lines_for_text(line)]
        for poly in _chain(segments):
            placed: FloatArray = poly * scale
            # Hershey glyphs run y down from the cap line; flip so y is up with the baseline at 0.
            placed[:, 1] = (baseline * scale - placed[:, 1]) - row * LINE_SPACING * cap_height
            result.append(placed)
    if not result:
        raise InputError(f"font {font!r} has no strokes for {text!r}")
    return result


def _cap_span(face: HersheyFonts) -> tuple[float, float]:
    """(cap line, baseline) y of the font, measured on 'H' (y down)."""
    ys = [float(p[1]) for seg in face.lines_for_text("H") for p in seg]
    if not ys or max(ys) <= min(ys):
        return (0.0, 1.0)
    return (min(ys), max(ys))
