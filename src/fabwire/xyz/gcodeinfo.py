"""What a printer's display needs to know about a G-code: print time, filament and layers.

Slicers state these in comments (at the top for Cura/XYZ, at the end for PrusaSlicer/Slic3r/Simplify3D); when a value
is missing it is computed from the moves themselves.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

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
        )


_NUM = rb"([0-9]+(?:\.[0-9]*)?)"


def _first(pattern: bytes) -> re.Pattern[bytes]:
    return re.compile(pattern, re.MULTILINE | re.IGNORECASE)


# Each list is in order of preference: the XYZ key a previous conversion wrote wins over a slicer's own wording.
_TIME = (
    ("xyz", _first(rb"^;[ \t]*print_time[ \t]*=[ \t]*" + _NUM)),
    ("cura", _first(rb"^;TIME:[ \t]*" + _NUM)),
    ("prusaslicer", _first(rb"^;[ \t]*estimated printing time \(normal mode\)[ \t]*=[ \t]*([^\r\n]+)")),
    ("simplify3d", _first(rb"^;[ \t]*Build time:[ \t]*([^\r\n]+)")),
)
_FILAMENT = (
    ("xyz", _first(rb"^;[ \t]*total_filament[ \t]*=[ \t]*" + _NUM)),
    ("cura", _first(rb"^;Filament used:[ \t]*([0-9.,m \t]+)\r?$")),
    ("prusaslicer", _first(rb"^;[ \t]*filament used \[mm\][ \t]*=[ \t]*([0-9., \t]+)")),
    ("simplify3d", _first(rb"^;[ \t]*Filament length:[ \t]*" + _NUM + rb"[ \t]*mm")),
    ("slic3r", _first(rb"^;[ \t]*filament[ _]used[ \t]*=[ \t]*" + _NUM)),
)
_LAYERS = (
    ("xyz", _first(rb"^;[ \t]*total_layers[ \t]*=[ \t]*([0-9]+)")),
    ("cura", _first(rb"^;LAYER_COUNT:[ \t]*([0-9]+)")),
    ("prusaslicer", _first(rb"^;[ \t]*total layers count[ \t]*=[ \t]*([0-9]+)")),
)
_FACETS = _first(rb"^;[ \t]*facets[ \t]*=[ \t]*([0-9]+)")
_DURATION = re.compile(rb"([0-9.]+)[ \t]*(d|h|m|s)", re.IGNORECASE)
_S3D_DURATION = re.compile(rb"([0-9.]+)[ \t]*(hour|minute|second|sec|min|hr)", re.IGNORECASE)
_UNIT_SECONDS = {b"d": 86400, b"h": 3600, b"m": 60, b"s": 1, b"hour": 3600, b"hr": 3600, b"minute": 60, b"min": 60,
                 b"second": 1, b"sec": 1}
_SLICER_NAMES = (
    (rb"prusaslicer", "prusaslicer"), (rb"superslicer", "prusaslicer"), (rb"cura", "cura"),
    (rb"simplify3d", "simplify3d"), (rb"slic3r", "slic3r"), (rb"xyzprint", "xyz"), (rb"xyzware", "xyz"),
)


ABSURD = 10**18
"""Stands for a stated number too long to be real (hundreds of digits): `intake` refuses the file for it."""


def _whole(raw: bytes) -> int:
    """A stated number rounded to a whole one; ABSURD for one with more digits than any real figure has."""
    value = float(raw) if len(raw.partition(b".")[0]) <= 18 else math.inf
    return round(value) if value < ABSURD else ABSURD


def _duration(text: bytes, units: re.Pattern[bytes]) -> int | None:
    parts = units.findall(text)
    if not parts:
        return None
    total = sum(float(value) * _UNIT_SECONDS[unit.lower()] for value, unit in parts)
    return round(total) if total < ABSURD else ABSURD


def _sum_numbers(text: bytes) -> float | None:
    values = [float(v) for v in re.findall(rb"[0-9]+(?:\.[0-9]*)?", text)]
    return round(sum(values), 6) if values else None


def _search(patterns: Iterable[tuple[str, re.Pattern[bytes]]], windows: Iterable[bytes]) -> tuple[str, bytes] | None:
    for name, pattern in patterns:
        for window in windows:
            found = pattern.search(window)
            if found:
                return name, found.group(1)
    return None


def _comment_lines(window: bytes) -> bytes:
    """The `;` comment lines of a piece of G-code (every pattern here reads comments; moves are most of a file)."""
    return b"\n".join(line for line in window.split(b"\n") if line.lstrip(b" \t")[:1] == b";")


def header_metadata(*windows: bytes) -> GcodeMetadata:
    """The values slicer comments state in the given pieces of a G-code (its head and its tail)."""
    windows = tuple(_comment_lines(window) for window in windows)
    time_s: int | None = None
    filament: float | None = None
    layers: int | None = None
    found = _search(_TIME, windows)
    if found:
        name, raw = found
        if name == "prusaslicer":
            time_s = _duration(raw, _DURATION)
        elif name == "simplify3d":
            time_s = _duration(raw, _S3D_DURATION)
        else:
            time_s = _whole(raw)
    found = _search(_FILAMENT, windows)
    if found:
        name, raw = found
        if name == "cura":
            metres = _sum_numbers(raw)
            filament = None if metres is None else round(metres * 1000.0, 6)
        else:
            filament = _sum_numbers(raw)
    found = _search(_LAYERS, windows)
    if found:
        layers = _whole(found[1])
    facets = _search((("xyz", _FACETS),), windows)
    slicer = None
    lowered = windows[0][:4096].lower() if windows else b""
    for needle, name in _SLICER_NAMES:
        if needle in lowered:
            slicer = name
            break
    return GcodeMetadata(time_s, filament, layers, _whole(facets[1]) if facets else None, slicer)


# G-code as Marlin reads it: a word is a letter, optional blanks, then a decimal number without exponent (so
# `G1X10E5` is X10 E5 and `X1E5` is X1 E5); `;` ends the code of a line, `(...)` is a comment and `*` starts the
# checksum. A command word opens the line, after blanks and an optional N line number.
_VALUE = rb"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)"
_NUMBER = re.compile(_VALUE)
_COMMAND = re.compile(
    rb"\n[ \t]*(?:[Nn][-+]?[0-9]+[ \t]*)?([GgMm])[ \t]*0*([0-9]+)(?![0-9.])([^\n;]*)",
)
_WORD = re.compile(rb"([A-Z])[ \t]*(" + _VALUE + rb")")
_PAREN_COMMENT = re.compile(rb"\([^)]*\)?")
_CONTROL = re.compile(rb"\n(?:G0*(92|90|91|28|4)|M0*(82|83))(?![0-9.])([^\n;]*)")
_AXIS_INDEX = np.full(256, -1, dtype=np.intp)
_AXIS_INDEX[list(b"XYZEF")] = np.arange(5)
_AXIS_FLAGS = bytes(int(_AXIS_INDEX[byte] >= 0) for byte in range(256))
"""bytes.translate table: 1 for an axis letter, 0 for anything else (faster than a numpy lookup)."""
_NOT_CODE = np.zeros(256, dtype=bool)
_NOT_CODE[list(b"(*")] = True
_NUMBER_CHARS = np.zeros(256, dtype=bool)
_NUMBER_CHARS[list(b"0123456789.+-")] = True
_DIGITS = np.zeros(256, dtype=bool)
_DIGITS[list(b"0123456789.")] = True
_MOVE_DIGIT = np.zeros(256, dtype=bool)
_MOVE_DIGIT[list(b"0123")] = True
_VALUE_WIDTH = 24
_POWERS = 10.0 ** np.arange(_VALUE_WIDTH + 1)
_PIECE = 1 << 18
"""Bytes analysed at once: the per-word arrays of a piece this size stay in the CPU's cache."""


