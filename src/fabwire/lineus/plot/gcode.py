"""Line-us G-code files (the format drawings are saved in) to pen-down polylines in machine units.

Understood: G0/G00/G1/G01 with any of X, Y, Z (Z below 500 = pen down), G28 (pen-up move home). Settings
(G54, G94, G90, G21, M-codes) carry no geometry and are skipped; relative moves and arcs are refused rather
than misdrawn.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from fabwire.errors import InputError
from fabwire.lineus.kinematics import HOME, PEN_DOWN_BELOW, Z_UP
from fabwire.lineus.plot.geometry import Polylines

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")
_COMMENT = re.compile(r"\([^)]*\)|;.*$")
_SKIPPED = {"G54", "G94", "G90", "G21", "G40", "G31", "G4"}
_REFUSED = {"G91": "relative positioning", "G2": "arcs", "G3": "arcs", "G20": "inch units"}


def _code(word: str) -> str:
    letter, number = word[0].upper(), word[1:]
    try:
        return f"{letter}{int(float(number))}" if float(number).is_integer() else f"{letter}{number}"
    except ValueError:
        return word.upper()


def parse_gcode_text(text: str, *, name: str = "G-code") -> Polylines:
    """Pen-down polylines drawn by `text`, starting from home with the pen up."""
    x, y = HOME
    z = Z_UP
    lines: Polylines = []
    current: list[tuple[float, float]] = []

    def finish() -> None:
        nonlocal current
        if len(current) >= 2 or (len(current) == 1 and z < PEN_DOWN_BELOW):
            lines.append(np.asarray(current, dtype=float))
        current = []

    for number, raw in enumerate(text.splitlines(), start=1):
        line = _COMMENT.sub("", raw).strip().strip("\x00")
        if not line:
            continue
        words = line.split()
        head = words[0]
        if not re.fullmatch(r"[GgMm]\d+(\.\d+)?", head):
            match = re.match(r"([GgMm]\d+)(.*)", head)
            if not match:
                raise InputError(f"{name}:{number}: cannot read {raw.strip()!r}")
            words = [match.group(1), match.group(2), *words[1:]]
        code = _code(words[0])
        if code.startswith("M") or code in _SKIPPED:
            continue
        if code in _REFUSED:
            raise InputError(f"{name}:{number}: {code} ({_REFUSED[code]}) is not supported")
        if code == "G28":
            finish()
            x, y = HOME
            z = Z_UP
            continue
        if code not in ("G0", "G1"):
            raise InputError(f"{name}:{number}: unknown command {words[0]!r}")
        params: dict[str, float] = {}
        rest = " ".join(words[1:])
        for letter, value in _WORD.findall(rest):
            params[letter.upper()] = float(value)
        leftover = _WORD.sub("", rest).strip()
        if leftover:
            raise InputError(f"{name}:{number}: cannot read parameters {leftover!r}")
        if any(not math.isfinite(v) for v in params.values()):
            raise InputError(f"{name}:{number}: coordinates must be finite numbers")
        nx, ny = params.get("X", x), params.get("Y", y)
        nz = params.get("Z", z)
        was_down = z < PEN_DOWN_BELOW
        down = nz < PEN_DOWN_BELOW
        if was_down and down:
            if not current:
                current = [(x, y)]
            if (nx, ny) != (x, y):
                current.append((nx, ny))
        elif was_down and not down:
            finish()
        elif down:
            # A pen-up position followed by a move that lands with the pen down: the pen drops at the end.
            current = [(nx, ny)]
        x, y, z = nx, ny, nz
    finish()
    return lines


def parse_gcode(path: str | Path) -> Polylines:
    """Read a G-code file; InputError when it is unreadable or draws nothing."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8", errors="strict")
    except FileNotFoundError as exc:
        raise InputError(f"{p}: no such file") from exc
    except UnicodeDecodeError as exc:
        raise InputError(f"{p}: not a text G-code file") from exc
    except OSError as exc:
        raise InputError(f"{p}: cannot read ({exc.strerror or exc})") from exc
    return parse_gcode_text(text, name=str(p))
