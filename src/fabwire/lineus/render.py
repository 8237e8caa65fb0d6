"""Pictures of a drawing in machine units: pen-down strokes, dashed pen-up travel, parts hidden by clip paths
(faint), the reachable area, the official app's drawing area, the machine's body and a scale bar.

The frame is the machine's: +X away from the body (rightwards), +Y up the sheet, so a preview shows what lands
on the paper. SVG is written as plain text; PNG goes through Pillow, drawn at three times the size and reduced,
which smooths (anti-aliases) every edge.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np
import numpy.typing as npt
from PIL import Image, ImageDraw, ImageFont

from fabwire.errors import InputError
from fabwire.lineus.kinematics import APP_AREA, BODY, BOUNDS, UNITS_PER_MM, area_outline

Polyline = Sequence[tuple[float, float]] | Sequence[Sequence[float]] | npt.NDArray[np.float64]
FloatArray = npt.NDArray[np.float64]

MARGIN = 60.0
"""Units of empty paper around the machine and its reachable area."""
DEFAULT_DPI = 150.0
PNG_SCALE = DEFAULT_DPI / 25.4 / UNITS_PER_MM
"""PNG pixels per machine unit at the default resolution."""
SUPERSAMPLE = 3
PEN_WIDTH = 10.0
"""Drawn line width, machine units (a fine-liner draws about 0.5 mm)."""
DASH = (30.0, 20.0)
"""Pen-up travel dash and gap, machine units."""
SCALE_BAR = 10.0 * UNITS_PER_MM
"""The scale bar's length (10 mm)."""
ROUND_JOINTS_UP_TO = 2_000
"""Vertices of a stroke up to which its joints are drawn round."""
LEGEND = "black: pen down · orange dashes: pen-up travel · grey lines: hidden by clip paths · grey block: Line-us body"

STROKE_COLOUR = (20, 20, 20)
TRAVEL_COLOUR = (230, 120, 60)
HIDDEN_COLOUR = (200, 200, 200)
AREA_COLOUR = (120, 170, 230)
APP_COLOUR = (60, 120, 200)
BODY_COLOUR = (150, 150, 150)
BACKGROUND = (255, 255, 255)


def dpi_scale(dpi: float) -> float:
    """PNG pixels per machine unit at `dpi` dots per inch of paper."""
    if not (math.isfinite(dpi) and 10 <= dpi <= 1200):
        raise InputError(f"the preview resolution must be 10 to 1200 dpi, got {dpi:g}")
    return dpi / 25.4 / UNITS_PER_MM


def frame() -> tuple[float, float, float, float]:
    """The drawn extent in machine units: (x_min, y_min, width, height)."""
    x0, y0 = min(BOUNDS[0], BODY[0]) - MARGIN, min(BOUNDS[1], BODY[1]) - MARGIN
    x1, y1 = max(BOUNDS[2], BODY[2]) + MARGIN, max(BOUNDS[3], BODY[3]) + MARGIN
    return (x0, y0, x1 - x0, y1 - y0)


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
    hidden: Iterable[Polyline] = (),
) -> Path:
    """Write the drawing to `path` as .svg or .png, chosen by the suffix; `scale` is PNG pixels per unit."""
    out = Path(path)
    suffix = out.suffix.lower()
    strokes_l = [_points(s) for s in strokes]
    travel_l = [_points(t) for t in travel or ()]
    hidden_l = [_points(h) for h in hidden]
    if suffix == ".svg":
        text = svg_text(strokes_l, travel_l, title=title, hidden=hidden_l)
        _write(out, lambda: out.write_text(text, encoding="utf-8"))
    elif suffix == ".png":
        image = _png_image(strokes_l, travel_l, hidden_l, title=title, scale=scale)
        _write(out, lambda: image.save(out, format="PNG"))
    else:
        raise InputError(f"{out}: {picture_suffix_problem(out)}")
    return out


