"""A vpype document as Line-us drawing passes: page pixels ↔ machine units, fitting every layer with one
transform, and one plan per layer.

vpype stores each line as a complex numpy array in CSS pixels (x + iy, y down); its layers are numbered and may
carry a name in the `vp_name` property (vpype's documented metadata). fabwire's planner works in Line-us machine
units (x away from the base, y up).
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fabwire.errors import InputError
from fabwire.lineus.kinematics import APP_AREA, UNITS_PER_MM
from fabwire.lineus.plot import Plan, PlanFigures, PlanOptions, plan_lines
from fabwire.lineus.plot.export import gcode_lines
from fabwire.lineus.plot.fit import fit_placement
from fabwire.lineus.plot.geometry import FloatArray, Polylines, compose, split_at
from fabwire.lineus.plot.intake import PAGE_ORIGIN, SVG_UNITS_PER_PX

LAYER_NAME = "vp_name"
"""vpype's layer-name property."""


def to_machine(line: Any) -> FloatArray:
    """A vpype line (complex array, pixels, y down) → (n, 2) machine units on the Line-us page."""
    z = np.asarray(line, dtype=complex).reshape(-1)
    return np.column_stack([PAGE_ORIGIN[0] + z.real * SVG_UNITS_PER_PX, PAGE_ORIGIN[1] - z.imag * SVG_UNITS_PER_PX])


def to_page(points: FloatArray) -> Any:
    """(n, 2) machine units → a vpype line (complex array, pixels, y down); the inverse of `to_machine`."""
    x = (points[:, 0] - PAGE_ORIGIN[0]) / SVG_UNITS_PER_PX
    y = (PAGE_ORIGIN[1] - points[:, 1]) / SVG_UNITS_PER_PX
    return x + 1j * y


APP_PAGE = ((APP_AREA[2] - APP_AREA[0]) / SVG_UNITS_PER_PX, (APP_AREA[3] - APP_AREA[1]) / SVG_UNITS_PER_PX)
"""The official app's drawing area as a page (width, height) in pixels: its top-left corner is the page origin."""


@dataclass(frozen=True)
class Pass:
    """One vpype layer: what one pen draws."""

    layer_id: int
    name: str | None
    lines: Polylines
    """Machine units, in the layer's order."""

    @property
    def label(self) -> str:
        return f"layer {self.layer_id}" + (f" ({self.name})" if self.name else "")


def document_passes(document: Any, layer_ids: Iterable[int] | None = None) -> list[Pass]:
    """The document's non-empty layers (all, or those in `layer_ids`) in layer-number order."""
    wanted = None if layer_ids is None else set(layer_ids)
    passes = []
    for layer_id in sorted(document.layers):
        if wanted is not None and layer_id not in wanted:
            continue
        layer = document.layers[layer_id]
        lines = [line for line in layer if len(line)]
        if lines:
            offsets = np.zeros(len(lines) + 1, dtype=np.int64)
            np.cumsum(np.fromiter((len(line) for line in lines), dtype=np.int64, count=len(lines)), out=offsets[1:])
            placed = to_machine(np.concatenate(lines))  # one conversion for the whole layer, then split (views)
            name = layer.property(LAYER_NAME)
            passes.append(Pass(layer_id, str(name) if name else None, split_at(placed, offsets)))
    return passes


PAGE_TO_MACHINE = np.array([[SVG_UNITS_PER_PX, 0.0, PAGE_ORIGIN[0]], [0.0, -SVG_UNITS_PER_PX, PAGE_ORIGIN[1]]])
MACHINE_TO_PAGE = np.array([[1 / SVG_UNITS_PER_PX, 0.0, -PAGE_ORIGIN[0] / SVG_UNITS_PER_PX],
                            [0.0, -1 / SVG_UNITS_PER_PX, PAGE_ORIGIN[1] / SVG_UNITS_PER_PX]])
"""`to_machine` and `to_page` as 2x3 matrices."""


