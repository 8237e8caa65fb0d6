"""G2/G3 arcs written as the straight G1 moves a printer surely runs.

PrusaSlicer 2.6+ and OrcaSlicer (arc fitting) and the ArcWelder post-processor replace polylines by G2/G3. No public
source shows whether da Vinci firmware executes G2/G3 (miniMover and the XYZ protocol notes never mention them),
so a conversion turns each arc into segments that stay within TOLERANCE_MM of the true arc, as Marlin's own
plan_arc would, unless the user keeps them (`--keep-arcs`).

The arc rules are Marlin's: I and J are offsets from the start to the centre whatever G90/G91 says; R gives the
radius instead (negative for the longer way round); an arc that ends where it starts is a full circle.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator

import numpy as np

from fabwire.errors import InputError
from fabwire.xyz import motion
from fabwire.xyz.gcodeinfo import MoveAnalyzer, arc_turns, words_of

TOLERANCE_MM = 0.01
"""Largest distance between a segment and the arc it stands for."""
MOST_SEGMENTS = 4096
"""Segments of a full circle at most, whatever its radius (within the tolerance up to a radius of 30 m)."""
_ARC_LINE = re.compile(rb"^[ \t]*(?:[Nn][0-9]+[ \t]*)?[Gg][ \t]*0*([23])(?![0-9.])([^\n]*)\n", re.MULTILINE)


def _number(value: float, places: int) -> str:
    text = f"{value:.{places}f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text


def segments(start: tuple[float, float, float, float], words: dict[bytes, float], clockwise: bool, *,
             absolute: bool = True, absolute_e: bool = True) -> list[str] | None:
    """The G1 lines for an arc from `start` (X, Y, Z, E) with these words, after the full turns its P asks for
    (`gcodeinfo.arc_turns`; Z and E spread over the whole path, as Marlin's plan_arc does), or None when the arc
    has no centre (no I, J or R; an R arc that ends where it starts; a circle too wide for a float to step
    across), which a printer runs as a straight move. An R shorter than half the chord puts the centre mid-chord,
    as Marlin does. At most MOST_SEGMENTS lines per turn."""
    x0, y0, z0, e0 = start

    def target(letter: bytes, begin: float, is_absolute: bool) -> float:
        if letter not in words:
            return begin
        return words[letter] if is_absolute else begin + words[letter]

    x1, y1 = target(b"X", x0, absolute), target(b"Y", y0, absolute)
    z1, e1 = target(b"Z", z0, absolute), target(b"E", e0, absolute_e)
    if b"I" in words or b"J" in words:
        cx, cy = x0 + words.get(b"I", 0.0), y0 + words.get(b"J", 0.0)
    elif b"R" in words and (x1, y1) != (x0, y0):
        r = words[b"R"]
        cx, cy = (float(v) for v in motion.radius_centre(np.array(x0), np.array(y0), np.array(x1), np.array(y1),
                                                          np.array(r), np.array(clockwise)))
    else:
        return None
    radius = math.hypot(x0 - cx, y0 - cy)
    if not all(math.isfinite(v) for v in (radius, x1, y1, z1, e1)):
        return None
    begin, end = math.atan2(y0 - cy, x0 - cx), math.atan2(y1 - cy, x1 - cx)
    sweep = ((begin - end) if clockwise else (end - begin)) % (2 * math.pi)
    if sweep < 1e-9:
        sweep = 2 * math.pi
    sweep += arc_turns(words) * 2 * math.pi
    step = 2 * math.acos(max(-1.0, 1 - TOLERANCE_MM / radius)) if radius > TOLERANCE_MM else math.pi
    step = max(step, 2 * math.pi / MOST_SEGMENTS)
    count = max(1, math.ceil(sweep / step))
    sign = -1.0 if clockwise else 1.0
    lines = []
    last = (x0, y0, z0, e0)
    for k in range(1, count + 1):
        if k == count:
            point = (x1, y1, z0 + (z1 - z0), e1)
        else:
            angle = begin + sign * sweep * k / count
            point = (cx + radius * math.cos(angle), cy + radius * math.sin(angle), z0 + (z1 - z0) * k / count,
                     e0 + (e1 - e0) * k / count)
        shown = point if absolute else tuple(p - q for p, q in zip(point, last, strict=True))
        if not all(math.isfinite(v) for v in shown):  # steps across a circle wider than a float holds
            return None
        line = f"G1 X{_number(shown[0], 4)} Y{_number(shown[1], 4)}"
        if z1 != z0:
            line += f" Z{_number(shown[2], 4)}"
        if e1 != e0:
            line += f" E{_number(point[3] if absolute_e else point[3] - last[3], 5)}"
        if k == 1 and math.isfinite(words.get(b"F", math.nan)):
            line += f" F{_number(words[b'F'], 3)}"
        lines.append(line)
        last = point
    return lines


GROWTH_ALLOWED = 8
"""How many times its own size a G-code may grow by its arcs becoming segments (beyond GROWTH_FREE): slicers' arcs
grow a file two to three times; full turns (P) of large circles could otherwise make a few kilobytes hundreds of
megabytes."""
GROWTH_FREE = 64 * 1024 * 1024


OUT_PIECE = 1 << 20
"""Bytes of converted G-code handed on at a time (`ArcExpander.expand`)."""


class ArcExpander:
    """Rewrites the G2/G3 lines of consecutive line-aligned chunks of a G-code as G1 segments, keeping track of
    the position and modes the file sets. `name` and `size` (bytes) are the file's: its segments may make it at most
    GROWTH_ALLOWED times that size plus GROWTH_FREE (InputError past it)."""

    def __init__(self, name: str = "the G-code", size: int = 0) -> None:
        self.tracker = MoveAnalyzer()
        self.converted = 0
        self.name = name
        self.room = GROWTH_ALLOWED * size + GROWTH_FREE

    def expand(self, chunk: bytes) -> Iterator[bytes]:
        """`chunk` (whole lines) with its arcs as G1 lines, in line-aligned pieces of about OUT_PIECE bytes: what
        a chunk grows into is never held whole."""
        out: list[bytes] = []
        held = 0
        at = 0
        for found in _ARC_LINE.finditer(chunk):
            if found.start() > at:
                self.tracker.feed_chunk(chunk[at:found.start()])
            t = self.tracker
            params = found.group(2).partition(b";")[0].upper()
            lines = segments((t.pos[0], t.pos[1], t.pos[2], t.e), words_of(params), found.group(1) == b"2",
                             absolute=t.absolute, absolute_e=t.absolute_e)
            out.append(chunk[at:found.start()])
            held += found.start() - at
            if lines is None:
                out.append(b"G1" + found.group(2) + b"\n")
            else:
                written = ("\n".join(lines) + "\n").encode()
                self.room -= len(written)
                if self.room < 0:
                    raise InputError(f"{self.name}: its G2/G3 arcs as straight moves would make it more than "
                                     f"{GROWTH_ALLOWED} times its size (past arc {self.converted + 1}): slice it "
                                     "with arcs off, or convert it with --keep-arcs")
                out.append(written)
                held += len(written)
                self.converted += 1
            t.feed_lines(found.group(0))
            at = found.end()
            if held >= OUT_PIECE:
                yield b"".join(out)
                out, held = [], 0
        if at == 0:
            self.tracker.feed_chunk(chunk)
            yield chunk
            return
        if at < len(chunk):
            self.tracker.feed_chunk(chunk[at:])
        out.append(chunk[at:])
        yield b"".join(out)