PICTURE_SUFFIXES = (".svg", ".png")
"""The picture formats `write_drawing` writes, chosen by the file name's suffix."""


def picture_suffix_problem(out: Path, also: str = "") -> str:
    """Why `out` names no picture format: the formats, `also` (other outputs the caller accepts), and the suffix."""
    given = f"not {out.suffix!r}" if out.suffix else "and this name has no extension"
    return f"a picture file ends in .svg or .png{also}, {given}"


PICTURE_SIDE = 160
"""The longer side, in pixels, of the picture a file library shows beside a drawing."""


def picture_png(strokes: Iterable[Polyline], *, side: int = PICTURE_SIDE) -> tuple[bytes, tuple[int, int]]:
    """What the pen draws, alone (no arm, area or legend: a thumbnail shows the drawing), fitted to `side` pixels
    on its longer side, as PNG bytes and their (width, height) in pixels."""
    lines = [_points(s) for s in strokes]
    drawn = [line for line in lines if len(line)]
    if not drawn:
        image = Image.new("RGB", (side, side), BACKGROUND)
    else:
        low = np.min([line.min(axis=0) for line in drawn], axis=0)
        high = np.max([line.max(axis=0) for line in drawn], axis=0)
        span = np.maximum(high - low, 1.0)
        margin = 0.05 * float(span.max())
        scale = (side - 1) / (float(span.max()) + 2 * margin)
        size = (max(1, round((float(span[0]) + 2 * margin) * scale)), max(1, round((float(span[1]) + 2 * margin)
                                                                                  * scale)))
        big = SUPERSAMPLE
        image = Image.new("RGB", (size[0] * big, size[1] * big), BACKGROUND)
        draw = ImageDraw.Draw(image)
        pen = max(1, round(1.5 * big))
        for line in drawn:  # the arm's y grows upward on the paper, a picture's downward
            xy = np.column_stack([(line[:, 0] - low[0] + margin) * scale * big,
                                  (high[1] + margin - line[:, 1]) * scale * big])
            if len(xy) == 1:
                (cx, cy), r = xy[0], pen
                draw.ellipse((cx - r, cy - r, cx + r, cy + r), fill=STROKE_COLOUR)
                continue
            for start in range(0, len(xy) - 1, 10_000):  # long strokes in pieces: bounded memory
                draw.line(xy[start:start + 10_001].ravel().tolist(), fill=STROKE_COLOUR, width=pen)
        image = image.resize(size, Image.Resampling.BOX)
    out = io.BytesIO()
    image.save(out, format="PNG")
    return out.getvalue(), image.size


def _points(line: Polyline) -> FloatArray:
    return np.asarray(line, dtype=float).reshape(-1, 2)


def _write(out: Path, save: Callable[[], object]) -> None:
    try:
        save()
    except OSError as exc:
        raise InputError(f"cannot write {out}: {exc.strerror or exc}") from exc


def dashes(line: FloatArray, dash: float = DASH[0], gap: float = DASH[1]) -> list[FloatArray]:
    """The dash pieces (two-point lines) of a polyline, restarting the pattern at each vertex."""
    if len(line) < 2:
        return []
    a, b = line[:-1], line[1:]
    lengths = np.hypot(*(b - a).T)
    n = np.ceil(lengths / (dash + gap)).astype(np.int64)
    seg = np.repeat(np.arange(len(a)), n)
    k = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
    with np.errstate(invalid="ignore", divide="ignore"):
        t0 = np.clip(k * (dash + gap) / lengths[seg], 0, 1)
        t1 = np.clip((k * (dash + gap) + dash) / lengths[seg], 0, 1)
    d = b[seg] - a[seg]
    p0 = a[seg] + d * t0[:, None]
    p1 = a[seg] + d * t1[:, None]
    return [np.vstack([p, q]) for p, q in zip(p0, p1, strict=True)]


def _rect(box: tuple[float, float, float, float]) -> FloatArray:
    x0, y0, x1, y1 = box
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]])


