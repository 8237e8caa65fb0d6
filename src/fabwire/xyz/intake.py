"""What a file handed to the XYZ side is, and its G-code text as the printer should see it.

One answer for `convert`, `info`, `print` and the simulator's file check: a `.3w`; base64 text of a `.3w` or of
G-code with its XYZ header (what XYZware imports and web slicers such as Kiri:Moto export for the mini w); G-code
text (UTF-8 with or without BOM, ASCII, Latin-1 comments; LF, CRLF or CR-only line ends; with or without a final
newline); or something else, named in words with what to do about it (binary G-code, 3MF projects and other zips,
gzip, images, STL models, PDFs, SVG/XML, UTF-16 text, binary junk).
"""

from __future__ import annotations

import base64
import binascii
import contextlib
import enum
import os
import re
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path
from typing import BinaryIO

import numpy as np

from fabwire import units
from fabwire.errors import InputError
from fabwire.xyz.gcodeinfo import GcodeMetadata, MoveAnalyzer, finish, header_metadata

MAGIC = b"3DPFNKG13WTW"
"""The .3w signature (reference §5.1)."""
_BASE64_TEXT = re.compile(rb"[A-Za-z0-9+/=\s]{16,}")
BOM = b"\xef\xbb\xbf"
SNIFF = 1 << 16
"""Bytes read to decide what a file is."""
CHUNK = 1 << 22
MAX_LINE = 1 << 20
"""Longest G-code line held in memory (firmware line buffers hold about 100 bytes; slicers wrap thumbnails at 78)."""

Progress = Callable[[int, int], None]
"""Called with (bytes of input done, input size)."""

_CONTROL = re.compile(rb"[\x00-\x08\x0e-\x1a\x1c-\x1f\x7f]")
_COMMAND_LINE = re.compile(rb"^[ \t]*(?:[Nn][0-9]+[ \t]*)?[GgMmTt][ \t]*[0-9]", re.MULTILINE)
_WHITESPACE = b" \t\r\n"


class Kind(enum.Enum):
    """What a file is, as far as a da Vinci printer is concerned."""

    THREEW = ".3w print file"
    THREEW_BASE64 = "base64-text .3w print file"
    GCODE = "G-code text"
    GCODE_BASE64 = "base64-text G-code"
    BINARY_GCODE = "binary G-code"
    PROJECT_3MF = "3MF project"
    ZIP = "zip archive"
    GZIP = "gzip-compressed file"
    IMAGE = "image"
    STL = "STL model"
    PDF = "PDF document"
    XML = "SVG/XML document"
    UTF16 = "UTF-16 text"
    BINARY = "binary data"
    EMPTY = "empty file"

    @property
    def printable(self) -> bool:
        """A printer can be given it (after conversion for G-code, after decoding for base64)."""
        return self in (Kind.THREEW, Kind.THREEW_BASE64, Kind.GCODE, Kind.GCODE_BASE64)

    @property
    def base64(self) -> bool:
        return self in (Kind.THREEW_BASE64, Kind.GCODE_BASE64)

    @property
    def decoded(self) -> Kind:
        """What the file is once its base64 text is decoded."""
        return {Kind.THREEW_BASE64: Kind.THREEW, Kind.GCODE_BASE64: Kind.GCODE}.get(self, self)


_ADVICE = {
    Kind.BINARY_GCODE: "turn off Binary G-code in PrusaSlicer's printer settings (Printer Settings > General) and "
                       "export again",
    Kind.PROJECT_3MF: "not G-code: export G-code from the slicer",
    Kind.ZIP: "not G-code: unpack it and give the .gcode inside",
    Kind.GZIP: "unpack it first (gunzip) and give the G-code inside",
    Kind.IMAGE: "not G-code: slice a model to G-code first",
    Kind.STL: "a 3D model, not G-code: slice it to G-code first",
    Kind.PDF: "not G-code or a .3w print file",
    Kind.XML: "not G-code or a .3w print file (drawings are for a plotter)",
    Kind.UTF16: "save the G-code as UTF-8 or ASCII and try again",
    Kind.BINARY: "not G-code or a .3w print file",
    Kind.EMPTY: "nothing to print",
}
_IMAGES = ((b"\x89PNG\r\n\x1a\n", "PNG"), (b"\xff\xd8\xff", "JPEG"), (b"GIF87a", "GIF"), (b"GIF89a", "GIF"),
           (b"II*\x00", "TIFF"), (b"MM\x00*", "TIFF"))


