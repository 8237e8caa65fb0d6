"""The Line-us drawing pipeline: SVG, G-code and single-stroke text → polylines → placed in the reachable
area → ordered for least pen-up travel → a typed move stream with time and length figures."""

from fabwire.lineus.plot.gcode import parse_gcode, parse_gcode_text
from fabwire.lineus.plot.optimize import drop_fine_points, greedy_order, improve, join_touching, optimise
from fabwire.lineus.plot.plan import (
    Move,
    MoveTo,
    PenDown,
    PenUp,
    Plan,
    PlanFigures,
    PlanOptions,
    file_digest,
    load_drawing,
    plan_file,
    plan_lines,
    plan_text,
)
from fabwire.lineus.plot.svg import parse_svg
from fabwire.lineus.plot.text import font_names, text_lines

__all__ = [
    "Move",
    "MoveTo",
    "PenDown",
    "PenUp",
    "Plan",
    "PlanFigures",
    "PlanOptions",
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
    "plan_file",
    "plan_lines",
    "plan_text",
    "text_lines",
]