def _svg_points(line: FloatArray) -> str:
    return " ".join(f"{x:.1f},{-y:.1f}" for x, y in line.tolist())


def svg_text(strokes: Sequence[Polyline], travel: Sequence[Polyline] = (), *, title: str | None = None,
             hidden: Sequence[Polyline] = ()) -> str:
    """The drawing as an SVG document whose user units are machine units (Y flipped so +Y is up)."""
    fx, fy, fw, fh = frame()
    top = -(fy + fh)
    rgb = "rgb({},{},{})".format
    parts = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{fw / UNITS_PER_MM:.1f}mm" '
        f'height="{fh / UNITS_PER_MM:.1f}mm" viewBox="{fx:.1f} {top:.1f} {fw:.1f} {fh:.1f}">',
    ]
    if title:
        parts.append(f"<title>{escape(title)}</title>")
    parts.append(f'<rect x="{fx:.1f}" y="{top:.1f}" width="{fw:.1f}" height="{fh:.1f}" fill="white"/>')
    parts.append(f'<polygon id="reachable-area" points="{_svg_points(np.array(area_outline()))}" '
                 f'fill="{rgb(*AREA_COLOUR)}" fill-opacity="0.12" stroke="{rgb(*AREA_COLOUR)}" stroke-width="4"/>')
    parts.append(f'<polyline id="app-area" points="{_svg_points(_rect(APP_AREA))}" fill="none" '
                 f'stroke="{rgb(*APP_COLOUR)}" stroke-width="3" stroke-dasharray="40 15"/>')
    parts.append(f'<polygon id="body" points="{_svg_points(_rect(BODY)[:-1])}" fill="{rgb(*BODY_COLOUR)}" '
                 'fill-opacity="0.3" stroke="' + rgb(*BODY_COLOUR) + '" stroke-width="4"/>')
    if hidden:
        parts.append(f'<g id="hidden" fill="none" stroke="{rgb(*HIDDEN_COLOUR)}" stroke-width="3">')
        parts.extend(f'<polyline points="{_svg_points(_points(h))}"/>' for h in hidden if len(h) >= 2)
        parts.append("</g>")
    if travel:
        parts.append(f'<g id="travel" fill="none" stroke="{rgb(*TRAVEL_COLOUR)}" stroke-width="3" '
                     f'stroke-dasharray="{DASH[0]:g} {DASH[1]:g}">')
        parts.extend(f'<polyline points="{_svg_points(_points(t))}"/>' for t in travel if len(t) >= 2)
        parts.append("</g>")
    parts.append(f'<g id="strokes" fill="none" stroke="{rgb(*STROKE_COLOUR)}" stroke-width="{PEN_WIDTH:g}" '
                 'stroke-linecap="round" stroke-linejoin="round">')
    for s in strokes:
        pts = _points(s)
        if len(pts) == 1:
            parts.append(f'<circle cx="{pts[0, 0]:.1f}" cy="{-pts[0, 1]:.1f}" r="{PEN_WIDTH / 2:g}"/>')
        elif len(pts):
            parts.append(f'<polyline points="{_svg_points(pts)}"/>')
    parts.append("</g>")
    bx, by = fx + 40, fy + 40
    parts.append(f'<g id="scale-bar"><rect x="{bx:.1f}" y="{-(by + 8):.1f}" width="{SCALE_BAR:g}" height="8" '
                 f'fill="black"/><text x="{bx:.1f}" y="{-(by + 20):.1f}" font-family="sans-serif" '
                 f'font-size="40">{SCALE_BAR / UNITS_PER_MM:g} mm</text></g>')
    parts.append(f'<text x="{fx + 20:.1f}" y="{top + fh - 12:.1f}" font-family="sans-serif" font-size="32">'
                 f"{escape(LEGEND)}</text>")
    if title:
        parts.append(f'<text x="{fx + 20:.1f}" y="{top + 60:.1f}" font-family="sans-serif" '
                     f'font-size="44">{escape(title)}</text>')
    parts.append("</svg>")
    return "\n".join(parts) + "\n"