def identify(head: bytes, size: int | None = None) -> Kind:
    """What the file that starts with `head` (its first `SNIFF` bytes or more) is; `size` is its whole length."""
    if not head:
        return Kind.EMPTY
    if head.startswith(MAGIC):
        return Kind.THREEW
    if _BASE64_TEXT.fullmatch(head[:4096]):
        inner = _base64_kind(head)
        if inner is not None:
            return inner
    if head.startswith(b"GCDE"):
        return Kind.BINARY_GCODE
    if head.startswith((b"PK\x03\x04", b"PK\x05\x06")):
        return Kind.PROJECT_3MF if b"3D/3dmodel.model" in head or b"[Content_Types].xml" in head else Kind.ZIP
    if head.startswith(b"\x1f\x8b"):
        return Kind.GZIP
    if head.startswith((b"\xff\xfe", b"\xfe\xff")):
        return Kind.UTF16
    if (head.startswith(b"RIFF") and head[8:12] == b"WEBP") or any(head.startswith(m) for m, _ in _IMAGES):
        return Kind.IMAGE
    if head.startswith(b"%PDF"):
        return Kind.PDF
    if size is not None and len(head) >= 84 and size == 84 + 50 * int.from_bytes(head[80:84], "little"):
        return Kind.STL
    text = head.removeprefix(BOM)
    if text[:6].lower() == b"solid " and b"facet" in text[:4096]:
        return Kind.STL
    if text.lstrip().startswith((b"<?xml", b"<svg", b"<!DOCTYPE", b"<html")):
        return Kind.XML
    if _CONTROL.search(head):
        return Kind.BINARY
    return Kind.GCODE


def _base64_kind(head: bytes) -> Kind | None:
    """THREEW_BASE64 or GCODE_BASE64 when `head` is base64 text of a .3w or of G-code, else None."""
    text = head.translate(None, _WHITESPACE)
    try:
        decoded = base64.b64decode(text[:len(text) - len(text) % 4], validate=True)
    except binascii.Error:
        return None
    if decoded.startswith(MAGIC):
        return Kind.THREEW_BASE64
    plain = decoded.removeprefix(BOM)
    if identify(decoded[:SNIFF]) is Kind.GCODE and (plain.lstrip().startswith(b";") or has_commands(plain)):
        return Kind.GCODE_BASE64
    return None


def _image_name(head: bytes) -> str:
    for magic, name in _IMAGES:
        if head.startswith(magic):
            return name
    return "WebP"


def refusal(kind: Kind, name: str, head: bytes = b"") -> InputError:
    """The one-line error for a file of `kind` that cannot be printed or converted."""
    what = f"an image ({_image_name(head)})" if kind is Kind.IMAGE else {
        Kind.ZIP: "a zip archive", Kind.PDF: "a PDF document", Kind.STL: "an STL model",
        Kind.XML: "an SVG/XML document", Kind.BINARY: "binary data", Kind.EMPTY: "empty",
        Kind.PROJECT_3MF: "a 3MF project", Kind.GZIP: "gzip-compressed", Kind.UTF16: "UTF-16 text",
        Kind.BINARY_GCODE: "binary G-code (.bgcode)",
    }.get(kind, kind.value)
    advice = _ADVICE.get(kind, "it cannot be printed")
    return InputError(f"{name} is {what}{', ' if advice.startswith('not ') else ': '}{advice}")


def open_input(path: Path, name: str | None = None) -> BinaryIO:
    """The file opened for reading; an unreadable one is an InputError naming it (`name`, default the path)."""
    try:
        return Path(path).open("rb")
    except OSError as exc:
        raise InputError(f"cannot read {name or path}: {exc.strerror}") from exc


