"""What a printer's display needs to know about a G-code: print time, filament and layers.

Slicers state these in comments (at the top for Cura/XYZ, at the end for PrusaSlicer/Slic3r/Simplify3D); when a value
is missing it is computed from the moves themselves.
"""

from __future__ import annotations

import functools
import itertools
import math
import re
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from fabwire.xyz import arcwork, gcodearrays, motion, slicerfigures
from fabwire.xyz.gcodearrays import (
    CENTRELESS,
    INCHES,
    REPEATED,
    SECOND_COMMAND,
    SECOND_COMMAND_WORD,
    SEPARATOR,
    SEPARATORS,
    SUBCODE,
    TEXT_COMMANDS,
    TURNS,
    VALUE,
    Ambiguous,
    Words,
)

DEFAULT_FACETS = 50
DEFAULT_FEED_MM_MIN = 1500.0
"""Feed rate assumed for moves before the first F word."""


@dataclass(frozen=True, slots=True)
class GcodeMetadata:
    """Values for the .3w header; None where neither a comment nor the moves told."""

    print_time_s: int | None = None
    filament_mm: float | None = None
    layers: int | None = None
    facets: int | None = None
    slicer: str | None = None
    notes: tuple[str, ...] = ()
    """Why a figure was set aside (a slicer's placeholder, a zero, a value no print has)."""
    extent: tuple[tuple[float, float], ...] | None = None
    """(lowest, highest) X, Y and Z in mm the moves reach, travel included (`REACH`); None when nothing moves."""
    arcs: int = 0
    """G2/G3 arc moves in the file (counted from the moves)."""

    @property
    def complete(self) -> bool:
        return None not in (self.print_time_s, self.filament_mm, self.layers)

    def merged(self, other: GcodeMetadata) -> GcodeMetadata:
        """Fill this one's gaps from `other`."""
        return GcodeMetadata(
            print_time_s=self.print_time_s if self.print_time_s is not None else other.print_time_s,
            filament_mm=self.filament_mm if self.filament_mm is not None else other.filament_mm,
            layers=self.layers if self.layers is not None else other.layers,
            facets=self.facets if self.facets is not None else other.facets,
            slicer=self.slicer or other.slicer,
            notes=self.notes + other.notes,
            extent=self.extent if self.extent is not None else other.extent,
            arcs=self.arcs or other.arcs,
        )


_FACETS = re.compile(rb"^;[ \t]*facets[ \t]*=[ \t]*([0-9]+)", re.MULTILINE | re.IGNORECASE)


def _comment_lines(window: bytes) -> bytes:
    """The `;` comment lines of a piece of G-code (every pattern here reads comments; moves are most of a file)."""
    return b"\n".join([line for line in window.split(b"\n")  # most lines start with their command: one look
                       if line[:1] == b";" or (line[:1] in b" \t" and line.lstrip(b" \t")[:1] == b";")])


_FIGURE_NAMES = {"time": "print time", "filament": "filament", "layers": "layer count"}


def header_metadata(*windows: bytes) -> GcodeMetadata:
    """The values slicer comments state in the given pieces of a G-code (its head and its tail), as the table of
    wordings in `slicerfigures` reads them; figures not believed are left out and named in `notes`."""
    windows = tuple(_comment_lines(window) for window in windows)
    stated = slicerfigures.stated_figures(windows)
    facets = None
    for window in windows:
        found = _FACETS.search(window)
        if found:
            count = int(found.group(1)) if len(found.group(1)) <= 18 else slicerfigures.ABSURD
            facets = count if 0 < count <= slicerfigures.MAX_COUNT else None
            break
    notes = tuple(f"the stated {_FIGURE_NAMES[figure]} is not believed: {why}" for figure, why in stated.rejected)
    return GcodeMetadata(stated.time_s, stated.filament_mm, stated.layers, facets, stated.slicer, notes)


# G-code as Marlin reads it: a word is a letter, optional blanks, then a decimal number without exponent (so
# `G1X10E5` is X10 E5 and `X1E5` is X1 E5); `;` ends the code of a line, `(...)` is a comment and `*` starts the
# checksum. A command word opens the line, after blanks and an optional N line number.
_COMMAND = re.compile(
    rb"\n[ \t]*(?:[Nn][-+]?[0-9]+[ \t]*)?([GgMm])[ \t]*0*([0-9]+)(\.[0-9]*)?(?![0-9.])([^\n;]*)",
)
_SECOND_COMMAND = re.compile(SECOND_COMMAND_WORD)
_NO_SUBCODE = {b"G0", b"G1", b"G2", b"G3", b"G92", b"G20", b"G21"}
"""Commands refused with a subcode (`gcodearrays.SUBCODE`): they move, set the position or set units."""
_WORD = re.compile(rb"([A-Z])[ \t]*(" + VALUE + rb")")
_PAREN_COMMENT = re.compile(rb"\([^)]*\)?")