def fit_document(document: Any, options: PlanOptions) -> Any:
    """Place every layer with one transform (scaled into the area with `options.fit`, else checked or clipped
    as it is) and return the document with its lines replaced; layers keep their ids and properties, and the
    page becomes the app drawing area.

    Raises InputError for an empty document or, without fitting or clipping, for lines out of reach."""
    if options.fit:
        lines = [line for layer_id in sorted(document.layers) for line in document.layers[layer_id] if len(line)]
        if not lines:
            raise InputError("the document is empty (nothing for the pen to draw)")
        z = np.concatenate(lines)
        if not bool(np.isfinite(z).all()):
            raise InputError("the drawing has coordinates that are not finite numbers (beyond any page)")
        # The bounding box on the machine, where the fit is made; the placement is then a uniform scale and a
        # shift of the page, which vpype applies to every layer itself (in place, as its own `scale` does).
        x0, x1 = float(z.real.min()), float(z.real.max())
        y0, y1 = float(z.imag.min()), float(z.imag.max())
        corners = np.array([[x0, y1, 1.0], [x1, y0, 1.0]]) @ PAGE_TO_MACHINE.T
        extent = (float(corners[0, 0]), float(corners[0, 1]), float(corners[1, 0]), float(corners[1, 1]))
        placement = fit_placement(extent, margin=options.margin_mm * UNITS_PER_MM, full=options.full_area)
        page = compose(MACHINE_TO_PAGE, compose(placement.matrix, PAGE_TO_MACHINE))
        document.scale(float(page[0, 0]), float(page[1, 1]))
        document.translate(float(page[0, 2]), float(page[1, 2]))
        document.page_size = APP_PAGE
        return document
    passes = document_passes(document)
    if not passes:
        raise InputError("the document is empty (nothing for the pen to draw)")
    unordered = dataclasses.replace(options, optimize=False, time_budget=0.0)
    for one in passes:
        lines = list(plan_lines(one.lines, unordered, fit_default=False).strokes)
        layer = document.layers[one.layer_id]
        document.layers[one.layer_id] = layer.clone([to_page(line) for line in lines])
    document.page_size = APP_PAGE
    return document


@dataclass(frozen=True)
class PassPlan:
    """A layer and the plan that draws it (starting from home, where the arm parks for a pen change)."""

    layer: Pass
    plan: Plan


def plan_passes(passes: Sequence[Pass], options: PlanOptions) -> list[PassPlan]:
    """Check (or clip) each layer as placed and order its lines; raises InputError naming the layer at fault."""
    if not passes:
        raise InputError("the document is empty (nothing for the pen to draw)")
    unplaced = dataclasses.replace(options, fit=False, rotate_deg=0.0)
    out = []
    for one in passes:
        try:
            plan = plan_lines(one.lines, unplaced, fit_default=False)
        except InputError as exc:
            raise InputError(f"{one.label}: {exc} (in vpype: put lineus-fit before this command)") from None
        out.append(PassPlan(one, plan))
    return out


def total_figures(plans: Sequence[PassPlan]) -> PlanFigures:
    """The figures of all passes together (each pass starts from home)."""
    figures = [one.plan.figures() for one in plans]
    return PlanFigures(
        strokes=sum(f.strokes for f in figures),
        segments=sum(f.segments for f in figures),
        pen_down_length=sum(f.pen_down_length for f in figures),
        pen_up_travel=sum(f.pen_up_travel for f in figures),
        pen_lifts=sum(f.pen_lifts for f in figures),
        estimated_seconds=sum(f.estimated_seconds for f in figures),
    )


def passes_key(passes: Sequence[Pass], options: PlanOptions, extra: str = "") -> str:
    """A digest of the geometry (to 0.01 unit) and the options: names the resume state of exactly this drawing."""
    digest = hashlib.sha256()
    for one in passes:
        digest.update(f"layer {one.layer_id}|".encode())
        for line in one.lines:
            digest.update(np.round(line, 2).astype("<f8").tobytes())
            digest.update(b"|")
    digest.update(repr((options.clip, options.optimize, extra)).encode())
    return digest.hexdigest()


def plan_gcode(plans: Sequence[PassPlan], *, pen_z: float = 0.0) -> list[str]:
    """Line-us G-code for the passes one after another: G01 moves with Z1000 (pen up) and `pen_z` (pen down),
    as the Line-us app saves drawings; no pen-change stop (G-code has none the firmware honours)."""
    return gcode_lines(*(one.plan for one in plans), pen_z=pen_z)
