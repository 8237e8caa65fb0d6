"""The figures slicers state in their G-code comments: print time, filament length and layer count.

One table, `WORDINGS`: each row is one slicer's wording of one figure, how its number reads (seconds, a duration
with units, minutes, millimetres, metres, a count) and the public source that documents it. Rows are tried in
order; the first row that matches a window (the head or the tail of the file) gives the figure.

A stated figure is believed only when it could be real: Cura's header placeholders (CuraEngine run without its
front end leaves `;TIME:6666`, `;Filament used: 0m` and `;MINX:2.14748e+06`), zeros and values no print has are
set aside with a note saying why, and the moves are used instead.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

Figure = Literal["time", "filament", "layers"]
Unit = Literal["seconds", "duration", "minutes", "mm", "metres", "count"]

MAX_PRINT_S = 90 * 86400
"""Longest print time believed: the longest real jobs take days, not months."""
MAX_FILAMENT_MM = 10_000_000.0
"""Most filament believed: 10 km, fifty spools; a da Vinci cartridge holds 200-300 m."""
MAX_COUNT = 100_000_000
"""Most layers or facets believed (a 300 mm print at 0.01 mm is 30,000 layers)."""
ABSURD = 10**18
"""Stands for a stated number too long to be real (hundreds of digits)."""

_NUMBER = rb"[0-9]+(?:\.[0-9]*)?|\.[0-9]+"
_EXPONENT = re.compile(rb"[0-9.][eE][-+]?[0-9]")
"""A number written with an exponent (`1e5`, `2.5E+1`): no slicer of `WORDINGS` writes one, and the plain decimal
reading takes `1e5m` for 5 m, so such a figure is set aside (not believed) and computed from the moves."""


@dataclass(frozen=True, slots=True)
class Wording:
    """One slicer's wording of one figure: `pattern` captures the value text, `unit` says how it reads."""

    figure: Figure
    slicer: str
    pattern: re.Pattern[bytes]
    unit: Unit
    source: str
    every: bool = False
    """Sum every matching line (one line per extruder), not just the first."""


def _w(figure: Figure, slicer: str, pattern: bytes, unit: Unit, source: str, *, every: bool = False) -> Wording:
    return Wording(figure, slicer, re.compile(rb"^;[ \t]*" + pattern + rb"([^\r\n]*)", re.MULTILINE | re.IGNORECASE),
                   unit, source, every)


_DSF = "Duet3D DuetSoftwareFramework, DuetControlServer Settings.cs (PrintTimeFilters / FilamentFilters)"
_MOONRAKER = "Arksine/moonraker, components/file_manager/metadata.py"
_PRUSA = "prusa3d/PrusaSlicer, src/libslic3r/GCode/GCodeProcessor.cpp (the end block it writes)"
_CURA = "Ultimaker/CuraEngine, src/FffGcodeWriter.cpp and src/gcodeExport.cpp (header it writes)"
_CURA15 = "Ultimaker/Cura 15.04, Cura/util/sliceEngine.py getPrintTime() and the start G-code's ;Print time:"
_BAMBU = "bambulab/BambuStudio and SoftFever/OrcaSlicer header block (as moonraker's metadata.py reads it)"

