"""Pictures of a drawing in machine units: pen-down strokes, pen-up travel and the reachable-area outline.

The frame is the machine's: +X away from the body (rightwards), +Y up the sheet, so a preview shows what lands
on the paper. SVG is written as plain text; PNG goes through Pillow.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np
import numpy.typing as npt
from PIL import Image, ImageDraw

from fabwire.errors import InputError
from fabwire.lineus.kinematics import BOUNDS, area_outline

Polyline = Sequence[tuple[float, float]] | Sequence[Sequence[float]] | npt.NDArray[np.float64]

MARGIN = 60.0
"""Units of empty paper around the reachable area's bounding box."""
PNG_SCALE = 0.3
"""PNG pixels per machine unit (the default picture is about 470 x 980 pixels)."""

STROKE_COLOUR = (20, 20, 20)
TRAVEL_COLOUR = (230, 120, 60)
AREA_COLOUR = (120, 170, 230)
BACKGROUND = (255, 255, 255)


def frame() -> tuple[float, float, float, float]:
    """The drawn extent in machine units: (x_min, y_min, width, height)."""
    x0, y0, x1, y1 = BOUNDS
    return (x0 - MARGIN, y0 - MARGIN, x1 - x0 + 2 * MARGIN, y1 - y0 + 2 * MARGIN)


def png_size(scale: float = PNG_SCALE) -> tuple[int, int]:
    """Pixel size of the PNG `write_drawing` produces at `scale`."""
    _, _, w, h = frame()
    return (math.ceil(w * scale), math.ceil(h * scale))


def write_drawing(
    path: str | Path,
    strokes: Iterable[Polyline],
    travel: Iterable[Polyline] | None = None,
    *,
    title: str | None = None,
    scale: float = PNG_SCALE,
) -> Path:
    """Write the drawing to `path` as .svg or .png, chosen by the suffix."""
    out = Path(path)
    suffix = out.suffix.lower()
    strokes_l = [_points(s) for s in strokes]
    travel_l = [_points(t) for t in travel or ()]
    if suffix == ".svg":
        text = svg_text(strokes_l, travel_l, title=title)
        _write(out, lambda: out.write_text(text, encoding="utf-8"))
    elif suffix == ".png":
        image = _png_image(strokes_l, travel_l, title=title, scale=scale)
        _write(out, lambda: image.save(out, format="PNG"))
    else:
        raise InputError(f"{out}: preview files must end in .svg or .png, not {out.suffix or 'nothing'!r}")
    return out


def _points(line: Polyline) -> list[tuple[float, float]]:
    rows = line.tolist() if isinstance(line, np.ndarray) else line
    return [(float(p[0]), float(p[1])) for p in rows]


def _write(out: Path, save: Callable[[], object]) -> None:
    try:
        save()
    except OSError as exc:
        raise InputError(f"cannot write {out}: {exc.strerror or exc}") from exc


def _svg_points(line: Polyline) -> str:
    return " ".join(f"{x:.1f},{-y:.1f}" for x, y in line)


def svg_text(strokes: Sequence[Polyline], travel: Sequence[Polyline] = (), *, title: str | None = None) -> str:
    """The drawing as an SVG document whose user units are machine units (Y flipped so +Y is up)."""
    fx, fy, fw, fh = frame()
    mm_w, mm_h = fw / 20.0, fh / 20.0
    rgb = "rgb({},{},{})".format
    parts = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{mm_w:.1f}mm" height="{mm_h:.1f}mm" '
        f'viewBox="{fx:.1f} {-(fy + fh):.1f} {fw:.1f} {fh:.1f}">',
    ]
    if title:
        parts.append(f"<title>{escape(title)}</title>")
    parts.append(f'<rect x="{fx:.1f}" y="{-(fy + fh):.1f}" width="{fw:.1f}" height="{fh:.1f}" fill="white"/>')
    parts.append(
        f'<polygon id="reachable-area" points="{_svg_points(area_outline())}" fill="{rgb(*AREA_COLOUR)}" '
        'fill-opacity="0.12" stroke="' + rgb(*AREA_COLOUR) + '" stroke-width="4"/>'
    )
    if travel:
        parts.append(f'<g id="travel" fill="none" stroke="{rgb(*TRAVEL_COLOUR)}" stroke-width="3" '
                     'stroke-dasharray="12 10">')
        parts.extend(f'<polyline points="{_svg_points(t)}"/>' for t in travel if len(t) >= 2)
        parts.append("</g>")
    parts.append(f'<g id="strokes" fill="none" stroke="{rgb(*STROKE_COLOUR)}" stroke-width="6" '
                 'stroke-linecap="round" stroke-linejoin="round">')
    for s in strokes:
        if len(s) == 1:
            x, y = s[0]
            parts.append(f'<circle cx="{x:.1f}" cy="{-y:.1f}" r="3"/>')
        elif s:
            parts.append(f'<polyline points="{_svg_points(s)}"/>')
    parts.append("</g>")
    if title:
        parts.append(f'<text x="{fx + 20:.1f}" y="{-(fy + fh) + 60:.1f}" font-family="sans-serif" '
                     f'font-size="44">{escape(title)}</text>')
    parts.append("</svg>")
    return "\n".join(parts) + "\n"


def _png_image(
    strokes: Sequence[Polyline], travel: Sequence[Polyline], *, title: str | None, scale: float
) -> Image.Image:
    fx, fy, _, fh = frame()
    size = png_size(scale)
    image = Image.new("RGB", size, BACKGROUND)
    draw = ImageDraw.Draw(image)

    def px(line: Polyline) -> list[tuple[float, float]]:
        return [((x - fx) * scale, (fy + fh - y) * scale) for x, y in line]

    outline = px(area_outline())
    draw.polygon(outline, fill=(235, 242, 250), outline=AREA_COLOUR)
    width = max(1, round(6 * scale))
    for t in travel:
        if len(t) >= 2:
            draw.line(px(t), fill=TRAVEL_COLOUR, width=1)
    for s in strokes:
        if len(s) == 1:
            (cx, cy), r = px(s)[0], max(1.0, 3 * scale)
            draw.ellipse((cx - r, cy - r, cx + r, cy + r), fill=STROKE_COLOUR)
        elif s:
            draw.line(px(s), fill=STROKE_COLOUR, width=width, joint="curve")
    if title:
        draw.text((6, 6), title, fill=(60, 60, 60))
    return image