def _ffill(values: NDArray[np.float64], start: float) -> NDArray[np.float64]:
    """Each NaN replaced by the last value before it (`start` before the first)."""
    known = ~np.isnan(values)
    index = np.where(known, np.arange(len(values)), -1)
    np.maximum.accumulate(index, out=index)
    return np.where(index >= 0, values[np.maximum(index, 0)], start)


def _parse_numbers(text: bytes, data: NDArray[np.uint8], at: NDArray[np.intp]) -> NDArray[np.float64]:
    """The numbers `_NUMBER` matches at offsets `at` of `text` (viewed as `data`), as float() reads them (NaN
    where there is none).

    Digits are accumulated column by column across all numbers at once: an exact integer mantissa divided by an
    exact power of ten rounds the same way a float parser does, for up to 15 significant digits.
    """
    count = len(at)
    first = data[at]
    signed = (first == 45) | (first == 43)
    mantissa = np.zeros(count, np.int64)
    fraction = np.zeros(count, np.int8)  # small counters: adding booleans to them costs less
    digits = np.zeros(count, np.int8)
    dotted = np.zeros(count, bool)
    active = np.ones(count, bool)
    for column in range(_VALUE_WIDTH):
        byte = first if column == 0 else data[at + column]
        value = byte - np.uint8(48)  # wraps below '0', so one comparison finds the digits
        is_digit = active & (value <= 9)
        is_dot = active & (byte == 46) & ~dotted
        active = is_digit | is_dot | (signed if column == 0 else False)
        if not active.any():
            break
        mantissa = np.where(is_digit, mantissa * 10 + value, mantissa)
        fraction += is_digit & dotted
        digits += is_digit
        dotted |= is_dot
    parsed: NDArray[np.float64] = mantissa / _POWERS[np.minimum(fraction, _VALUE_WIDTH)]
    parsed = np.where(first == 45, -parsed, parsed)
    parsed[digits == 0] = np.nan
    odd = np.flatnonzero((digits > 15) | active)
    for i in odd:  # very long numbers: let the float parser have them
        found = _NUMBER.match(text, int(at[i]))
        parsed[i] = float(found.group(0)) if found else math.nan
    return parsed


