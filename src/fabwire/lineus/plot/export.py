"""A plan written out as Line-us G-code: the file format of drawings stored on the machine (`files save`), and a
drawing `draw` reads back to the same strokes.

The text is what the official Inkscape extension writes for the machine: a `G54 X0 Y0 S1` header, then one `G01`
per line ended by `\\n`; pen lifts and drops are `G01 Z…` moves on their own, so the pen never drags during a hop.
"""

from __future__ import annotations

from pathlib import Path

from fabwire.errors import InputError
from fabwire.lineus import kinematics as kin
from fabwire.lineus import protocol as p
from fabwire.lineus.plot.plan import MoveTo, PenDown, PenUp, Plan

GCODE_SUFFIXES = (".gcode", ".gc", ".nc", ".ngc", ".g")
DECIMALS = 3
"""Coordinates to 1/1000 unit (0.05 µm): far below the arm's resolution, and short lines for the machine's flash."""


def gcode_lines(*plans: Plan, pen_z: float = kin.Z_DOWN) -> list[str]:
    """The plans' move streams, one after another, as G-code lines (no terminators), starting with the pen lifted.

    No G54 header: a stored drawing plays in a session of its own, which starts at `G54 X0 Y0 S1`."""
    lines = [p.Move(z=kin.Z_UP).text()]
    for plan in plans:
        for move in plan.moves():
            if isinstance(move, MoveTo):
                lines.append(p.Move(round(move.x, DECIMALS), round(move.y, DECIMALS)).text())
            elif isinstance(move, PenDown):
                lines.append(p.Move(z=pen_z).text())
            elif isinstance(move, PenUp):
                lines.append(p.Move(z=kin.Z_UP).text())
    return lines


def write_gcode(path: str | Path, plan: Plan, *, pen_z: float = kin.Z_DOWN) -> Path:
    """Write the plan to `path` as Line-us G-code; InputError when it cannot be written."""
    out = Path(path)
    text = "".join(line + "\n" for line in gcode_lines(plan, pen_z=pen_z))
    try:
        out.write_text(text, encoding="ascii")
    except OSError as exc:
        raise InputError(f"cannot write {out}: {exc.strerror or exc}") from exc
    return out
