"""From a drawing (SVG, G-code, text) to a plan: strokes in machine units, placed in the reachable area and
ordered, with the typed move stream a client sends and the figures (length, travel, lifts, time) it will cost."""

from __future__ import annotations

import hashlib
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fabwire.errors import InputError
from fabwire.lineus.kinematics import HOME, UNITS_PER_MM, MotionModel, body_detour
from fabwire.lineus.plot.fit import check_placed, fit_into_area, largest_box
from fabwire.lineus.plot.gcode import parse_gcode
from fabwire.lineus.plot.geometry import (
    FloatArray,
    Polylines,
    affine,
    bbox,
    compose,
    drawn_length,
    rotation,
    scale_translate,
    segment_count,
)
from fabwire.lineus.plot.optimize import RESOLUTION, optimise, travel_length
from fabwire.lineus.plot.svg import parse_svg
from fabwire.lineus.plot.text import DEFAULT_FONT, text_lines

SVG_UNITS_PER_PX = 25.4 / 96 * UNITS_PER_MM
"""Machine units per SVG user unit (CSS pixel, 96 per inch)."""
PAGE_ORIGIN = (650.0, 1000.0)
"""Unfitted SVG pages sit with their top-left corner here: the corner of the app drawing area."""


@dataclass(frozen=True, slots=True)
class PenUp:
    """Lift the pen where it is."""


@dataclass(frozen=True, slots=True)
class PenDown:
    """Lower the pen where it is."""


@dataclass(frozen=True, slots=True)
class MoveTo:
    """Straight move to (x, y) in machine units, pen as it is."""

    x: float
    y: float


Move = PenUp | PenDown | MoveTo


@dataclass(frozen=True, slots=True)
class PlanFigures:
    strokes: int
    segments: int
    pen_down_length: float
    """Machine units."""
    pen_up_travel: float
    """Machine units, from the starting point through every stroke."""
    pen_lifts: int
    estimated_seconds: float

    def as_dict(self) -> dict[str, Any]:
        return {
            "strokes": self.strokes,
            "segments": self.segments,
            "pen_down_length_mm": round(self.pen_down_length / UNITS_PER_MM, 2),
            "pen_up_travel_mm": round(self.pen_up_travel / UNITS_PER_MM, 2),
            "pen_lifts": self.pen_lifts,
            "estimated_seconds": round(self.estimated_seconds, 2),
        }


@dataclass(frozen=True)
class Plan:
    """Strokes in drawing order (machine units) and how they were derived."""

    strokes: tuple[FloatArray, ...]
    origin: tuple[float, float] = HOME
    motion: MotionModel = field(default_factory=MotionModel)
    scale: float = 1.0
    """Machine units per input unit after placement."""
    clipped: float = 0.0
    """Pen-down length (machine units) left out because it lay outside the area."""
    notes: tuple[str, ...] = ()

    def moves(self, start: int = 0) -> Iterator[Move]:
        """The move stream from stroke `start` on: travel with the pen up, drop, draw, lift."""
        for index in range(start, len(self.strokes)):
            yield from self.stroke_moves(index)

    def stroke_moves(self, index: int, *, from_point: int = 0, here: tuple[float, float] | None = None
                     ) -> list[Move]:
        """The moves of one stroke from its vertex `from_point` on, the pen-up travel to it included (from `here`,
        by default the end of the stroke before). A hop that would cut the body notch goes round its corner:
        firmware 1.0.1 does not keep the arm out of it."""
        stroke = self.strokes[index]
        if here is None:
            here = self.origin if index == 0 else (float(self.strokes[index - 1][-1, 0]),
                                                    float(self.strokes[index - 1][-1, 1]))
        first = (float(stroke[from_point, 0]), float(stroke[from_point, 1]))
        out: list[Move] = [MoveTo(x, y) for x, y in body_detour(here, first)]
        out.append(PenDown())
        out.extend(MoveTo(x, y) for x, y in stroke[from_point + 1 :].tolist())
        out.append(PenUp())
        return out

    def travel(self) -> list[FloatArray]:
        """The pen-up hops as two-point polylines, from the starting point on."""
        hops: list[FloatArray] = []
        here = np.asarray(self.origin, dtype=float)
        for stroke in self.strokes:
            if not np.array_equal(here, stroke[0]):
                hops.append(np.vstack([here, stroke[0]]))
            here = stroke[-1]
        return hops

    def stroke_seconds(self) -> list[float]:
        """Estimated time of each stroke, including the travel to it and its pen drop and lift."""
        m = self.motion
        out: list[float] = []
        here = self.origin
        for stroke in self.strokes:
            start = (float(stroke[0, 0]), float(stroke[0, 1]))
            t = m.move_time((*here, 1000.0), (*start, 1000.0))
            t += m.move_time((*start, 1000.0), (*start, 0.0))
            t += m.polyline_time(stroke, pen_down=True)
            end = (float(stroke[-1, 0]), float(stroke[-1, 1]))
            t += m.move_time((*end, 0.0), (*end, 1000.0))
            out.append(t)
            here = end
        return out

    def figures(self) -> PlanFigures:
        strokes = list(self.strokes)
        return PlanFigures(
            strokes=len(strokes),
            segments=segment_count(strokes),
            pen_down_length=drawn_length(strokes),
            pen_up_travel=travel_length(strokes, self.origin),
            pen_lifts=len(strokes),
            estimated_seconds=sum(self.stroke_seconds()),
        )


