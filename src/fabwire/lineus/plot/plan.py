"""From a drawing (SVG, G-code, text) to a plan: strokes in machine units, placed in the reachable area and
ordered, with the typed move stream a client sends and the figures (length, travel, lifts, time) it will cost."""

from __future__ import annotations

import functools
import hashlib
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from fabwire.errors import InputError
from fabwire.lineus.kinematics import HOME, UNITS_PER_MM, MotionModel, body_detour
from fabwire.lineus.plot.fit import check_placed, fit_into_area, fit_scale, largest_box
from fabwire.lineus.plot.geometry import (
    FloatArray,
    Polylines,
    affine,
    bbox,
    compose,
    flatten,
    inner_segments,
    rotation,
    scale_translate,
)
from fabwire.lineus.plot.intake import FLATTEN_TOLERANCE, Drawing, read_drawing
from fabwire.lineus.plot.intake import PAGE_ORIGIN as PAGE_ORIGIN
from fabwire.lineus.plot.intake import SVG_UNITS_PER_PX as SVG_UNITS_PER_PX
from fabwire.lineus.plot.optimize import RESOLUTION, optimise, work_budget
from fabwire.lineus.plot.text import DEFAULT_FONT, text_lines


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
            "estimated_s": round(self.estimated_seconds, 2),
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
    hidden: tuple[FloatArray, ...] = ()
    """Lines of the drawing that clip paths hide, placed like the strokes (for previews; never drawn)."""

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
        seconds: list[float] = self._measured[1].tolist()
        return seconds

    def figures(self) -> PlanFigures:
        return self._measured[0]

    @functools.cached_property
    def _measured(self) -> tuple[PlanFigures, FloatArray]:
        """The figures and each stroke's seconds, from one pass over all points at once: the motion model's step
        counts over every segment and hop."""
        m = self.motion
        if not self.strokes:
            return PlanFigures(0, 0, 0.0, 0.0, 0, 0.0), np.zeros(0)
        points, offsets = flatten(self.strokes)
        starts, ends = points[offsets[:-1]], points[offsets[1:] - 1]
        here = np.vstack([np.asarray(self.origin, dtype=float), ends[:-1]])
        hop = starts - here
        inner = inner_segments(offsets)
        step = np.diff(points, axis=0)
        drawn = _steps(_longer_axis(step), m.draw_step) * inner
        per_stroke = np.add.reduceat(np.append(drawn, 0.0), offsets[:-1])
        sizes = offsets[1:] - offsets[:-1]
        per_stroke[sizes < 2] = 0.0  # a dot has no segment of its own (reduceat hands it the next one)
        segments = sizes - 1
        # Travel (one command), drop and lift (one command and a pen move each), one command per segment.
        hops = _steps(_longer_axis(hop), m.travel_step)
        seconds = (hops + per_stroke) * m.step_time + (3 + segments) * m.command_time + 2 * m.pen_time
        figures = PlanFigures(
            strokes=len(self.strokes),
            segments=int(segments.sum()),
            pen_down_length=float(np.hypot(step[inner, 0], step[inner, 1]).sum()),
            pen_up_travel=float(np.hypot(hop[:, 0], hop[:, 1]).sum()),
            pen_lifts=len(self.strokes),
            estimated_seconds=float(seconds.sum()),
        )
        return figures, seconds


def _longer_axis(moves: FloatArray) -> FloatArray:
    """Each (dx, dy) move's span on its longer axis (column by column: many times faster than along axis 1)."""
    span: FloatArray = np.maximum(np.abs(moves[:, 0]), np.abs(moves[:, 1]))
    return span


def _steps(span: FloatArray, step: float) -> FloatArray:
    """The firmware's interpolation steps for moves spanning `span` units on their longer axis."""
    n: FloatArray = np.where(span > 0, np.ceil(span / step - 1e-9), 0.0)
    return n