def _code(params: bytes) -> bytes:
    """A command's parameters without comments in parentheses and without the checksum."""
    if b"(" in params:
        params = _PAREN_COMMENT.sub(b" ", params)
    return params.partition(b"*")[0]


def _words(params: bytes) -> dict[bytes, float]:
    """Letter -> value of upper-cased parameters; the first word wins when a letter repeats, as in Marlin."""
    words: dict[bytes, float] = {}
    for letter, value in _WORD.findall(_code(params)):
        words.setdefault(letter, float(value))
    return words


class MoveAnalyzer:
    """Computes print time, net filament and layer count from the moves, fed line-aligned chunks in order.

    Time is length / feed rate per move (no acceleration), so it is an estimate on the short side. Ordinary slicer
    output is analysed with array operations; chunks with indented or numbered lines take a line-by-line path.
    """

    def __init__(self) -> None:
        self.pos = [0.0, 0.0, 0.0]
        self.e = 0.0
        self.feed = DEFAULT_FEED_MM_MIN
        self.absolute = True
        self.absolute_e = True
        self.filament = 0.0
        self.seconds = 0.0
        self.layer_heights: set[int] = set()
        """Heights (in µm) at which extruding moves happened."""

    def feed_chunk(self, chunk: bytes) -> None:
        """Analyse whole lines; `chunk` must start at a line start (its end ends its last line)."""
        start = 0
        while start < len(chunk):  # bounded pieces keep the per-word arrays small
            end = chunk.find(b"\n", start + _PIECE) + 1 or len(chunk)
            piece = chunk[start:end]
            if not piece.endswith(b"\n"):  # the last line of a chunk without its newline
                piece += b"\n"
            text = b"\n" + piece.upper()
            if not self._feed_arrays(text):
                self.feed_lines(piece)
            start = end

    def feed_lines(self, chunk: bytes) -> None:
        """The line-by-line analysis (any G-code layout)."""
        for letter, number, params in _COMMAND.findall(b"\n" + chunk):
            self._command(letter.upper() + number.lstrip(b"0").rjust(1, b"0"), params.upper())

    def _command(self, command: bytes, params: bytes) -> None:
        if command in (b"G0", b"G1", b"G2", b"G3"):
            self._move(params)
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

    def _move(self, params: bytes) -> None:
        x, y, z = self.pos
        e = self.e
        target_x, target_y, target_z, target_e = x, y, z, e
        for axis, number in _words(params).items():
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
        length = math.sqrt(dx * dx + dy * dy + dz * dz) or abs(de)
        self.seconds += length * 60.0 / self.feed
        self.filament += de
        if de > 0 and (dx or dy) and math.isfinite(target_z):
            self.layer_heights.add(round(target_z * 1000))
        self.pos = [target_x, target_y, target_z]
        self.e = target_e

    def _set_position(self, params: bytes) -> None:
        words = _words(params)
        if not words:
            self.pos = [0.0, 0.0, 0.0]
            self.e = 0.0
        for axis, number in words.items():
            if axis == b"E":
                self.e = number
            elif axis in (b"X", b"Y", b"Z"):
                self.pos[b"XYZ".index(axis)] = number

    def _home(self, params: bytes) -> None:
        axes = set(re.findall(rb"[XYZ]", _code(params))) or {b"X", b"Y", b"Z"}
        for axis in axes:
            self.pos[b"XYZ".index(axis)] = 0.0

    def _dwell(self, params: bytes) -> None:
        words = _words(params)  # S (seconds) overrides P (milliseconds), as in Marlin
        if b"S" in words:
            self.seconds += words[b"S"]
        elif b"P" in words:
            self.seconds += words[b"P"] / 1000.0

    def _feed_arrays(self, text: bytes) -> bool:
        """Analyse `text` if it is plain enough for array operations, else leave the state alone and say False.

        `text` is upper-cased, starts with a newline and every line starts with its command letter.
        """
        data = np.frombuffer(text + bytes(_VALUE_WIDTH + 4), dtype=np.uint8)
        newlines = np.flatnonzero(data[: len(text)] == 10)
        starts = newlines[:-1] + 1
        ends = newlines[1:]
        if not len(starts):
            return True
        c0, c1, c2, c3 = (data[starts + i] for i in range(4))
        blank1 = (c1 == 32) | (c1 == 9)
        command = (c0 == ord("G")) | (c0 == ord("M"))
        if ((c0 == 32) | (c0 == 9) | (c0 == ord("N")) | (command & (
                blank1 | ((c1 == 48) & (c2 == 48) & (c3 - np.uint8(48) <= 9))))).any():
            return False  # blanks or a number before the command, blanks inside it, or `G001`
        is_move = (c0 == ord("G")) & (
            (_MOVE_DIGIT[c1] & ~_DIGITS[c2]) | ((c1 == ord("0")) & _MOVE_DIGIT[c2] & ~_DIGITS[c3])
        )
        controls: list[tuple[int, bytes, bytes]] = []
        is_set = np.zeros(len(starts), dtype=bool)
        for control_line in np.flatnonzero(command & ~is_move).tolist():  # the few other commands
            found = _CONTROL.match(text, int(starts[control_line]) - 1)
            if found is None:
                continue
            code = b"G" + found.group(1) if found.group(1) else b"M" + found.group(2)
            params = found.group(3)
            if code == b"G92" and _WORD.search(params) and not re.search(rb"[^XYZE0-9.+\- \t]", params):
                is_set[control_line] = True
            else:
                controls.append((control_line, code, params))
        is_row = is_move | is_set
        row_lines = np.flatnonzero(is_row)
        if not len(row_lines) and not controls:
            return True
        row_of_line = np.full(len(starts), -1, dtype=np.int64)
        row_of_line[row_lines] = np.arange(len(row_lines))
        semis = np.flatnonzero(data[: len(text)] == ord(";"))
        semis = np.append(semis, len(text))
        code_end = np.minimum(semis[np.searchsorted(semis, starts)], ends)
        if b"(" in text or b"*" in text:
            odd = np.flatnonzero(_NOT_CODE[data[: len(text)]])
            odd_line = np.searchsorted(starts, odd, side="right") - 1
            if (odd < code_end[odd_line]).any():  # a comment in parentheses or a checksum
                return False
        values = np.full((5, len(row_lines)), np.nan)
        where = np.flatnonzero(np.frombuffer(text.translate(_AXIS_FLAGS), dtype=np.bool_))
        line = np.cumsum(data[: len(text)] == 10, dtype=np.int32)[where].astype(np.intp) - 1
        keep = (line >= 0) & is_row[np.maximum(line, 0)]
        where, line = where[keep], line[keep]
        keep = where < code_end[line]
        where, line = where[keep], line[keep]
        if len(where):
            at = where + 1
            blank = (data[at] == 32) | (data[at] == 9)
            while blank.any():  # blanks between a letter and its number
                at += blank
                blank = (data[at] == 32) | (data[at] == 9)
            numbers = _parse_numbers(text, data, at)
            axis, row = _AXIS_INDEX[data[where]], row_of_line[line]
            known = ~np.isnan(numbers)
            if not known.all():  # bare letters are not words
                axis, row, numbers = axis[known], row[known], numbers[known]
            values[axis, row] = numbers
            if np.count_nonzero(values == values) < len(numbers):  # fewer cells than words (NaN != NaN)
                return False  # a letter repeats within a line
        sets = is_set[row_lines]
        bounds = [0]
        bounds.extend(int(np.searchsorted(row_lines, control[0])) for control in controls)
        bounds.append(len(row_lines))
        for i in range(len(bounds) - 1):
            lo, hi = bounds[i], bounds[i + 1]
            if hi > lo:
                self._segment(values[:, lo:hi], sets[lo:hi])
            if i < len(controls):
                _line, code, params = controls[i]
                self._command(code, params)
        return True

    def _axis(self, given: NDArray[np.float64], sets: NDArray[np.bool_], start: float,
              absolute: bool) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(position after each row, delta of each row) for one axis."""
        if absolute:
            after = _ffill(given, start)
            delta = np.diff(after, prepend=start)
            delta[sets] = 0.0
            return after, delta
        delta = np.where(sets, 0.0, np.nan_to_num(given))
        total = np.cumsum(delta)
        base = np.where(sets, given - total, np.nan)
        return total + _ffill(base, start), delta

    def _segment(self, values: NDArray[np.float64], sets: NDArray[np.bool_]) -> None:
        (x, dx), (y, dy), (z, dz) = (
            self._axis(values[k], sets, self.pos[k], self.absolute) for k in range(3)
        )
        e, de = self._axis(values[3], sets, self.e, self.absolute_e)
        feeds = values[4]
        feeds[feeds <= 0] = np.nan
        feed = _ffill(feeds, self.feed)
        with np.errstate(over="ignore", invalid="ignore"):  # absurd coordinates make inf: `absurd` reports it
            length = np.sqrt(dx * dx + dy * dy + dz * dz)
            length = np.where(length > 0, length, np.abs(de))
            self.seconds += float(np.sum(length * 60.0 / feed))
            self.filament += float(np.sum(de))
        printing = (de > 0) & ((dx != 0) | (dy != 0)) & np.isfinite(z)
        if printing.any():
            heights = z[printing] * 1000
            changes = np.flatnonzero(heights[1:] != heights[:-1]) + 1  # layers are runs: only run starts differ
            self.layer_heights.update(map(round, heights[np.append(0, changes)].tolist()))
        self.pos = [float(x[-1]), float(y[-1]), float(z[-1])]
        self.e = float(e[-1])
        self.feed = float(feed[-1])

    @property
    def absurd(self) -> bool:
        """Whether the moves went beyond what a float holds (a coordinate of 1e309 mm): no print does."""
        return not (math.isfinite(self.seconds) and math.isfinite(self.filament))

    def result(self) -> GcodeMetadata:
        """The totals; absurd coordinates (beyond what a float holds) leave time and filament unknown."""
        return GcodeMetadata(
            print_time_s=max(1, round(self.seconds)) if math.isfinite(self.seconds) else None,
            filament_mm=max(0.0, self.filament) if math.isfinite(self.filament) else None,
            layers=max(1, len(self.layer_heights)),
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
