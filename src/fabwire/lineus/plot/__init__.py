"""The Line-us drawing pipeline: SVG, G-code and single-stroke text → polylines → placed in the drawing
area → ordered for least pen-up travel → a typed move stream with time and length figures.

Public entry points: `read_drawing` (file or '-' → Drawing), `plan_drawing` / `plan_file` / `plan_lines` /
`plan_text` (→ Plan), `Plan.figures()` (length, travel, time estimate)."""

from fabwire.lineus.plot.gcode import parse_gcode, parse_gcode_text
from fabwire.lineus.plot.intake import Drawing, read_drawing
from fabwire.lineus.plot.optimize import drop_fine_points, greedy_order, improve, join_touching, optimise
from fabwire.lineus.plot.plan import (
    Move,
    MoveTo,
    PenDown,
    PenUp,
    Plan,
    PlanFigures,
    PlanOptions,
    auto_rotation,
    file_digest,
    load_drawing,
    plan_drawing,
    plan_file,
    plan_lines,
    plan_text,
)
from fabwire.lineus.plot.svg import parse_svg
from fabwire.lineus.plot.text import font_names, text_lines

__all__ = [
    "Drawing",
    "Move",
    "MoveTo",
    "PenDown",
    "PenUp",
    "Plan",
    "PlanFigures",
    "PlanOptions",
    "auto_rotation",
    "drop_fine_points",
    "file_digest",
    "font_names",
    "greedy_order",
    "improve",
    "join_touching",
    "load_drawing",
    "optimise",
    "parse_gcode",
    "parse_gcode_text",
    "parse_svg",
    "plan_drawing",
    "plan_file",
    "plan_lines",
    "plan_text",
    "read_drawing",
    "text_lines",
]