@dataclass(frozen=True, slots=True)
class PlanOptions:
    fit: bool | None = None
    """Scale into the area; None = yes for SVG and text, no for G-code (already in machine units)."""
    margin_mm: float = 2.0
    rotate_deg: float = 0.0
    rotate_auto: bool = False
    """Turn by 0 or 90 degrees, whichever lets the drawing be larger (overrides `rotate_deg`)."""
    full_area: bool = False
    """Fit into the whole reachable area instead of the official app's drawing area."""
    optimize: bool = True
    clip: bool = False
    """Without fitting: cut away what lies outside the area instead of refusing the drawing."""
    time_budget: float | None = 1.0
    """Work the ordering may spend improving on greedy, in nominal CPU seconds (counted in lines examined, never
    read from a clock: the same drawing and options give the same plan on any machine), or None for work in
    proportion to the number of lines (see `optimize.work_budget`)."""
    resolution: float = RESOLUTION
    motion: MotionModel = field(default_factory=MotionModel)
    svg_text: str = "hershey"
    """SVG `<text>`: 'hershey' draws it in single-stroke letters, 'outline' leaves it out with a note."""

    def __post_init__(self) -> None:
        if self.time_budget is not None:
            work_budget(self.time_budget, 0)  # refuses a budget out of range (nan included) when it is given


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
    """Read a drawing (see `read_drawing`) into polylines in machine orientation; returns (lines, kind, notes)."""
    drawing = read_drawing(path)
    return drawing.lines, drawing.kind, list(drawing.notes)


def _rotation_about_centre(polys: Polylines, degrees: float) -> FloatArray:
    x0, y0, x1, y1 = bbox(polys)
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    return compose(scale_translate(1.0, cx, cy), compose(rotation(degrees), scale_translate(1.0, -cx, -cy)))


def auto_rotation(polys: Polylines, options: PlanOptions) -> float:
    """0 or 90 degrees: whichever lets the drawing be fitted larger into the area (0 on a tie)."""
    margin = options.margin_mm * UNITS_PER_MM
    upright, _ = fit_scale(polys, margin=margin, full=options.full_area)
    turned, _ = fit_scale(affine(polys, _rotation_about_centre(polys, 90.0)), margin=margin, full=options.full_area)
    return 90.0 if turned > upright * 1.001 else 0.0


def rotation_of(polys: Polylines, options: PlanOptions) -> float:
    """The degrees `options` ask for: their own, or 0/90 chosen by `auto_rotation`."""
    return auto_rotation(polys, options) if options.rotate_auto else options.rotate_deg


def _identity() -> FloatArray:
    return scale_translate(1.0, 0.0, 0.0)


def plan_lines(
    lines: Sequence[FloatArray], options: PlanOptions = PlanOptions(), *, fit_default: bool = True,
    notes: Sequence[str] = (), hidden: Sequence[FloatArray] = ()
) -> Plan:
    """Place (rotate, then fit or check), optimise and wrap polylines already in machine orientation.

    `hidden` lines (cut away by clip paths) are placed the same way and kept in the plan for previews.
    """
    polys = [np.asarray(line, dtype=float).reshape(-1, 2) for line in lines if len(line)]
    if not polys:
        raise InputError("the drawing is empty (nothing for the pen to draw)")
    _check_finite(polys, "the drawing")
    if options.margin_mm < 0:
        raise InputError(f"the margin must not be negative, got {options.margin_mm:g} mm")
    fit = fit_default if options.fit is None else options.fit
    degrees = rotation_of(polys, options)
    matrix = _identity()
    if degrees % 360:
        matrix = _rotation_about_centre(polys, degrees)
        polys = affine(polys, matrix)
    clipped = 0.0
    scale = 1.0
    if fit:
        polys, placement = fit_into_area(polys, margin=options.margin_mm * UNITS_PER_MM, full=options.full_area)
        scale = placement.scale
        matrix = compose(placement.matrix, matrix)
    else:
        polys, clipped = check_placed(polys, clip=options.clip)
        if not polys:
            raise InputError("nothing of the drawing lies inside the reachable area")
    if options.optimize:
        polys = optimise(polys, resolution=options.resolution, time_budget=options.time_budget)
    extra = list(notes)
    if clipped:
        extra.append(f"clipped {clipped / UNITS_PER_MM:.1f} mm of lines outside the reachable area")
    return Plan(tuple(polys), motion=options.motion, scale=scale, clipped=clipped, notes=tuple(extra),
                hidden=tuple(affine(list(hidden), matrix)))


def _check_finite(polys: Sequence[FloatArray], what: str) -> None:
    if polys and not bool(np.isfinite(np.concatenate(polys)).all()):
        raise InputError(f"{what} has coordinates that are not finite numbers (beyond any page)")