@dataclass(frozen=True, slots=True)
class PlanOptions:
    fit: bool | None = None
    """Scale into the area; None = yes for SVG and text, no for G-code (already in machine units)."""
    margin_mm: float = 2.0
    rotate_deg: float = 0.0
    optimize: bool = True
    clip: bool = False
    """Without fitting: cut away what lies outside the area instead of refusing the drawing."""
    time_budget: float = 1.0
    """Seconds the ordering may spend improving on greedy."""
    resolution: float = RESOLUTION
    motion: MotionModel = field(default_factory=MotionModel)


def file_digest(path: str | Path) -> str:
    """SHA-256 of a file's bytes (keys resume state to exactly this drawing)."""
    digest = hashlib.sha256()
    try:
        with Path(path).open("rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 16), b""):
                digest.update(chunk)
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    return digest.hexdigest()


def load_drawing(path: str | Path) -> tuple[Polylines, str, list[str]]:
    """Read .svg or .gcode into polylines in machine orientation (y up); returns (lines, kind, notes).

    SVG comes out at real size (96 user units per inch) with its page's top-left corner at the app drawing
    area's corner (650, 1000); G-code is already in machine units.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    notes: list[str] = []
    if suffix in (".svg", ".svgz"):
        drawing = parse_svg(p)
        for tag, count in sorted(drawing.skipped.items()):
            notes.append(f"skipped {count} {tag} element(s): convert them to paths to draw them")
        m = scale_translate(SVG_UNITS_PER_PX, PAGE_ORIGIN[0], PAGE_ORIGIN[1], flip_y=True)
        lines = affine(drawing.lines, m)
        kind = "svg"
    elif suffix in (".gcode", ".gc", ".nc", ".txt", ".ngc", ".g"):
        lines = parse_gcode(p, notes=notes)
        kind = "gcode"
    else:
        raise InputError(f"{p}: unknown drawing type {p.suffix or '(none)'!r}; give an .svg or .gcode file")
    if not lines:
        why = f" ({'; '.join(notes)})" if notes else ""
        raise InputError(f"{p}: the drawing is empty (nothing for the pen to draw){why}")
    return lines, kind, notes


def plan_lines(
    lines: Sequence[FloatArray], options: PlanOptions = PlanOptions(), *, fit_default: bool = True,
    notes: Sequence[str] = ()
) -> Plan:
    """Place (fit or check), optimise and wrap polylines already in machine orientation."""
    polys = [np.asarray(line, dtype=float).reshape(-1, 2) for line in lines if len(line)]
    if not polys:
        raise InputError("the drawing is empty (nothing for the pen to draw)")
    if not all(bool(np.isfinite(p).all()) for p in polys):
        raise InputError("the drawing has coordinates that are not finite numbers")
    if options.margin_mm < 0:
        raise InputError(f"the margin must not be negative, got {options.margin_mm:g} mm")
    fit = fit_default if options.fit is None else options.fit
    if options.rotate_deg % 360:
        x0, y0, x1, y1 = bbox(polys)
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        m = compose(scale_translate(1.0, cx, cy), compose(rotation(options.rotate_deg),
                                                          scale_translate(1.0, -cx, -cy)))
        polys = affine(polys, m)
    clipped = 0.0
    scale = 1.0
    if fit:
        polys, placement = fit_into_area(polys, margin=options.margin_mm * UNITS_PER_MM)
        scale = placement.scale
    else:
        polys, clipped = check_placed(polys, clip=options.clip)
        if not polys:
            raise InputError("nothing of the drawing lies inside the reachable area")
    if options.optimize:
        polys = optimise(polys, resolution=options.resolution, time_budget=options.time_budget)
    extra = list(notes)
    if clipped:
        extra.append(f"clipped {clipped / UNITS_PER_MM:.1f} mm of lines outside the reachable area")
    return Plan(tuple(polys), motion=options.motion, scale=scale, clipped=clipped, notes=tuple(extra))


def plan_file(path: str | Path, options: PlanOptions = PlanOptions()) -> Plan:
    """Plan an .svg or .gcode drawing."""
    lines, kind, notes = load_drawing(path)
    return plan_lines(lines, options, fit_default=(kind == "svg"), notes=notes)


def plan_text(text: str, options: PlanOptions = PlanOptions(), *, size_mm: float | None = None,
              font: str = DEFAULT_FONT) -> Plan:
    """Plan text in a single-stroke font: `size_mm` tall capitals centred in the area, or fitted to it."""
    if size_mm is None:
        return plan_lines(text_lines(text, font=font), options, fit_default=True)
    if not (math.isfinite(size_mm) and size_mm > 0):
        raise InputError(f"the text size must be a positive number of mm, got {size_mm:g}")
    lines = text_lines(text, font=font, cap_height=size_mm * UNITS_PER_MM)
    x0, y0, x1, y1 = bbox(lines)
    w, h = x1 - x0, y1 - y0
    box = largest_box(round(max(w, 1e-3) / max(h, 1e-3), 4), options.margin_mm * UNITS_PER_MM)
    if w > box.width + 1e-6 or h > box.height + 1e-6:
        factor = max(w / box.width, h / box.height)
        raise InputError(
            f"text {size_mm:g} mm tall is {w / UNITS_PER_MM:.0f} x {h / UNITS_PER_MM:.0f} mm and does not fit the "
            f"drawing area ({box.width / UNITS_PER_MM:.0f} x {box.height / UNITS_PER_MM:.0f} mm at this shape); "
            f"use --size {size_mm / factor:.1f} or less"
        )
    placed = affine(lines, scale_translate(1.0, box.cx - (x0 + x1) / 2, box.cy - (y0 + y1) / 2))
    unfit = PlanOptions(fit=False, margin_mm=options.margin_mm, rotate_deg=options.rotate_deg,
                        optimize=options.optimize, clip=False, time_budget=options.time_budget,
                        resolution=options.resolution, motion=options.motion)
    return plan_lines(placed, unfit, fit_default=False)
