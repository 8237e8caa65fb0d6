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
import sys
from collections.abc import Iterator

import numpy as np
from numpy.typing import NDArray

from fabwire.errors import InputError
from fabwire.xyz import gcodeinfo, motion

TOLERANCE_MM = motion.ARC_TOLERANCE_MM
"""Largest distance between a segment and the arc it stands for."""
MOST_SEGMENTS = motion.ARC_MOST_SEGMENTS
"""Segments of a full circle at most, whatever its radius (within the tolerance up to a radius of 30 m)."""
Floats = NDArray[np.float64]
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
    as Marlin does. As many lines as `motion.arc_segment_counts` says (at most MOST_SEGMENTS per turn), each at
    most as long as `lines_size` allows."""
    x0, y0, z0, e0 = start

    def target(letter: bytes, begin: float, is_absolute: bool) -> float:
        if letter not in words:
            return begin
        return words[letter] if is_absolute else begin + words[letter]

    x1, y1 = target(b"X", x0, absolute), target(b"Y", y0, absolute)
    z1, e1 = target(b"Z", z0, absolute), target(b"E", e0, absolute_e)
    nan = math.nan
    ax0, ay0, ax1, ay1, i, j, r = (np.array([v]) for v in (x0, y0, x1, y1, words.get(b"I", nan),
                                                            words.get(b"J", nan), words.get(b"R", nan)))
    paths = motion.arc_paths(ax0, ay0, ax1, ay1, i, j, r, np.array([clockwise]),
                             np.array([float(gcodeinfo.arc_turns(words))]))
    cx, cy, radius, begin, sweep = (float(v[0]) for v in paths)
    if not all(math.isfinite(v) for v in (radius, x1, y1, z1, e1)):  # no centre, or beyond what a float holds
        return None
    count = int(motion.arc_segment_counts(paths[2], paths[4])[0])
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


def _widths(low: Floats, high: Floats, places: int) -> Floats:
    """Characters at most of a number from `low` to `high` written with `places` decimals (`_number`): its sign
    where it may be negative, integer digits (one more where rounding carries), the point and the decimals."""
    with np.errstate(invalid="ignore", over="ignore"):
        most = np.minimum(np.maximum(np.abs(low), np.abs(high)) * (1 + 1e-9) + 10.0 ** -places, sys.float_info.max)
        digits = np.floor(np.log10(np.maximum(most, 1.0))) + 1
        width: Floats = (low < 0) + digits + (1 + places)
    return width


def lines_size(paths: tuple[Floats, Floats, Floats, Floats, Floats], counts: NDArray[np.int64], x1: Floats,
               y1: Floats, z: tuple[Floats, Floats], e: tuple[Floats, Floats], feed: Floats, *,
               absolute: bool = True, absolute_e: bool = True) -> Floats:
    """Bytes at most (newlines included) of the G1 lines `segments` writes for arcs with these `paths`
    (`motion.arc_paths`) and `counts` (`motion.arc_segment_counts`), ending at (x1, y1), with Z and E from
    (start, end) and the F word on the line (NaN without one), in these modes: every coordinate lies within
    the arc's circle and its end (relative moves within a diameter, or the end's distance from the centre plus
    the radius for the last), Z and E within their start and end. 0 for an arc without segments (count 0)."""
    cx, cy, radius = paths[:3]
    (z0, z1), (e0, e1) = z, e
    with np.errstate(invalid="ignore", over="ignore"):
        if absolute:
            wx = _widths(np.minimum(cx - radius, x1), np.maximum(cx + radius, x1), 4)
            wy = _widths(np.minimum(cy - radius, y1), np.maximum(cy + radius, y1), 4)
            wz = _widths(np.minimum(z0, z1), np.maximum(z0, z1), 4)
        else:
            reach = [np.maximum(2 * radius, np.abs(end - c) + radius) for end, c in ((x1, cx), (y1, cy))]
            wx, wy = (_widths(-most, most, 4) for most in reach)
            wz = _widths(-np.abs(z1 - z0), np.abs(z1 - z0), 4)
        we = (_widths(np.minimum(e0, e1), np.maximum(e0, e1), 5) if absolute_e
              else _widths(-np.abs(e1 - e0), np.abs(e1 - e0), 5))
        line = len("G1 X Y\n") + wx + wy + np.where(z1 != z0, 2 + wz, 0.0) + np.where(e1 != e0, 2 + we, 0.0)
        first = np.where(np.isfinite(feed), 2 + _widths(feed, feed, 3), 0.0)
        size = counts * line + first
    result: Floats = np.where((counts > 0) & ~np.isnan(size), size, 0.0)  # NaN: an end no float holds, no segments
    return result


GROWTH_ALLOWED = 8
"""How many times its own size a G-code may grow by its arcs becoming segments (beyond GROWTH_FREE): slicers' arcs
grow a file two to three times; full turns (P) of large circles could otherwise make a few kilobytes hundreds of
megabytes."""
GROWTH_FREE = 64 * 1024 * 1024


def growth_room(size: int) -> int:
    """Bytes of segments the arcs of a G-code of `size` bytes may become (GROWTH_ALLOWED, GROWTH_FREE)."""
    return GROWTH_ALLOWED * size + GROWTH_FREE


class TooMuchGrowth(InputError):
    """The refusal of a G-code whose arcs would grow it past `growth_room` (`too_much_growth`): `name`, `arc`."""

    def __init__(self, name: str, arc: int, advice: str) -> None:
        super().__init__(f"{name}: its G2/G3 arcs as straight moves would make it more than {GROWTH_ALLOWED} times "
                         f"its size (past arc {arc}): {advice}")
        self.name, self.arc = name, arc


def too_much_growth(name: str, arc: int, advice: str = "slice it with arcs off, or convert it with --keep-arcs",
                    ) -> TooMuchGrowth:
    """The refusal of the G-code `name` whose `arc`-th G2/G3 arc takes its segments past `growth_room`, with
    `advice` on what to do (the command line's by default)."""
    return TooMuchGrowth(name, arc, advice)


OUT_PIECE = 1 << 20
"""Bytes of converted G-code handed on at a time (`ArcExpander.expand`)."""


class ArcExpander:
    """Rewrites the G2/G3 lines of consecutive line-aligned chunks of a G-code as G1 segments, keeping track of
    the position and modes the file sets. `name` and `size` (bytes) are the file's: its segments may make it at most
    GROWTH_ALLOWED times that size plus GROWTH_FREE (InputError past it)."""

    def __init__(self, name: str = "the G-code", size: int = 0) -> None:
        self.tracker = gcodeinfo.MoveAnalyzer(timing=False, positions_only=True)
        self.converted = 0
        self.name = name
        self.room = growth_room(size)

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
            lines = segments((t.pos[0], t.pos[1], t.pos[2], t.e), gcodeinfo.words_of(params), found.group(1) == b"2",
                             absolute=t.absolute, absolute_e=t.absolute_e)
            out.append(chunk[at:found.start()])
            held += found.start() - at
            if lines is None:
                out.append(b"G1" + found.group(2) + b"\n")
            else:
                written = ("\n".join(lines) + "\n").encode()
                self.room -= len(written)
                if self.room < 0:  # (the analysis bounded every arc's segments before: see `lines_size`)
                    raise too_much_growth(self.name, self.converted + 1)
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