STDIN = "-"
"""The file name that means standard input."""
STDIN_NAME = "standard input"
MAX_STDIN = 4 << 30
"""Most bytes taken from standard input (a pipe may never end; a print file is far smaller)."""


@contextlib.contextmanager
def input_file(path: Path) -> Iterator[tuple[Path, str]]:
    """(a file to read, its name for messages): `path` itself, or for `-` standard input copied in CHUNK pieces to
    a temporary file, so a piped G-code or .3w is read like any other file with memory bounded by CHUNK."""
    if str(path) != STDIN:
        yield path, str(path)
        return
    import sys

    with tempfile.TemporaryDirectory() as scratch:
        spooled = Path(scratch) / "stdin"
        try:
            with spooled.open("wb") as out:
                while block := sys.stdin.buffer.read(CHUNK):
                    if out.tell() + len(block) > MAX_STDIN:
                        raise InputError(f"{STDIN_NAME} is over {MAX_STDIN >> 30} GiB: not a print file that ends")
                    out.write(block)
        except OSError as exc:
            raise InputError(f"cannot read {STDIN_NAME}: {exc.strerror or exc}") from exc
        yield spooled, STDIN_NAME


def sniff(path: Path, name: str | None = None) -> tuple[Kind, bytes]:
    """(what the file is, its first bytes); an unreadable file is an InputError (naming `name` or `path`)."""
    with open_input(path, name) as handle:
        head = handle.read(SNIFF)
        size = handle.seek(0, 2)
    return identify(head, size), head


def require_printable(kind: Kind, name: str, head: bytes) -> Kind:
    """`kind` if a printer can take it (maybe after conversion), else the refusal for it."""
    if not kind.printable:
        raise refusal(kind, name, head)
    return kind


# ------------------------------------------------------------------------------------------- base64 .3w


def decode_base64_into(src: BinaryIO, out: BinaryIO, name: str) -> None:
    """Decode base64 text (any line wrapping) from `src` into `out`, in bounded pieces."""
    carry = b""
    while block := src.read(CHUNK):
        data = carry + block.translate(None, _WHITESPACE)
        cut = len(data) - len(data) % 4
        carry = data[cut:]
        try:
            out.write(base64.b64decode(data[:cut], validate=True))
        except binascii.Error as exc:
            raise InputError(f"{name} is a corrupt base64 .3w ({exc})") from exc
    if carry:
        raise InputError(f"{name} is a truncated base64 .3w ({len(carry)} stray characters at the end)")


def decode_base64(data: bytes, name: str) -> bytes:
    out = BytesIO()
    decode_base64_into(BytesIO(data), out, name)
    return out.getvalue()


@contextlib.contextmanager
def decoded_file(path: Path, kind: Kind) -> Iterator[BinaryIO]:
    """The file's own bytes, or for a base64 kind its decoded bytes (in a temporary file)."""
    with open_input(path) as handle:
        if not kind.base64:
            yield handle
            return
        with tempfile.TemporaryFile() as decoded:
            decode_base64_into(handle, decoded, str(path))
            decoded.seek(0)
            yield decoded


@contextlib.contextmanager
def decoded_path(path: Path, kind: Kind) -> Iterator[Path]:
    """`path` itself, or for a base64 kind a temporary file holding the decoded bytes."""
    if not kind.base64:
        yield path
        return
    with tempfile.TemporaryDirectory() as scratch:
        target = Path(scratch) / (Path(path).stem + (".3w" if kind is Kind.THREEW_BASE64 else ".gcode"))
        with decoded_file(path, kind) as source, target.open("wb") as out:
            while block := source.read(CHUNK):
                out.write(block)
        yield target


def plain_bytes(data: bytes, name: str) -> bytes:
    """In-memory data with any base64 text layer decoded."""
    return decode_base64(data, name) if identify(data[:SNIFF]).base64 else data


# ------------------------------------------------------------------------------------------- G-code text


def normalise(window: bytes, *, first: bool = False) -> bytes:
    """A piece of G-code with LF line ends (and without the BOM when it is the file's start)."""
    if first:
        window = window.removeprefix(BOM)
    if b"\r" in window:
        window = window.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    return window