def plan_drawing(drawing: Drawing, options: PlanOptions = PlanOptions()) -> Plan:
    """Plan a drawing read by `read_drawing`. A fitted SVG's curves are flattened again when fitting enlarges
    them, so the chord error on paper stays within FLATTEN_TOLERANCE whatever the page size and scale."""
    _check_finite(drawing.lines, f"{drawing.name}: the drawing")
    fit = options.fit if options.fit is not None else drawing.kind == "svg"
    if fit and drawing.curved:
        polys = drawing.lines
        if options.rotate_auto or options.rotate_deg % 360:
            degrees = rotation_of(polys, options)
            polys = affine(polys, _rotation_about_centre(polys, degrees))
        scale, _ = fit_scale(polys, margin=options.margin_mm * UNITS_PER_MM, full=options.full_area)
        if drawing.tolerance * scale > FLATTEN_TOLERANCE * 1.001:
            drawing = drawing.reflattened(FLATTEN_TOLERANCE / scale)
    return plan_lines(drawing.lines, options, fit_default=(drawing.kind == "svg"), notes=drawing.notes,
                      hidden=drawing.hidden)


def plan_file(path: str | Path, options: PlanOptions = PlanOptions()) -> Plan:
    """Plan an SVG, SVGZ or Line-us G-code drawing from a file, or from standard input for '-'."""
    return plan_drawing(read_drawing(path, svg_text=options.svg_text), options)


LEGIBLE_CAP_MM = 2.0
"""Capital height below which fitted text is called illegible: letters a few pen-line widths tall."""
PEN_LINE_MM = 0.5


def plan_text(text: str, options: PlanOptions = PlanOptions(), *, size_mm: float | None = None,
              font: str = DEFAULT_FONT) -> Plan:
    """Plan text in a single-stroke font: `size_mm` tall capitals centred in the area, or fitted to it.

    The rotation is applied before the size is checked against the area; InputError names the largest size that
    fits when the text does not.
    """
    notes: list[str] = []
    if size_mm is None:
        plan = plan_lines(text_lines(text, font=font, notes=notes), options, fit_default=True, notes=notes)
        cap_mm = plan.scale / UNITS_PER_MM  # the letters were made 1 machine unit tall before fitting
        if cap_mm < LEGIBLE_CAP_MM:
            plan = replace(plan, notes=(*plan.notes, (
                f"the text fits the area only {cap_mm:.2g} mm tall, too small to read in a pen line about "
                f"{PEN_LINE_MM} mm wide: break it into lines with \\n, or shorten it")))
        return plan
    if not (math.isfinite(size_mm) and size_mm > 0):
        raise InputError(f"the text size must be a positive number of mm, got {size_mm:g}")
    lines = text_lines(text, font=font, cap_height=size_mm * UNITS_PER_MM, notes=notes)
    degrees = rotation_of(lines, options)
    if degrees % 360:
        lines = affine(lines, _rotation_about_centre(lines, degrees))
    x0, y0, x1, y1 = bbox(lines)
    w, h = x1 - x0, y1 - y0
    box = largest_box(round(max(w, 1e-3) / max(h, 1e-3), 4), options.margin_mm * UNITS_PER_MM, options.full_area)
    if w > box.width + 1e-6 or h > box.height + 1e-6:
        factor = max(w / box.width, h / box.height)
        turned = f" turned {degrees:g} degrees" if degrees % 360 else ""
        raise InputError(
            f"text {size_mm:g} mm tall{turned} is {w / UNITS_PER_MM:.0f} x {h / UNITS_PER_MM:.0f} mm and does not fit "
            f"the drawing area ({box.width / UNITS_PER_MM:.0f} x {box.height / UNITS_PER_MM:.0f} mm at this shape); "
            f"use --size {math.floor(size_mm / factor * 10) / 10:.1f} or less"
            + ("" if options.rotate_auto or degrees % 360 else ", or --rotate auto")
        )
    placed = affine(lines, scale_translate(1.0, box.cx - (x0 + x1) / 2, box.cy - (y0 + y1) / 2))
    unfit = replace(options, fit=False, rotate_deg=0.0, rotate_auto=False, clip=False)
    return plan_lines(placed, unfit, fit_default=False, notes=notes)