def _font(size: int) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    try:
        return ImageFont.load_default(size=size)
    except (TypeError, OSError):  # Pillow without FreeType: the fixed bitmap font
        return ImageFont.load_default()


def _wrapped(draw: ImageDraw.ImageDraw, font: ImageFont.ImageFont | ImageFont.FreeTypeFont, room: float
             ) -> list[str]:
    """The legend's items (` · ` apart) on lines no wider than `room` px where they fit."""
    lines: list[str] = []
    for item in LEGEND.split(" · "):
        joined = f"{lines[-1]} · {item}" if lines else item
        if lines and draw.textlength(joined, font=font) <= room:
            lines[-1] = joined
        else:
            lines.append(item)
    return lines


def _png_image(strokes: Sequence[FloatArray], travel: Sequence[FloatArray], hidden: Sequence[FloatArray], *,
               title: str | None, scale: float) -> Image.Image:
    fx, fy, _, fh = frame()
    size = png_size(scale)
    big = scale * SUPERSAMPLE
    image = Image.new("RGB", (size[0] * SUPERSAMPLE, size[1] * SUPERSAMPLE), BACKGROUND)
    draw = ImageDraw.Draw(image)

    def px(line: FloatArray) -> list[float]:
        out: list[float] = np.column_stack([(line[:, 0] - fx) * big, (fy + fh - line[:, 1]) * big]).ravel().tolist()
        return out

    def width(units: float) -> int:
        return max(1, round(units * big))

    draw.polygon(px(np.array(area_outline())), fill=(235, 242, 250), outline=AREA_COLOUR, width=width(4))
    for piece in dashes(_rect(APP_AREA), 40.0, 15.0):
        draw.line(px(piece), fill=APP_COLOUR, width=width(3))
    draw.polygon(px(_rect(BODY)[:-1]), fill=(225, 225, 225), outline=BODY_COLOUR, width=width(4))
    for h in hidden:
        if len(h) >= 2:
            draw.line(px(h), fill=HIDDEN_COLOUR, width=width(3))
    for t in travel:
        for piece in dashes(t):
            draw.line(px(piece), fill=TRAVEL_COLOUR, width=width(3))
    pen = width(PEN_WIDTH)
    for s in strokes:
        if len(s) == 1:
            (cx, cy), r = px(s)[:2], pen / 2
            draw.ellipse((cx - r, cy - r, cx + r, cy + r), fill=STROKE_COLOUR)
        # Rounded joints cost a disc per vertex: worth it for ordinary strokes, not for one of 100,000 points.
        joint = "curve" if len(s) <= ROUND_JOINTS_UP_TO else None
        for start in range(0, max(0, len(s) - 1), 10_000):  # long strokes in pieces: bounded memory
            draw.line(px(s[start : start + 10_001]), fill=STROKE_COLOUR, width=pen, joint=joint)
    image = image.resize(size, Image.Resampling.BOX)  # area average: smooth edges, no ringing
    draw = ImageDraw.Draw(image)
    text_px = max(9, round(size[0] / 60))
    font = _font(text_px)
    bx = 12
    room = size[0] - 2 * bx
    legend = _wrapped(draw, font, room)
    by = size[1] - (len(legend) + 1) * (text_px + 4) - 8  # the scale bar above the legend's lines
    draw.rectangle((bx, by, bx + SCALE_BAR * scale, by + max(2, text_px // 4)), fill=(0, 0, 0))
    draw.text((bx, by - text_px - 4), f"{SCALE_BAR / UNITS_PER_MM:g} mm", fill=(0, 0, 0), font=font)
    for row, words in enumerate(reversed(legend)):  # on as many lines as the picture's width needs
        draw.text((bx, size[1] - (row + 1) * (text_px + 4) - 4), words, fill=(60, 60, 60), font=font)
    if title:
        draw.text((8, 6), title, fill=(60, 60, 60), font=font)
    return image