def _check_lines(text: bytes, name: str, line_offset: int) -> None:
    """Refuse a line longer than MAX_LINE: probe windows of MAX_LINE/2 (any such line covers one) for newlines."""
    step = MAX_LINE // 2
    for at in range(0, len(text) - step + 1, step):
        if text.find(b"\n", at, at + step) < 0:
            start = text.rfind(b"\n", 0, at) + 1
            end = text.find(b"\n", at)
            length = (len(text) if end < 0 else end) - start + (line_offset if start == 0 else 0)
            if length > MAX_LINE:
                raise _long_line(name, length)


def _long_line(name: str, length: int) -> InputError:
    return InputError(f"{name} has a line of over {length} bytes (the limit is {MAX_LINE}): not G-code as a "
                      "printer reads it")


def gcode_lines(src: BinaryIO, name: str, progress: Progress | None = None, total: int = 0) -> Iterator[bytes]:
    """The whole G-code from the file's start as LF-terminated, line-aligned chunks of at most about CHUNK bytes:
    BOM dropped, CRLF and CR made LF, a final newline added. Memory stays within CHUNK + MAX_LINE."""
    src.seek(0)
    carry = b""
    held_cr = False
    first = True
    done = 0
    while block := src.read(CHUNK):
        done += len(block)
        if first:
            block = block.removeprefix(BOM)
            first = False
        if held_cr:
            block = b"\r" + block
        held_cr = block.endswith(b"\r")
        if held_cr:
            block = block[:-1]
        text = normalise(block)
        _check_lines(text, name, len(carry))
        if carry and len(carry) + max(0, text.find(b"\n")) > MAX_LINE:
            raise _long_line(name, len(carry) + max(0, text.find(b"\n")))
        cut = text.rfind(b"\n") + 1
        if cut == 0:
            carry += text
            if len(carry) > MAX_LINE:
                raise _long_line(name, len(carry))
            continue
        yield carry + text[:cut] if carry else text[:cut]
        carry = text[cut:]
        if len(carry) > MAX_LINE:
            raise _long_line(name, len(carry))
        if progress is not None:
            progress(done - len(carry), total)
    if carry or held_cr:
        yield carry + b"\n"
    if progress is not None:
        progress(total, total)


def has_commands(text: bytes) -> bool:
    """Whether normalised text holds a G/M/T command line."""
    return _COMMAND_LINE.search(text) is not None


# ---------------------------------------------------------------------------- G-code → the text a .3w carries

XYZ_VERSION = "18020109"
"""`; version =` in the XYZ keys (miniMover's)."""
HEAD_WINDOW = 1 << 18
TAIL_WINDOW = 1 << 18
"""Bytes at each end of a G-code searched for slicer comments (Cura states at the top, PrusaSlicer at the end)."""
_FIRST_CODE_LINE = re.compile(rb"^[ \t]*[^;\s]", re.MULTILINE)
_XYZ_KEY_LINE = re.compile(
    rb"^[ \t]*;[ \t]*(?:filename|print_time|machine|facets|total_layers|version|total_filament)[ \t]*="
)
_G0_WORD = re.compile(rb"\n([ \t]*(?:[Nn][0-9]+[ \t]*)?[Gg][ \t]*0?)0(?![0-9.])")
_ODD_FIRST = np.zeros(256, dtype=bool)
_ODD_FIRST[list(b" \tNng")] = True
"""A line starting with one of these needs the regular expression to find its command word."""
_DIGIT_OR_DOT = np.zeros(256, dtype=bool)
_DIGIT_OR_DOT[list(b"0123456789.")] = True


@dataclass(frozen=True, slots=True)
class Prepared:
    keys: bytes
    """The XYZ key lines (XYZprint's order) that open the body."""
    header: bytes
    """The .3w header: the keys plus the slicer's leading comments when they fit, else the keys alone."""
    metadata: GcodeMetadata
    analysed: bool
    """The moves were read once already to compute metadata (so progress counts two passes)."""


