"""Line-us G-code files (the format drawings are stored in) to pen-down polylines in machine units.

The lines run through the machine's own interpreter (`fabwire.lineus.interpreter`): G54 scale and origin, G40
moves that ignore it, G28, partial axes, Z semantics and comments mean here exactly what they mean to the arm, and
a dot (pen down and up in one place) is a one-point polyline. The geometry stays raw (no out-of-area clamping)
so the planner can refuse, clip or fit what lies outside the drawing area. Codes that mean other geometry on other
machines (arcs, relative moves, inches) are refused rather than misdrawn.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fabwire.errors import InputError
from fabwire.lineus.interpreter import trace_text
from fabwire.lineus.plot.geometry import Polylines


def parse_gcode_text(text: str, *, name: str = "G-code", notes: list[str] | None = None) -> Polylines:
    """Pen-down polylines drawn by `text`, starting from home with the pen up; skipped lines are described in
    `notes` when given. InputError names the file and line of anything the Line-us cannot run."""
    traced = trace_text(text, name=name)
    note = traced.program.skipped_note()
    if note is not None and notes is not None:
        notes.append(note)
    return [np.asarray(stroke, dtype=float).reshape(-1, 2) for stroke in traced.ink.strokes]


def parse_gcode(path: str | Path, *, notes: list[str] | None = None) -> Polylines:
    """Read a G-code file through the drawing intake (size limit, encodings); InputError when it is unreadable,
    empty, or not G-code."""
    from fabwire.lineus.plot.intake import read_drawing

    drawing = read_drawing(path)
    if drawing.kind != "gcode":
        raise InputError(f"{path}: not a G-code file")
    if notes is not None:
        notes.extend(drawing.notes)
    return drawing.lines