WORDINGS: tuple[Wording, ...] = (
    # A previous conversion's own XYZ keys (XYZprint, XYZmaker, miniMover) win over any slicer wording.
    _w("time", "xyz", rb"print_time[ \t]*=[ \t]*", "seconds", "miniMover docs; XYZprint .3w headers (seconds)"),
    _w("filament", "xyz", rb"total_filament[ \t]*=[ \t]*", "mm", "miniMover docs; XYZprint .3w headers (mm)"),
    _w("layers", "xyz", rb"total_layers[ \t]*=[ \t]*", "count", "miniMover docs; XYZprint .3w headers"),
    # PrusaSlicer, SuperSlicer, OrcaSlicer, BambuStudio: the end block (before the config block).
    _w("time", "prusaslicer", rb"estimated printing time \(normal mode\)[ \t]*=[ \t]*", "duration", _PRUSA),
    _w("filament", "prusaslicer", rb"filament used \[mm\][ \t]*=[ \t]*", "mm", _PRUSA),
    _w("layers", "prusaslicer", rb"total layers count[ \t]*=[ \t]*", "count", _MOONRAKER + " (PrusaSlicer)"),
    # BambuStudio / OrcaSlicer: the header block.
    _w("time", "bambustudio", rb"model printing time:[^;\r\n]*;[ \t]*total estimated time:[ \t]*", "duration",
       _BAMBU),
    _w("filament", "bambustudio", rb"total filament length \[mm\][ \t]*:[ \t]*", "mm", _BAMBU),
    _w("layers", "bambustudio", rb"total layer number:[ \t]*", "count", _BAMBU),
    # Cura 4-5 (CuraEngine as the Cura front end fills its header), and the Griffin header flavour.
    _w("time", "cura", rb"TIME:[ \t]*", "seconds", _CURA + "; " + _DSF),
    _w("time", "cura", rb"PRINT\.TIME:[ \t]*", "seconds", _CURA + " (Griffin header)"),
    _w("filament", "cura", rb"Filament used:[ \t]*", "metres", _CURA + "; " + _MOONRAKER + " (Cura)"),
    _w("layers", "cura", rb"LAYER_COUNT:[ \t]*", "count", _CURA),
    # Cura 15.x (the legacy Cura with its own start G-code template); Fusion 360 writes Cura's words too.
    _w("time", "cura15", rb"Print time:[ \t]*(?=[0-9.]+[ \t]*(?:hours?|minutes?))", "duration", _CURA15),
    _w("layers", "cura15", rb"Layer count:[ \t]*", "count",
       "Ultimaker/CuraEngine 15.04, gcodeExport (;Layer count:); Raise3D ideaMaker header (;Layer Count:)"),
    _w("layers", "fusion360", rb"NUM_LAYERS:?[ \t]*", "count", _DSF + " (NumLayersFilters; test case Fusion360)"),
    # Simplify3D (4.x and 5.x wordings).
    _w("time", "simplify3d", rb"Build time:[ \t]*", "duration", _DSF + "; " + _MOONRAKER + " (Simplify3D)"),
    _w("filament", "simplify3d", rb"(?:Filament length|Material Length):[ \t]*(?=[0-9.]+[ \t]*mm)", "mm",
       _MOONRAKER + " (Simplify3D 4 and 5)"),
    # ideaMaker (Raise3D; has da Vinci profiles).
    _w("time", "ideamaker", rb"Print Time:[ \t]*(?=[0-9.]+[ \t]*s?[ \t]*$)", "seconds",
       _DSF + " (print time:, IdeaMaker v4); " + _MOONRAKER + " (IdeaMaker)"),
    _w("filament", "ideamaker", rb"Material#[0-9]+ Used:[ \t]*", "mm", _DSF + " (material#n, IdeaMaker)", every=True),
    # KISSlicer (1.x and 2.x).
    _w("time", "kisslicer", rb"Calculated-during-export Build Time:[ \t]*", "minutes", _MOONRAKER + " (KISSlicer)"),
    _w("time", "kisslicer", rb"Total estimated \(pre-cool\) minutes:[ \t]*", "minutes", _DSF + " (KISSlicer v2.0)"),
    _w("filament", "kisslicer", rb"Ext #[0-9]+[ \t]*=[ \t]*", "mm", _DSF + " (KISSlicer v2.0); " + _MOONRAKER,
       every=True),
    # Slic3r (the original and Slic3r PE before it became PrusaSlicer).
    _w("filament", "slic3r", rb"filament used[ \t]*=[ \t]*(?=[0-9.]+[ \t]*mm)", "mm", _MOONRAKER + " (Slic3r PE)"),
    _w("filament", "slic3r", rb"filament_length_m[ \t]*=[ \t]*", "metres", _MOONRAKER + " (Slic3r)"),
    _w("filament", "minimover", rb"filament_used[ \t]*=[ \t]*", "mm", "miniMover G-code keys (; filament_used = mm)"),
    # Kiri:Moto (Grid.Space; exports for the da Vinci mini w).
    _w("time", "kirimoto", rb"--- print time:[ \t]*", "seconds", _MOONRAKER + " (KiriMoto)"),
    _w("filament", "kirimoto", rb"--- filament used:[ \t]*(?=[0-9.]+[ \t]*mm)", "mm", _MOONRAKER + " (KiriMoto)"),
    # IceSL (INRIA).
    _w("time", "icesl", rb"estimated_print_time_s[ \t]*:[ \t]*", "seconds", _MOONRAKER + " (IceSL)"),
    _w("filament", "icesl", rb"filament_used_mm[ \t]*:[ \t]*", "mm", _MOONRAKER + " (IceSL)"),
    _w("layers", "icesl", rb"layer_count[ \t]*:[ \t]*", "count", _MOONRAKER + " (IceSL)"),
)
"""Every wording read, in order of preference."""