def _ffill(values: NDArray[np.float64], start: float) -> NDArray[np.float64]:
    """Each NaN replaced by the last value before it (`start` before the first)."""
    known = ~np.isnan(values)
    index = np.where(known, np.arange(len(values)), -1)
    np.maximum.accumulate(index, out=index)
    return np.where(index >= 0, values[np.maximum(index, 0)], start)


def _axis(given: NDArray[np.float64], sets: NDArray[np.bool_], start: float,
          absolute: bool) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(position after each word, the move each word makes) for one axis's words in order; a G92 word moves
    nothing and sets the position."""
    if absolute:
        delta = np.diff(given, prepend=start)
        delta[sets] = 0.0
        return given, delta
    delta = np.where(sets, 0.0, given)
    total = np.cumsum(delta)
    if not sets.any():
        return total + start, delta
    base = np.where(sets, given - total, np.nan)
    return total + _ffill(base, start), delta


def _runs(lines: NDArray[np.intp], values: NDArray[np.float64],
          before: float) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """(first line, value) of each run of lines sharing the value set at its first line; `before` holds from 0."""
    if len(lines) and lines[0] == 0:
        return lines, values
    return np.concatenate(([0], lines)), np.concatenate(([before], values))


def _code(params: bytes) -> bytes:
    """A command's parameters without comments in parentheses and without the checksum."""
    if b"(" in params:
        params = _PAREN_COMMENT.sub(b" ", params)
    return params.partition(b"*")[0]


@functools.lru_cache(maxsize=64)
def _homed_axes(params: bytes) -> tuple[int, ...]:
    """The axes (0 X, 1 Y, 2 Z) a G28 with these parameters homes: those it names, else all three (Marlin)."""
    named = sorted({b"XYZ".index(axis) for axis in re.findall(rb"[XYZ]", _code(params))})
    return tuple(named) or (0, 1, 2)


def words_of(params: bytes) -> dict[bytes, float]:
    """Letter -> value of upper-cased parameters; `gcodearrays.Ambiguous` when a letter repeats (Marlin's parsers
    disagree on which one wins)."""
    code = _code(params)
    found = _WORD.findall(code)
    words: dict[bytes, float] = {}
    for letter, value in found:
        words.setdefault(letter, float(value))
    if len(words) < len(found) and not gcodearrays.MALFORMED.search(code):  # `X1e3 E5`: the exponent's refusal
        raise Ambiguous(REPEATED)
    return words


MOST_TURNS = 100
"""Full turns an arc's P may ask for: Marlin's ARC_P_CIRCLES range (G2_G3.cpp, WITHIN(circles_to_do, 0, 100))."""


def full_turns(given: NDArray[np.float64]) -> NDArray[np.float64]:
    """The full turns (P) G2/G3 arcs make before their arcs, 0 where P is not given (NaN); `gcodearrays.Ambiguous`
    (TURNS) for a P that is not a whole number from 0 to MOST_TURNS."""
    turns: NDArray[np.float64] = np.where(np.isnan(given), 0.0, given)
    if not ((turns >= 0) & (turns <= MOST_TURNS) & (turns == np.floor(turns))).all():
        raise Ambiguous(TURNS)
    return turns


def arc_turns(words: dict[bytes, float]) -> int:
    """`full_turns` of one arc's words."""
    return int(full_turns(np.array([words.get(b"P", math.nan)]))[0])


