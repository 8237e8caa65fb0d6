"""One way in for drawings: a file or standard input ('-'), gzip-compressed or not, SVG or Line-us G-code,
told apart by suffix or, without a known suffix, by content. Out come pen lines in machine orientation."""

from __future__ import annotations

import gzip
import hashlib
import io
import sys
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from fabwire.errors import InputError
from fabwire.lineus.kinematics import UNITS_PER_MM
from fabwire.lineus.plot.gcode import parse_gcode_text
from fabwire.lineus.plot.geometry import Polylines, affine, scale_translate
from fabwire.lineus.plot.svg import parse_svg

SVG_UNITS_PER_PX = 25.4 / 96 * UNITS_PER_MM
"""Machine units per SVG px (CSS pixel, 96 per inch)."""
PAGE_ORIGIN = (650.0, 1000.0)
"""Unfitted SVG pages sit with their top-left corner here: the corner of the app drawing area."""
FLATTEN_TOLERANCE = 0.5
"""Largest chord error of a flattened curve on the paper, machine units (0.025 mm; the pen line is ~0.5 mm)."""
MAX_INPUT = 256 << 20
"""Bytes of drawing (after decompression) read at most."""
SVG_SUFFIXES = (".svg", ".svgz")
GCODE_SUFFIXES = (".gcode", ".gc", ".nc", ".txt", ".ngc", ".g")
STDIN = "-"


@dataclass(frozen=True)
class Drawing:
    """A drawing read in: pen lines in machine units and orientation (y up), and where they came from."""

    lines: Polylines
    kind: str
    """'svg' or 'gcode'."""
    name: str
    notes: tuple[str, ...] = ()
    hidden: Polylines = field(default_factory=list)
    """Lines an SVG clip path hides, machine units."""
    empty_reason: str = ""
    """Why the file shows nothing at all, when the reader knows (an SVG viewport of size 0)."""
    data: bytes = b""
    curved: bool = False
    tolerance: float = FLATTEN_TOLERANCE
    """Chord tolerance the curves were flattened with, machine units at real size."""
    digest: str = ""
    """SHA-256 of the bytes as given (before decompression)."""
    svg_text: str = "hershey"
    """How SVG `<text>` was read: 'hershey' (single-stroke letters) or 'outline' (left out, with a note)."""

    def reflattened(self, tolerance: float) -> Drawing:
        """The same SVG with its curves flattened to `tolerance` machine units at real size."""
        if self.kind != "svg":
            return self
        return _svg_drawing(self.name, self.data, self.digest, tolerance, self.svg_text)


def _read_limited(read: Callable[[int], bytes], refusal: str) -> bytes:
    """At most MAX_INPUT bytes, read in pieces so memory follows what is there, not the limit; InputError(`refusal`)
    as soon as there is more, before anything is copied (a gzip bomb costs the limit, not twice it)."""
    out = bytearray()
    while piece := read(min(1 << 20, MAX_INPUT + 1 - len(out))):
        out += piece
        if len(out) > MAX_INPUT:
            raise InputError(refusal)
    return bytes(out)


def _read_bytes(source: str | Path) -> tuple[str, bytes]:
    name = "standard input" if str(source) == STDIN else str(source)
    too_big = f"{name}: larger than {MAX_INPUT >> 20} MB; refusing to read it"
    if str(source) == STDIN:
        return name, _read_limited(sys.stdin.buffer.read, too_big)
    try:
        with Path(source).open("rb") as fh:
            return name, _read_limited(fh.read, too_big)
    except FileNotFoundError as exc:
        raise InputError(f"{name}: no such file") from exc
    except IsADirectoryError as exc:
        raise InputError(f"{name}: is a directory, not a drawing") from exc
    except OSError as exc:
        raise InputError(f"{name}: cannot read ({exc.strerror or exc})") from exc


def _gunzip(name: str, data: bytes) -> bytes:
    try:
        with gzip.GzipFile(fileobj=io.BytesIO(data)) as fh:
            return _read_limited(fh.read, f"{name}: expands to more than {MAX_INPUT >> 20} MB; refusing to read it")
    except (OSError, EOFError, zlib.error) as exc:
        raise InputError(f"{name}: not a readable gzip file ({exc})") from exc


def _kind(name: str, data: bytes) -> str:
    suffix = Path(name).suffix.lower() if name != "standard input" else ""
    if suffix in SVG_SUFFIXES:
        return "svg"
    if suffix in GCODE_SUFFIXES:
        return "gcode"
    head = data[:4096].lstrip(b"\xef\xbb\xbf \t\r\n")
    if head.startswith(b"<"):
        return "svg"
    if head[:1].upper() in (b"G", b"M", b"(", b";") or not head:
        return "gcode"
    what = f"unknown drawing type {suffix!r}" if suffix else "neither SVG nor G-code"
    raise InputError(f"{name}: {what}; give an .svg, .svgz or Line-us .gcode drawing")


def _svg_drawing(name: str, data: bytes, digest: str, tolerance: float, svg_text: str) -> Drawing:
    try:
        drawing = parse_svg(data, tolerance=tolerance / SVG_UNITS_PER_PX, text=svg_text)
    except InputError as exc:
        raise InputError(str(exc).replace("SVG data", name, 1)) from exc
    notes = [f"left out {count} {tag} element(s): convert them to paths to draw them"
             for tag, count in sorted(drawing.skipped.items())]
    notes.extend(drawing.notes)
    m = scale_translate(SVG_UNITS_PER_PX, PAGE_ORIGIN[0], PAGE_ORIGIN[1], flip_y=True)
    return Drawing(affine(drawing.lines, m), "svg", name, tuple(notes), affine(drawing.hidden, m),
                   drawing.empty_reason, data, drawing.curved, tolerance, digest, svg_text)


def read_drawing(source: str | Path, *, svg_text: str = "hershey") -> Drawing:
    """Read a drawing file, or standard input for '-'.

    SVG comes out at real size (96 px per inch) with its page's top-left corner at the app drawing area's corner
    (650, 1000), curves within FLATTEN_TOLERANCE, its `<text>` as `svg_text` says (see parse_svg); G-code is
    already in machine units. InputError for unreadable, unknown or empty drawings.
    """
    name, raw = _read_bytes(source)
    return drawing_from_bytes(name, raw, svg_text=svg_text)


def drawing_from_bytes(name: str, raw: bytes, *, svg_text: str = "hershey") -> Drawing:
    """`read_drawing` for bytes already in memory; `name` (its file name) picks the type and names it in errors."""
    if len(raw) > MAX_INPUT:
        raise InputError(f"{name}: larger than {MAX_INPUT >> 20} MB; refusing to read it")
    digest = hashlib.sha256(raw).hexdigest()
    data = _gunzip(name, raw) if raw[:2] == b"\x1f\x8b" else raw
    if _kind(name, data) == "svg":
        drawing = _svg_drawing(name, data, digest, FLATTEN_TOLERANCE, svg_text)
    else:
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise InputError(f"{name}: not a text G-code file") from exc
        notes: list[str] = []
        drawing = Drawing(parse_gcode_text(text, name=name, notes=notes), "gcode", name, tuple(notes), digest=digest)
    if not drawing.lines:
        why = drawing.empty_reason or (
            "no shape in it has a visible stroke or fill" if drawing.kind == "svg" else "it has no pen-down moves")
        also = f" ({'; '.join(drawing.notes)})" if drawing.notes else ""
        raise InputError(f"{name}: nothing to draw: {why}{also}")
    return drawing