SLICER_NAMES: tuple[tuple[bytes, str], ...] = (
    (b"prusaslicer", "prusaslicer"), (b"superslicer", "superslicer"), (b"orcaslicer", "orcaslicer"),
    (b"bambustudio", "bambustudio"), (b"ideamaker", "ideamaker"), (b"kisslicer", "kisslicer"),
    (b"kiri:moto", "kirimoto"), (b"<icesl", "icesl"), (b"fusion 360", "fusion360"), (b"simplify3d", "simplify3d"),
    (b"cura_steamengine 15.", "cura15"), (b"cura", "cura"), (b"slic3r", "slic3r"), (b"xyzprint", "xyz"),
    (b"xyzware", "xyz"), (b"xyzmaker", "xyz"),
)
"""Needles (lower case) in the first comments that name the slicer, most specific first."""

_CURA_PLACEHOLDER = re.compile(rb"^;(?:MIN|MAX)[XYZ]:[ \t]*-?2\.14748e\+0?6", re.MULTILINE)
"""CuraEngine's unfilled bounding box (INT32_MAX µm): the header was never filled in by the Cura front end."""
_DURATION_PART = re.compile(
    rb"(" + _NUMBER + rb")[ \t]*(days?|d|hours?|hrs?|h|minutes?|mins?|m|seconds?|secs?|s)(?![a-z])", re.IGNORECASE)
_CLOCK = re.compile(rb"^[ \t]*([0-9]+):([0-5]?[0-9])(?::([0-5]?[0-9](?:\.[0-9]*)?))?(?![0-9])")
_METRES = re.compile(rb"(" + _NUMBER + rb")[ \t]*m(?![a-z])", re.IGNORECASE)
_ANY_NUMBER = re.compile(_NUMBER)


def _seconds_of_unit(unit: bytes) -> int:
    word = unit.lower()
    for prefix, seconds in ((b"d", 86400), (b"h", 3600), (b"mi", 60), (b"m", 60), (b"s", 1)):
        if word.startswith(prefix):
            return seconds
    return 1


def _finite(value: float) -> float:
    return value if math.isfinite(value) and value < ABSURD else float(ABSURD)


def _float(raw: bytes) -> float:
    """A number as written; ABSURD for one with more digits than any real figure has."""
    return float(raw) if len(raw.partition(b".")[0]) <= 18 else float(ABSURD)


def read_value(text: bytes, unit: Unit) -> float | None:
    """The figure `text` states in `unit`, as seconds, millimetres or a count; None when it holds no number.

    Durations read `1d 2h 3m 4s`, `1 hour 23 minutes`, `2h 5.5m`, `1:02:03` and a bare number as seconds.
    Metres read `1.234m` and sum extruder lists (`1m, 0.5m`); a figure in grams only is no length (None).
    """
    if unit == "duration":
        clock = _CLOCK.match(text)
        if clock:
            hours, minutes, seconds = clock.groups()
            return _finite(float(hours) * 3600 + float(minutes) * 60 + float(seconds or 0))
        parts = _DURATION_PART.findall(text)
        if parts:
            return _finite(sum(_float(value) * _seconds_of_unit(word) for value, word in parts))
        bare = re.match(rb"[ \t]*(" + _NUMBER + rb")[ \t]*$", text)
        return _finite(_float(bare.group(1))) if bare else None
    if unit == "metres":
        metres = [_float(v) for v in _METRES.findall(text)]
        if not metres:
            bare = re.match(rb"[ \t]*(" + _NUMBER + rb")[ \t]*$", text)
            metres = [_float(bare.group(1))] if bare else []
        return _finite(round(sum(metres) * 1000.0, 6)) if metres else None
    numbers = _ANY_NUMBER.findall(text)
    if not numbers:
        return None
    if unit == "mm":
        stop = re.search(rb"\(|[0-9.][ \t]*(?:cm|m\b|g\b)", text)  # `1234.5mm (3.0cm3)`: the length only
        head = text[:stop.start() + 1] if stop and stop.start() > 0 else text
        values = [_float(v) for v in _ANY_NUMBER.findall(head)] or [_float(numbers[0])]
        return _finite(round(sum(values), 6))
    value = _float(numbers[0])
    if unit == "minutes":
        return _finite(value * 60.0)
    return _finite(value)


@dataclass(frozen=True, slots=True)
class Stated:
    """What the comments of a G-code state, and what was set aside (figure -> reason)."""

    time_s: int | None = None
    filament_mm: float | None = None
    layers: int | None = None
    slicer: str | None = None
    rejected: tuple[tuple[Figure, str], ...] = ()
    wordings: tuple[tuple[Figure, Wording], ...] = ()
    """The row that gave each believed figure."""