def centreless(x0: NDArray[np.float64], y0: NDArray[np.float64], x1: NDArray[np.float64], y1: NDArray[np.float64],
               i: NDArray[np.float64], j: NDArray[np.float64], r: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Which G2/G3 arcs from (x0, y0) to (x1, y1) with centre offsets I, J or radius R (NaN when not given) give a
    centre offset of zero, which Marlin refuses (`gcodearrays.CENTRELESS`): I and J both zero, R zero, or an R arc
    that ends where it starts. An arc with none of I, J and R is not one of them (`REACH`)."""
    by_offsets = ~(np.isnan(i) & np.isnan(j))
    found: NDArray[np.bool_] = (by_offsets & (np.nan_to_num(i) == 0) & (np.nan_to_num(j) == 0)) | (
        ~by_offsets & ~np.isnan(r) & ((r == 0) | ((x1 == x0) & (y1 == y0))))
    return found


@dataclass(frozen=True, slots=True)
class LayerMarker:
    """A comment a slicer writes at each layer change."""

    pattern: bytes
    slicers: str
    source: str


LAYER_MARKERS: tuple[LayerMarker, ...] = (
    LayerMarker(rb"LAYER_CHANGE\n", "PrusaSlicer, SuperSlicer, OrcaSlicer, BambuStudio",
                "prusa3d/PrusaSlicer src/libslic3r/GCode.cpp (process_layer writes ;LAYER_CHANGE)"),
    LayerMarker(rb"LAYER:-?[0-9]+\n", "Cura, ideaMaker",
                "Ultimaker/CuraEngine gcodeExport::writeLayerComment; moonraker metadata.py (IdeaMaker ;LAYER:0)"),
    LayerMarker(rb"[ \t]*layer [0-9]+, Z = ", "Simplify3D",
                "Arksine/moonraker metadata.py; Simplify3D G-code (; layer 1, Z = 0.200)"),
    LayerMarker(rb"; --- layer [0-9]+ ", "Kiri:Moto", "Arksine/moonraker metadata.py (KiriMoto ;; --- layer N)"),
    LayerMarker(rb"[ \t]*END_LAYER_OBJECT z=", "KISSlicer", "Arksine/moonraker metadata.py (KISSlicer)"),
)
"""Layer change comments, one count per kind; the layers are the most any kind counts."""
_MARKERS = re.compile(rb"\n;(?:" + b"|".join(b"(" + m.pattern + b")" for m in LAYER_MARKERS) + rb")", re.IGNORECASE)
_ARC = {b"G2": 2, b"G3": 3}
VASE_LAYER_MM = 0.2
"""Layer height assumed for a spiral vase without any flat layer to learn it from."""


@dataclass(frozen=True, slots=True)
class ReachRule:
    """How one kind of move widens the extent the build volume check compares with the machine."""

    construct: str
    counted: str
    source: str


REACH: tuple[ReachRule, ...] = (
    ReachRule("G0/G1 with X, Y or Z, extruding or not", "its start and end points",
              "RepRap wiki G-code, G0 & G1; travel goes beyond the volume as surely as printing does, and no public "
              "source says a da Vinci has software endstops to stop it"),
    ReachRule("G1 with Z only and E (extruding while it rises)", "its start and end points, like any move",
              "RepRap wiki G-code, G0 & G1 (the axes named move, extruding or not)"),
    ReachRule("G1 with E only (extruding where the nozzle stands)", "the point it extrudes at (its start and end)",
              "RepRap wiki G-code, G0 & G1"),
    ReachRule("G2/G3 with I and J (centre offsets)", "the whole arc: its end points and every axis extreme "
              "(centre ± radius) its swept angle crosses; a start that equals the end is a full circle",
              "Marlin G2-G3 Arc or Circle Move (marlinfw.org/docs/gcode/G002-G003.html); Marlin plan_arc"),
    ReachRule("G2/G3 with R (radius; negative for the longer way round)", "the whole arc as for I and J, its centre "
              "on the chord's bisector; an R shorter than half the chord puts the centre mid-chord (a half circle)",
              "Marlin G2-G3 Arc or Circle Move, R form; Marlin gcode/motion/G2_G3.cpp (h = 0 when R is too short)"),
    ReachRule("G2/G3 without I, J or R", "its end points (a straight move at most)",
              "Marlin G2-G3 (refuses the move); arcwork passes it on as G1"),
    ReachRule("G92 (set position)", "nothing by itself: moves after it count from the position it sets",
              "RepRap wiki G-code, G92"),
)
"""What the extent of a G-code counts, per construct (tests/xyz/test_reach.py has one test per row)."""


def arc_box(x0: NDArray[np.float64], y0: NDArray[np.float64], x1: NDArray[np.float64], y1: NDArray[np.float64],
            i: NDArray[np.float64], j: NDArray[np.float64], r: NDArray[np.float64],
            clockwise: NDArray[np.bool_]) -> tuple[NDArray[np.float64], ...]:
    """(lowest X, highest X, lowest Y, highest Y) in mm of G2 (clockwise) / G3 arcs from (x0, y0) to (x1, y1) with
    centre offsets I, J (NaN when not given) or radius R (`REACH`): the end points, the point at the end's angle on
    the start's circle, and each of the four axis extremes of that circle that the swept angle crosses. NaN results
    (coordinates no float holds) are infinite."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        centred = ~(np.isnan(i) & np.isnan(j))
        chord = np.hypot(x1 - x0, y1 - y0)
        by_radius = motion.radius_centre(x0, y0, x1, y1, np.nan_to_num(r), clockwise)
        cx = np.where(centred, x0 + np.nan_to_num(i), by_radius[0])
        cy = np.where(centred, y0 + np.nan_to_num(j), by_radius[1])
        has_centre = centred | (~np.isnan(r) & (chord > 0))
        radius = np.hypot(x0 - cx, y0 - cy)
        begin, end = np.arctan2(y0 - cy, x0 - cx), np.arctan2(y1 - cy, x1 - cx)
        sweep = np.where(clockwise, begin - end, end - begin) % (2 * math.pi)
        sweep = np.where(sweep < 1e-9, 2 * math.pi, sweep)
        # an end off the start's circle (I and J disagreeing with it): the arc runs on that circle to the end's angle
        last_x = np.where(has_centre, cx + radius * np.cos(end), x1)
        last_y = np.where(has_centre, cy + radius * np.sin(end), y1)
        box = [np.minimum(np.minimum(x0, x1), last_x), np.maximum(np.maximum(x0, x1), last_x),
               np.minimum(np.minimum(y0, y1), last_y), np.maximum(np.maximum(y0, y1), last_y)]
        for quarter, (k, centre, sign) in enumerate(((1, cx, 1.0), (3, cy, 1.0), (0, cx, -1.0), (2, cy, -1.0))):
            angle = quarter * math.pi / 2
            crossed = has_centre & (np.where(clockwise, begin - angle, angle - begin) % (2 * math.pi) <= sweep)
            extreme = centre + sign * radius
            box[k] = np.where(crossed, (np.maximum if sign > 0 else np.minimum)(box[k], extreme), box[k])
            box[k] = np.where(crossed & np.isnan(extreme), np.inf, box[k])
    return tuple(np.where(np.isnan(side), np.inf, side) for side in box)


def _separated(chunk: bytes, separator: bytes) -> int:
    """The start (offset in b"\n" + `chunk`) of the first line with `separator` in its code (before any `;`: a
    comment is any text), or len(chunk) + 1."""
    at = chunk.find(separator)
    while at >= 0:
        start = chunk.rfind(b"\n", 0, at) + 1
        if b";" not in chunk[start:at]:
            return start
        at = chunk.find(separator, at + 1)
    return len(chunk) + 1


def _ambiguous_at(piece: bytes, found: Ambiguous) -> int:
    """The offset in `piece` of the first line `gcodearrays.LINE_RULES` refuses (where the line reader finds it;
    `found`'s own offset when it finds none)."""
    try:
        MoveAnalyzer(timing=False)._lines(piece)
    except Ambiguous as exc:
        return exc.offset
    return found.offset


class ArcGrowth(Exception):
    """The G2/G3 arcs read so far would become more bytes of segments than `MoveAnalyzer`'s `arc_room`; `arc` is
    the one (counted from 1 among the file's arcs) that went past it."""

    def __init__(self, arc: int) -> None:
        super().__init__(arc)
        self.arc = arc


class MoveAnalyzer:
    """Computes print time, net filament and layer count from the moves, fed line-aligned chunks in order.

    Time: a trapezoid per move under the file's own M201-M205 limits (`motion`), plus dwells. Layers: the
    slicer's layer markers when present, else the distinct heights of flat extruding moves plus, for spiral
    vase parts (moves that rise while they extrude), their rise over the layer height. G2/G3 arcs count by their
    length. Ordinary slicer output is analysed with array operations; chunks with indented or numbered lines take a
    line-by-line path.
    """

    def __init__(self, *, timing: bool = True, g0_words: list[NDArray[np.intp] | None] | None = None,
                 arc_room: float = math.inf, positions_only: bool = False) -> None:
        """`timing=False` skips planning the moves' time (when the file states it): `seconds` is then the
        path over feed rate only. `g0_words` collects, per chunk fed, the offsets of the `0` of its G0 and G00
        command words (see `gcodearrays.Scan.g0_at`), or None for a chunk with lines only the line reader reads.
        `arc_room`: the bytes of G1 segments the arcs may become (`arcwork.lines_size` bounds each arc's); the arc
        that takes them past it raises ArcGrowth as soon as it is read. `positions_only`: the line reader follows
        where G2/G3 arcs end and nothing more (not their length, reach or segments; nor their checks)."""
        self.timing = timing
        self.g0_words = g0_words
        self.pos = [0.0, 0.0, 0.0]
        self.e = 0.0
        self.feed = DEFAULT_FEED_MM_MIN
        self.absolute = True
        self.absolute_e = True
        self.filament = 0.0
        self.path_seconds = 0.0
        """Path length over feed rate, without acceleration (the lower bound of the time), plus dwells."""
        self.dwell = 0.0
        self.planner = motion.Planner()
        self.layer_heights: set[int] = set()
        """Heights (in µm) at which flat extruding moves happened."""
        self.vase_rise = 0.0
        """How far extruding moves rose while they moved (mm): spiral vase printing."""
        self.markers = [0] * len(LAYER_MARKERS)
        self.arcs = 0
        self.arc_room = arc_room
        self.positions_only = positions_only
        self.arc_segments = 0
        """The G1 segments the arcs read so far become (`motion.arc_segment_counts`, as `arcwork.segments`)."""
        self.arc_bytes = 0.0
        """Bytes at most those segments take as G1 lines (`arcwork.lines_size`)."""
        self._bounded = 0
        self.low = [math.inf] * 3
        self.high = [-math.inf] * 3
        """The extent (mm, per axis) the moves reach, as `REACH` counts it."""
        self._held: list[tuple[float, float, float, float, float, float]] = []
        gcodearrays.reuse_freed_memory()

    @property
    def seconds(self) -> float:
        """The estimated print time so far (complete once the whole file was fed)."""
        self._release()
        return self.planner.total() + self.dwell if self.timing else self.path_seconds

    def feed_chunk(self, chunk: bytes, odd: list[tuple[int, int]] | None = None) -> None:
        """Analyse whole lines; `chunk` must start at a line start (its end ends its last line).

        `odd` collects the (start, end) offsets of the parts of `chunk`, from a line start to a line end, outside
        which no G line holds a word of `gcodearrays.NUMBER_FORMS` in its code."""
        self._count_markers(chunk)
        g0_words: list[NDArray[np.intp]] | None = []
        for start, end, found in gcodearrays.scanned_pieces(chunk):  # bounded pieces keep the word arrays small
            ended = b"" if chunk[end - 1] == 10 else b"\n"  # the last line of a chunk without its newline
            try:
                if found is None:
                    self._lines(chunk[start:end] + ended)
                else:
                    self._feed_arrays(found)
            except Ambiguous as exc:  # the line reader, started afresh on the piece, says where
                raise Ambiguous(exc.rule, start + _ambiguous_at(chunk[start:end] + ended, exc)) from None
            odd_at: int | None = start  # where a malformed number may be: the line reader reads the whole piece
            if found is None:
                g0_words = None
            else:
                odd_at = None if found.odd_at is None else start + found.odd_at - 1
                if g0_words is not None and found.g0_at is not None:
                    g0_words.append(found.g0_at + (start - 1))
            del found  # its arrays are not held while the next piece is read
            if odd is not None and odd_at is not None:
                odd.append((odd_at, end))
        if self.g0_words is not None:
            self.g0_words.append(None if g0_words is None else np.concatenate(g0_words or [np.zeros(0, np.intp)]))

    def feed_lines(self, chunk: bytes) -> None:
        """The line-by-line analysis (any G-code layout)."""
        self._count_markers(chunk)
        self._lines(chunk)

    def _count_markers(self, chunk: bytes) -> None:
        text = b"\n" + chunk
        at = text.find(b";")
        while at >= 0:  # comments are few: find each `;` (memchr), try the markers where one opens a line
            if text[at - 1] == 10:
                found = _MARKERS.match(text, at - 1)
                if found is not None:
                    self.markers[found.lastindex - 1 if found.lastindex else 0] += 1
            end = text.find(b"\n", at)
            at = text.find(b";", end + 1) if end >= 0 else -1

    def _lines(self, chunk: bytes) -> None:
        """Analyse the commands of whole lines one by one; `gcodearrays.Ambiguous` (with the line's offset in
        `chunk`) for a line `gcodearrays.LINE_RULES` refuses."""
        text = b"\n" + chunk
        separated = len(text)  # the start of the first line with a separator: the lines before it come first
        if any(separator in chunk for separator in SEPARATORS):
            separated = min((_separated(chunk, separator) for separator in SEPARATORS), default=separated)
        found: re.Match[bytes] | None = None
        try:
            for found in _COMMAND.finditer(text, 0, separated):
                letter, number, subcode, params = found.groups()
                command = letter.upper() + number.lstrip(b"0").rjust(1, b"0")
                params = params.upper()
                if letter in b"Gg":
                    if subcode is not None and command in _NO_SUBCODE:
                        raise Ambiguous(SUBCODE)
                    if command == b"G20":
                        raise Ambiguous(INCHES)
                if command not in TEXT_COMMANDS and _SECOND_COMMAND.search(_code(params)):
                    raise Ambiguous(SECOND_COMMAND)
                if subcode is None:
                    self._command(command, params)
        except Ambiguous as exc:
            raise Ambiguous(exc.rule, 0 if found is None else found.start()) from None
        if separated < len(text):
            raise Ambiguous(SEPARATOR, separated)
        self._release()

    def _command(self, command: bytes, params: bytes) -> None:
        if command in (b"G0", b"G1", b"G2", b"G3"):
            self._move(params, _ARC.get(command, 0))
        elif command == b"G92":
            self._set_position(params)
        elif command == b"G90":
            self.absolute = self.absolute_e = True
        elif command == b"G91":
            self.absolute = self.absolute_e = False
        elif command == b"G28":
            self._home(params)
        elif command == b"G4":
            self._dwell(params)
        elif command == b"M82":
            self.absolute_e = True
        elif command == b"M83":
            self.absolute_e = False
        elif command in motion.LIMIT_COMMANDS:
            self._release()
            self.planner.set_limits(motion.apply_command(self.planner.limits, command, words_of(params)))

    def _move(self, params: bytes, arc: int = 0) -> None:
        x, y, z = self.pos
        e = self.e
        target_x, target_y, target_z, target_e = x, y, z, e
        words = words_of(params)
        for axis, number in words.items():
            if axis == b"X":
                target_x = number if self.absolute else x + number
            elif axis == b"Y":
                target_y = number if self.absolute else y + number
            elif axis == b"Z":
                target_z = number if self.absolute else z + number
            elif axis == b"E":
                target_e = number if self.absolute_e else e + number
            elif axis == b"F" and number > 0:
                self.feed = number
        dx, dy, dz, de = target_x - x, target_y - y, target_z - z, target_e - e
        if arc and not self.positions_only:
            self.arcs += 1
            nan = math.nan
            x0, y0, x1, y1, i, j, r = (np.array([v]) for v in (
                x, y, target_x, target_y, words.get(b"I", nan), words.get(b"J", nan), words.get(b"R", nan)))
            malformed = gcodearrays.MALFORMED.search(_code(params)) is not None  # the number's refusal comes first
            if centreless(x0, y0, x1, y1, i, j, r)[0] and not malformed:
                raise Ambiguous(CENTRELESS)
            turns = full_turns(np.array([words.get(b"P", nan)])) if not malformed else np.zeros(1)
            clockwise = np.array([arc == 2])
            paths = self._bound_arcs((x0, y0, x1, y1, i, j, r), clockwise, turns,
                                     (np.array([z]), np.array([target_z])), (np.array([e]), np.array([target_e])),
                                     np.array([words.get(b"F", nan)]))
            with_centre = np.array([any(letter in words for letter in (b"I", b"J", b"R"))])
            flat = float(self._arc_path(x0, y0, x1, y1, (i, j, r), clockwise, turns, with_centre, paths)[0])
            length = math.sqrt(flat * flat + dz * dz)
        else:
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
        self.path_seconds += (length or abs(de)) * 60.0 / self.feed
        self.filament += de
        centred = arc and any(letter in words for letter in (b"I", b"J", b"R"))
        if dx or dy or dz or de or centred or not math.isfinite(dx + dy + dz + de):  # any move, travel too (REACH)
            for k, (start, end) in enumerate(((x, target_x), (y, target_y), (z, target_z))):
                # a coordinate that is no number (NaN, or beyond a float) reaches beyond any build volume
                start, end = (v if not math.isnan(v) else math.inf for v in (start, end))
                self.low[k] = min(self.low[k], start, end)
                self.high[k] = max(self.high[k], start, end)
        if de > 0 and (dx or dy or arc or not math.isfinite(dx + dy)):
            if dz:
                self.vase_rise += max(0.0, dz)
            else:
                self.layer_heights.add(round(target_z * 1000))
        self._held.append((dx, dy, dz, de, length, self.feed))
        self.pos = [target_x, target_y, target_z]
        self.e = target_e

    def _release(self) -> None:
        """Hand the moves the line reader collected to the planner (before any array moves or limit change)."""
        if self._held and not self.timing:
            self._held = []
        if self._held:
            dx, dy, dz, de, length, feed = np.array(self._held).T
            self._held = []
            with np.errstate(invalid="ignore", over="ignore"):
                self.planner.add((dx, dy, dz, de), length, feed)

    def _set_position(self, params: bytes) -> None:
        words = words_of(params)
        if not words:
            self.pos = [0.0, 0.0, 0.0]
            self.e = 0.0
        for axis, number in words.items():
            if axis == b"E":
                self.e = number
            elif axis in (b"X", b"Y", b"Z"):
                self.pos[b"XYZ".index(axis)] = number

    def _home(self, params: bytes) -> None:
        for axis in _homed_axes(params):
            self.pos[axis] = 0.0

    def _dwell(self, params: bytes) -> None:
        words = words_of(params)  # S (seconds) overrides P (milliseconds), as in Marlin
        seconds = words[b"S"] if b"S" in words else words[b"P"] / 1000.0 if b"P" in words else 0.0
        self.dwell += seconds
        self.path_seconds += seconds

    def _feed_arrays(self, found: gcodearrays.Scan) -> None:
        """Analyse a piece read into arrays."""
        self.arcs += int(np.count_nonzero(found.arcs))  # `G2` alone too: a line the printer is given as an arc
        controls = [*found.controls, (len(found.arcs) + 1, b"", b"")]
        lines = np.array([line for line, _, _ in controls], dtype=np.int64)
        # where each axis's words stop before each other command, found at once: most commands follow another
        # command or a move with no words between them, and those need no segment
        bounds = np.stack([np.searchsorted(words.lines, lines) for words in found.axes], axis=1).tolist()
        start = [0] * len(found.axes)
        for (_, code, params), ends in zip(controls, bounds, strict=True):
            if ends != start:
                self._segment([Words(w.lines[a:b], w.values[a:b], w.sets[a:b])
                               for w, a, b in zip(found.axes, start, ends, strict=True)], found.arcs)
            if code:
                self._command(code, params)
            start = ends

    def _segment(self, axes: list[Words], arcs: NDArray[np.int8]) -> None:
        """The moves and G92s between two other commands: every axis's words, on lines counted from the piece's."""
        given = [words for words in axes if len(words.lines)]  # `G2 I5 J0` alone is a full circle
        if not given:
            return
        first = min(int(words.lines[0]) for words in given)
        count = max(int(words.lines[-1]) for words in given) + 1 - first
        with np.errstate(over="ignore", invalid="ignore"):  # absurd coordinates make inf: `absurd` reports it
            moves = []
            after: list[NDArray[np.float64]] = []
            for k, words in enumerate(axes[:4]):
                start, absolute = (self.e, self.absolute_e) if k == 3 else (self.pos[k], self.absolute)
                positions, delta = _axis(words.values, words.sets, start, absolute)
                move = np.zeros(count)
                move[words.lines - first] = delta
                moves.append(move)
                after.append(positions)
            dx, dy, dz, de = moves
            length = np.sqrt(dx * dx + dy * dy + dz * dz)
            arc = arcs[first:first + count]
            centred = np.zeros(count, dtype=bool)  # arcs with I, J or R: they move even where they end as they start
            if arc.any():
                for words in axes[5:8]:
                    centred[words.lines - first] = True
                centred &= arc != 0
                length = self._arc_lengths(axes, after, arc, centred, first, count, moves, length)
            feeds = axes[4]
            valid = feeds.values > 0
            runs, feed = _runs(feeds.lines[valid] - first, feeds.values[valid], self.feed)
            per_move = np.repeat(feed, np.diff(np.append(runs, count)))
            self.path_seconds += float(np.sum(np.where(length > 0, length, np.abs(de)) * 60.0 / per_move))
            self.filament += float(np.sum(de))
            moving = (dx != 0) | (dy != 0) | (dz != 0) | (de != 0) | centred  # a NaN move is != 0 too
            if moving.any():  # travel too: the machine goes there whether or not it extrudes (REACH)
                self._reach(axes, after, moving, first, count)
            printing = (de > 0) & ((dx != 0) | (dy != 0) | (arc != 0))
            if printing.any():
                rising = printing & (dz != 0)
                if rising.any():
                    self.vase_rise += float(np.sum(np.maximum(dz[rising], 0.0)))
                    printing &= ~rising
                runs, heights = _runs(axes[2].lines - first, after[2], self.pos[2])
                heights = heights[np.logical_or.reduceat(printing, runs)] * 1000
                self.layer_heights.update(map(round, heights[np.isfinite(heights)].tolist()))
            if self.timing:
                self._release()
                self.planner.add((dx, dy, dz, de), length, per_move)
        for k in range(3):
            if len(after[k]):
                self.pos[k] = float(after[k][-1])
        if len(after[3]):
            self.e = float(after[3][-1])
        self.feed = float(feed[-1])

    def _reach(self, axes: list[Words], after: list[NDArray[np.float64]], moving: NDArray[np.bool_], first: int,
               count: int) -> None:
        """Widen the extent with the start and end points of the `moving` lines (arcs: see `_widen_arcs`).

        A point is the position after a moving line or after the line before one; on each axis that is the value
        of the last word at or before that line, so a word counts when a moving line or the line before one lies
        in its reign (from its line to the next word's), and the position before the piece counts when one lies
        before the axis's first word."""
        wanted = moving.copy()
        wanted[:-1] |= moving[1:]
        marks = np.concatenate(([0], np.cumsum(wanted)))
        for k in range(3):
            lines = axes[k].lines - first
            reigns = marks[np.append(lines[1:], count)] - marks[lines]
            points = after[k][reigns > 0]
            if not len(lines) or marks[lines[0]] > 0 or moving[0]:
                points = np.append(points, self.pos[k])
            # a coordinate that is no number (NaN, or beyond what a float holds) reaches beyond any build volume
            points = np.where(np.isnan(points), np.inf, points)
            if len(points):
                self.low[k] = min(self.low[k], float(points.min()))
                self.high[k] = max(self.high[k], float(points.max()))

    def _arc_lengths(self, axes: list[Words], after: list[NDArray[np.float64]], arc: NDArray[np.int8],
                     centred: NDArray[np.bool_], first: int, count: int, moves: list[NDArray[np.float64]],
                     length: NDArray[np.float64]) -> NDArray[np.float64]:
        """`length` with each arc's own length in place of its chord; the `centred` ones (with I, J or R) widen the
        extent by their whole arc (`REACH`), the others by their end points as a straight move."""
        dx, dy, dz = moves[:3]
        rows = np.flatnonzero(arc)
        ends = []
        for k in range(4):  # the position after each line
            at = np.full(count, np.nan)
            at[axes[k].lines - first] = after[k]
            ends.append(_ffill(at, self.pos[k] if k < 3 else self.e)[rows])
        end_x, end_y, end_z, end_e = ends
        offsets = []
        for words in (*axes[5:9], axes[4]):
            value = np.full(count, np.nan)
            value[words.lines - first] = words.values
            offsets.append(value[rows])
        i, j, r, given_turns, feed = offsets
        x0, y0, x1, y1 = end_x - dx[rows], end_y - dy[rows], end_x, end_y
        if centreless(x0, y0, x1, y1, i, j, r).any():
            raise Ambiguous(CENTRELESS)
        turns = full_turns(given_turns)
        clockwise = arc[rows] == 2
        paths = self._bound_arcs((x0, y0, x1, y1, i, j, r), clockwise, turns, (end_z - moves[2][rows], end_z),
                                 (end_e - moves[3][rows], end_e), feed)
        flat = self._arc_path(x0, y0, x1, y1, (i, j, r), clockwise, turns, centred[rows], paths)
        out = length.copy()
        out[rows] = np.sqrt(flat * flat + dz[rows] * dz[rows])
        return out

    def _arc_path(self, x0: NDArray[np.float64], y0: NDArray[np.float64], x1: NDArray[np.float64],
                  y1: NDArray[np.float64], centre: tuple[NDArray[np.float64], ...], clockwise: NDArray[np.bool_],
                  turns: NDArray[np.float64], centred: NDArray[np.bool_],
                  paths: tuple[NDArray[np.float64], ...]) -> NDArray[np.float64]:
        """The XY path lengths of arcs with (I, J, R) `centre` words and `turns` (`motion.arc_paths` gave
        `paths`); the `centred` ones (with I, J or R) widen the extent by their whole arc and, with full turns, by
        the start's circle (`REACH`), the others count by their end points, as a straight move."""
        i, j, r = centre
        flat = motion.arc_lengths(x0, y0, x1, y1, i, j, r, clockwise)
        if centred.any():
            self._widen_arcs(arc_box(x0[centred], y0[centred], x1[centred], y1[centred], i[centred], j[centred],
                                     r[centred], clockwise[centred]))
            full = centred & (turns > 0)
            if full.any():  # whole circles first: around the start's circle
                cx, cy, radius = paths[:3]
                self._widen_arcs(arc_box(x0[full], y0[full], x0[full], y0[full], cx[full] - x0[full],
                                         cy[full] - y0[full], r[full], clockwise[full]))
                flat = np.where(full, flat + turns * 2 * math.pi * radius, flat)
        return flat

    def _bound_arcs(self, ends: tuple[NDArray[np.float64], ...], clockwise: NDArray[np.bool_],
                    turns: NDArray[np.float64], z: tuple[NDArray[np.float64], NDArray[np.float64]],
                    e: tuple[NDArray[np.float64], NDArray[np.float64]],
                    feed: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        """Count the segments of arcs with these (x0, y0, x1, y1, I, J, R) `ends`, Z and E (start, end) and F
        (NaN where not given), and bound their bytes; ArcGrowth when they go past `arc_room`. Their
        `motion.arc_paths`."""
        x0, y0, x1, y1, i, j, r = ends
        paths = motion.arc_paths(x0, y0, x1, y1, i, j, r, clockwise, turns)
        counts = motion.arc_segment_counts(paths[2], paths[4])
        sizes = np.cumsum(arcwork.lines_size(paths, counts, x1, y1, z, e, feed, absolute=self.absolute,
                                             absolute_e=self.absolute_e))
        if self.arc_bytes + sizes[-1] > self.arc_room:
            raise ArcGrowth(self._bounded + int(np.searchsorted(sizes, self.arc_room - self.arc_bytes, "right")) + 1)
        self.arc_segments += int(counts.sum())
        self.arc_bytes += float(sizes[-1])
        self._bounded += len(counts)
        return paths

    def _widen_arcs(self, box: tuple[NDArray[np.float64], ...]) -> None:
        """Widen the X and Y extent with arcs' bounding boxes (`arc_box`)."""
        low_x, high_x, low_y, high_y = box
        for k, low, high in ((0, low_x, high_x), (1, low_y, high_y)):
            self.low[k] = min(self.low[k], float(low.min()))
            self.high[k] = max(self.high[k], float(high.max()))

    @property
    def absurd(self) -> bool:
        """Whether the moves went beyond what a float holds (a coordinate of 1e309 mm): no print does."""
        return not (math.isfinite(self.path_seconds) and math.isfinite(self.filament))

    @property
    def layers(self) -> int:
        """The slicer's layer markers when it wrote any, else flat printing heights plus the vase's rise."""
        if max(self.markers):
            return max(self.markers)
        heights = sorted(self.layer_heights)
        steps = [b - a for a, b in itertools.pairwise(heights) if b - a >= 20]
        height = (sorted(steps)[len(steps) // 2] / 1000 if steps else heights[0] / 1000 if heights and heights[0] > 0
                  else VASE_LAYER_MM)
        return max(1, len(heights) + round(self.vase_rise / height))

    def result(self) -> GcodeMetadata:
        """The totals; absurd coordinates (beyond what a float holds) leave time and filament unknown."""
        seconds = self.seconds if not self.absurd else math.inf
        extent = tuple(zip(self.low, self.high, strict=True)) if self.low[0] <= self.high[0] else None
        return GcodeMetadata(
            print_time_s=max(1, round(seconds)) if math.isfinite(seconds) else None,
            filament_mm=max(0.0, self.filament) if math.isfinite(self.filament) else None,
            layers=self.layers, extent=extent, arcs=self.arcs,
        )


def finish(stated: GcodeMetadata, computed: GcodeMetadata | None) -> GcodeMetadata:
    """Stated values first, computed ones for the gaps, the conventional defaults for anything left."""
    merged = stated.merged(computed) if computed is not None else stated
    return replace(
        merged,
        print_time_s=merged.print_time_s if merged.print_time_s is not None else 1,
        filament_mm=merged.filament_mm if merged.filament_mm is not None else 1.0,
        layers=merged.layers if merged.layers is not None else 10,
        facets=merged.facets if merged.facets is not None else DEFAULT_FACETS,
    )