def stream_size(src: BinaryIO) -> int:
    here = src.tell()
    end = src.seek(0, os.SEEK_END)
    src.seek(here)
    return end


def _first_half(progress: Progress | None) -> Progress | None:
    return None if progress is None else lambda done, total: progress(done // 2, total)


def _second_half(progress: Progress | None) -> Progress | None:
    return None if progress is None else lambda done, total: progress((total + done) // 2, total)


def check_gcode_head(src: BinaryIO, name: str) -> tuple[bytes, int]:
    """(the normalised first CHUNK of the G-code, the file size); G-code without commands is refused."""
    total = stream_size(src)
    src.seek(0)
    raw = src.read(CHUNK)
    head = normalise(raw[:-1] if raw.endswith(b"\r") else raw, first=True)
    if not head.strip():
        raise InputError(f"{name} is empty G-code: nothing to convert")
    if not has_commands(head[:HEAD_WINDOW]):
        found = _FIRST_CODE_LINE.search(head)
        if found is None and len(raw) == total:
            raise InputError(f"{name} has no commands, only comments")
        if found is not None and found.start() < HEAD_WINDOW:
            raise InputError(f"{name} is text, not G-code: no G, M or T command in its first {HEAD_WINDOW} bytes")
    return head, total


def _leading_comments(head: bytes, room: int) -> bytes | None:
    """The leading comment block without XYZ key lines, if it is within `room` bytes and ends inside `head`."""
    found = _FIRST_CODE_LINE.search(head, 0, room + 1)
    if found is None:
        return None
    return b"".join(line + b"\n" for line in head[:found.start()].split(b"\n")[:-1] if not _XYZ_KEY_LINE.match(line))


def prepare(src: BinaryIO, name: str, file_id: str, filename: str, header_space: int,
            progress: Progress | None) -> Prepared:
    """The XYZ key lines and the .3w header for a G-code (its metadata read or computed); `header_space` is the
    room the container has for the (padded) header."""
    head, total = check_gcode_head(src, name)
    stated, computed = _metadata(src, name, head, total, _first_half(progress))
    meta = finish(stated, computed)
    safe_name = re.sub(r"[\r\n]", "", filename) or "temp.3w"
    keys = (
        f"; filename = {safe_name}\n"
        f"; print_time = {meta.print_time_s}\n"
        f"; machine = {file_id}\n"
        f"; facets = {meta.facets}\n"
        f"; total_layers = {meta.layers}\n"
        f"; version = {XYZ_VERSION}\n"
        f"; total_filament = {meta.filament_mm:.2f}\n"
    ).encode("utf-8", "surrogateescape")  # a file name's undecodable bytes go into the header as they were
    comments = _leading_comments(head, header_space)
    fits = comments is not None and (len(keys + comments) // 16 + 1) * 16 <= header_space  # with its PKCS#7 pad
    header = keys + comments if comments is not None and fits else keys
    return Prepared(keys, header, meta, computed is not None)


def _metadata(
    src: BinaryIO, name: str, head: bytes, total: int, progress: Progress | None = None,
) -> tuple[GcodeMetadata, GcodeMetadata | None]:
    """(what the slicer's comments state, what the moves say when the comments leave gaps)."""
    tail = b""
    if total > CHUNK:
        src.seek(max(CHUNK, total - TAIL_WINDOW))
        tail = normalise(src.read())
    stated = header_metadata(head[:HEAD_WINDOW], tail)
    _check_plausible(stated, name, "its comments state", "which no print takes")
    if stated.complete:
        return stated, None
    analyzer = MoveAnalyzer()
    for chunk in gcode_lines(src, name, progress, total):
        analyzer.feed_chunk(chunk)
    if analyzer.absurd:
        raise InputError(f"{name}: its moves go further than a number can hold, far beyond any printer's reach; "
                         "this is not a print file")
    computed = analyzer.result()
    _check_plausible(computed, name, "its moves add up to", "so its coordinates lie far beyond any printer's reach")
    return stated, computed


MAX_PRINT_S = 90 * 86400
"""Longest print time believed: the longest real jobs take days, not months."""
MAX_FILAMENT_MM = 10_000_000.0
"""Most filament believed: 10 km, fifty spools; a da Vinci cartridge holds 200-300 m."""


MAX_COUNT = 100_000_000
"""Most layers or facets believed (a 300 mm print at 0.01 mm is 30,000 layers)."""


def _check_plausible(meta: GcodeMetadata, name: str, how: str, why: str) -> None:
    """InputError when the figures say the file is no print at all: coordinates far outside any build volume
    (a Z of 1e23 mm) add up to centuries of printing, and the printer would show that as its time left."""
    too_long = meta.print_time_s is not None and meta.print_time_s > MAX_PRINT_S
    too_much = meta.filament_mm is not None and not meta.filament_mm <= MAX_FILAMENT_MM
    too_many = [f"{units.count(n, noun)}" for n, noun in ((meta.layers, "layer"), (meta.facets, "facet"))
                if n is not None and n > MAX_COUNT]
    if too_long or too_much or too_many:
        what = (f"{units.duration(meta.print_time_s)} of printing" if too_long
                else f"{units.filament(meta.filament_mm)} of filament" if too_much else too_many[0])
        raise InputError(f"{name}: {how} {what}, {why}; this is not a print file")


def gcode_metadata(path: Path) -> tuple[GcodeMetadata, GcodeMetadata | None]:
    """What a G-code file's comments state, and what its moves say where the comments are silent."""
    with open_input(path) as src:
        return stream_metadata(src, str(path))


def stream_metadata(src: BinaryIO, name: str, *, every_line: bool = True) -> tuple[GcodeMetadata, GcodeMetadata | None]:
    """`gcode_metadata` for an open G-code stream named `name` in messages; InputError for figures no print has
    and for lines no printer reads (`every_line=False`: only the lines read for the figures, when the caller has
    the whole file checked anyway)."""
    head, total = check_gcode_head(src, name)
    stated, computed = _metadata(src, name, head, total)
    if computed is None and every_line:  # the comments told everything: the lines are still each checked
        src.seek(0)
        for _ in gcode_lines(src, name):
            pass
    return stated, computed


def _process(chunk: bytes) -> bytes:
    """LF line ends, and G0/G00 command words as G1/G01 (the printers do not know G0)."""
    if not chunk:
        return chunk
    data = np.frombuffer(chunk, dtype=np.uint8)
    starts = np.insert(np.flatnonzero(data[:-1] == 10) + 1, 0, 0)
    c0, c1, c2, c3 = (np.take(data, starts + i, mode="clip") for i in range(4))
    if (_ODD_FIRST[c0] | ((c0 == 71) & ((c1 == 32) | (c1 == 9)))).any():  # blanks, line numbers or lower case
        return _G0_WORD.sub(rb"\n\g<1>1", b"\n" + chunk)[1:]
    # Every line starts with its command: the `0` of each G0/G00 becomes `1` in place.
    g0 = (c0 == 71) & (c1 == 48)
    ones = np.concatenate((starts[g0 & ~_DIGIT_OR_DOT[c2]] + 1, starts[g0 & (c2 == 48) & ~_DIGIT_OR_DOT[c3]] + 2))
    if not len(ones):
        return chunk
    out = bytearray(chunk)
    np.frombuffer(out, dtype=np.uint8)[ones] = ord("1")
    return bytes(out)


def processed_body(src: BinaryIO, name: str, prepared: Prepared, progress: Progress | None) -> Iterator[bytes]:
    """The body: the XYZ keys, the slicer's leading comments without XYZ key lines, then the processed code."""
    yield prepared.keys
    if prepared.analysed:
        progress = _second_half(progress)
    leading = True
    for chunk in gcode_lines(src, name, progress, stream_size(src)):
        if leading:
            found = _FIRST_CODE_LINE.search(chunk)
            end = len(chunk) if found is None else found.start()
            yield b"".join(line + b"\n" for line in chunk[:end].split(b"\n")[:-1] if not _XYZ_KEY_LINE.match(line))
            if found is None:
                continue
            leading = False
            chunk = chunk[end:]
        yield _process(chunk)