UNREADABLE: tuple[tuple[re.Pattern[bytes], str, str], ...] = (
    (_EXPONENT, "a number with an exponent, which no slicer writes and readers take differently",
     "C strtod(3) reads 3.5e3 as 3500, a reader of plain numbers as 3.5"),
    (re.compile(rb"[{\[<%$][ \t]*[A-Za-z_]"), "a placeholder the slicer never filled in",
     "PrusaSlicer/Slic3r [print_time] and {print_time}, Cura {print_time} and %TIME% in start G-code templates"),
    (re.compile(rb"-[ \t]*[0-9.]"), "a negative figure, which no print has",
     "a duration, a length or a count is not negative; CuraEngine writes ;TIME:-1 when it has no estimate"),
    (re.compile(rb"[0-9](?:[,'\xa0]|\xc2\xa0|\xe2\x80\xaf)[0-9]{3}(?![0-9])"),  # U+00A0, U+202F in UTF-8
     "digits grouped by a separator (1,234), which readers take as 1 or as 1234",
     "CLDR number formats: ',' and U+00A0 group thousands in some locales, ',' is the decimal mark in others"),
)
"""Stated figures that are not read as numbers: (the form, why it is set aside, source). A wording whose text has
one of these forms, or no number at all, is set aside with that reason and the figure is computed instead."""


def _unreadable(text: bytes) -> str | None:
    """Why the text after a wording is no figure (`UNREADABLE`, or no number in it), None when it reads."""
    for form, why, _source in UNREADABLE:
        if form.search(text):
            return why
    return None if _ANY_NUMBER.search(text) else "no number"


def _find(wording: Wording, windows: Sequence[bytes]) -> tuple[bytes, float | str] | None:
    """(the matched text, its value, or why it is no figure: `_unreadable`) for the first window where `wording`
    matches."""
    for window in windows:
        found = [m for m in (wording.pattern.finditer(window) if wording.every else [wording.pattern.search(window)])
                 if m is not None]
        if not found:
            continue
        for match in found:
            why = _unreadable(match.group(1))
            if why is not None:
                return match.group(0).strip(), why
        values = [(m.group(0), read_value(m.group(1), wording.unit)) for m in found]
        read = [(text, v) for text, v in values if v is not None]
        if read:
            return read[0][0].strip(), sum(v for _t, v in read)
        return found[0].group(0).strip(), "no number"
    return None


def _implausible(figure: Figure, value: float | str) -> str | None:
    limit = {"time": MAX_PRINT_S, "filament": MAX_FILAMENT_MM, "layers": MAX_COUNT}[figure]
    if isinstance(value, str):
        return value
    if value <= 0:
        return "zero"
    if value > limit:
        return "more than any print" + (" takes" if figure == "time" else " has")
    return None


def slicer_name(window: bytes) -> str | None:
    lowered = window[:4096].lower()
    for needle, name in SLICER_NAMES:
        if needle in lowered:
            return name
    return None


def stated_figures(windows: Sequence[bytes]) -> Stated:
    """The figures the comment lines of `windows` (head first, then tail) state and believe."""
    placeholder = any(_CURA_PLACEHOLDER.search(window) for window in windows)
    found: dict[Figure, float] = {}
    rows: list[tuple[Figure, Wording]] = []
    rejected: list[tuple[Figure, str]] = []
    for wording in WORDINGS:
        if wording.figure in found:
            continue
        hit = _find(wording, windows)
        if hit is None:
            continue
        text, value = hit
        shown = text.decode("utf-8", "replace")[:80]
        if placeholder and wording.slicer == "cura" and wording.figure != "layers":
            rejected.append((wording.figure, f"`{shown}` is CuraEngine's placeholder (its header was never "
                                             "filled in)"))
            continue
        why = _implausible(wording.figure, value)
        if why is not None:
            rejected.append((wording.figure, f"`{shown}` states {why}"))
            continue
        found[wording.figure] = float(value)
        rows.append((wording.figure, wording))
    rejected = list(dict.fromkeys((figure, why) for figure, why in rejected if figure not in found))
    time_s = found.get("time")
    layers = found.get("layers")
    return Stated(
        time_s=None if time_s is None else round(time_s),
        filament_mm=found.get("filament"),
        layers=None if layers is None else round(layers),
        slicer=slicer_name(windows[0]) if windows else None,
        rejected=tuple(rejected),
        wordings=tuple(rows),
    )
