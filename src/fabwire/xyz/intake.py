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
import functools
import math
import os
import re
import stat
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from io import BytesIO
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

from fabwire import units
from fabwire.errors import FabwireError, InputError, excerpt
from fabwire.xyz.models import PrinterModel

if TYPE_CHECKING:  # the move analysis (numpy) is loaded when G-code is read, not to decode a .3w
    import numpy as np
    from numpy.typing import NDArray

    from fabwire.xyz.gcodearrays import LineRule
    from fabwire.xyz.gcodeinfo import GcodeMetadata

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
    if _CONTROL.search(head) and not _nul_only(head):
        return Kind.BINARY
    return Kind.GCODE


def _nul_only(head: bytes) -> bool:
    """Whether the only control bytes of text are NULs, few of them or a run that pads its end (what a copy off an
    SD card leaves): G-code with NULs, which `gcode_lines` drops (padding) or refuses by line (inside the code)."""
    text = head.rstrip(b"\0")
    if not text.strip() or _CONTROL.search(text.replace(b"\0", b"")):
        return False
    return text.count(b"\0") <= max(8, len(text) // 100)


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
MAX_STDIN = 1 << 30
"""Most bytes taken from standard input or a pipe, spooled to a temporary file: a pipe may never end, and the print
files slicers write for these machines' build volumes are tens of megabytes (the agent takes 64 MB by default)."""


@contextlib.contextmanager
def input_file(path: Path) -> Iterator[tuple[Path, str]]:
    """(a file to read, its name for messages): `path` itself, or for `-` (standard input) and anything that is no
    file to read twice (a pipe, `<(…)`, a device, /proc) its content copied in CHUNK pieces to a temporary file, so
    it is read like any other file with memory bounded by CHUNK."""
    import sys

    name = STDIN_NAME if str(path) == STDIN else str(path)
    if name != STDIN_NAME and _rereadable(path):
        yield path, name
        return
    with tempfile.TemporaryDirectory() as scratch:
        spooled = Path(scratch) / ("stdin" if name == STDIN_NAME else path.name or "input")  # a printer's file name
        try:
            with contextlib.ExitStack() as stack:
                src = sys.stdin.buffer if name == STDIN_NAME else stack.enter_context(open_input(path, name))
                out = stack.enter_context(spooled.open("wb"))
                while block := src.read(CHUNK):
                    if not out.tell():
                        _judge_first_block(block, name)
                    if out.tell() + len(block) > MAX_STDIN:
                        raise InputError(f"{name} is over {MAX_STDIN >> 30} GiB: not a print file that ends")
                    out.write(block)
        except OSError as exc:
            raise InputError(f"cannot read {name}: {exc.strerror or exc}") from exc
        try:
            yield spooled, name
        except FabwireError as exc:  # readers name the file they were given: the copy is the input's
            if exc.args and isinstance(exc.args[0], str):
                exc.args = (exc.args[0].replace(str(spooled), name), *exc.args[1:])
            raise


def _rereadable(path: Path) -> bool:
    """Whether `path` is a regular file with a size, which the intake may read twice and seek in (a missing one is
    left to the reader, which names the error)."""
    try:
        found = path.stat()
    except OSError:
        return True
    return stat.S_ISREG(found.st_mode) and found.st_size > 0


def _judge_first_block(block: bytes, name: str) -> None:
    """Refuse standard input from its first block when that already shows it can be neither G-code nor a .3w, so
    an endless binary stream is not spooled to its end first. A binary STL is told by its whole size, so data that
    could be one (its declared size is beyond the block, within the limit) is read on, and the full read names it."""
    head = block[:SNIFF]
    kind = identify(head)
    stl_size = 84 + 50 * int.from_bytes(head[80:84], "little")  # what a binary STL declares
    could_be_stl = kind is Kind.BINARY and len(head) >= 84 and len(block) <= stl_size <= MAX_STDIN
    if not kind.printable and kind is not Kind.EMPTY and not could_be_stl:
        raise refusal(kind, name, head)


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


def _check_lines(text: bytes, name: str, line_offset: int, lines_before: Callable[[], int]) -> None:
    """Refuse a line longer than MAX_LINE: probe windows of MAX_LINE/2 (any such line covers one) for newlines;
    `line_offset` bytes of the first line came before `text`, after `lines_before()` whole lines."""
    step = MAX_LINE // 2
    for at in range(0, len(text) - step + 1, step):
        if text.find(b"\n", at, at + step) < 0:
            start = text.rfind(b"\n", 0, at) + 1
            end = text.find(b"\n", at)
            length = (len(text) if end < 0 else end) - start + (line_offset if start == 0 else 0)
            if length > MAX_LINE:
                raise _long_line(name, lines_before() + text.count(b"\n", 0, start) + 1)


_MOVE_LINE = re.compile(rb"[ \t]*(?:N[0-9]+[ \t]*)?G", re.IGNORECASE)


def _lines_after_crs(src: BinaryIO, begin: int, carried_cr: bool) -> int:
    return _lines_before(src, begin) - carried_cr


def _check_numbers(text: bytes, name: str, lines_before: Callable[[], int], start: int = 0,
                   end: int | None = None) -> None:
    """Refuse a G line with a word whose value is not exactly one plain decimal number (`gcodearrays.NUMBER_FORMS`,
    and a bare letter on a move: `EMPTY_VALUE`), among the whole lines from offset `start` to `end` of `text` (a
    last line without its line break is left for when it is whole)."""
    from fabwire.xyz.gcodearrays import SUSPECT_LINE, malformed_word

    for found in SUSPECT_LINE.finditer(text, start, len(text) if end is None else end):
        stop = text.find(b"\n", found.start())
        if stop < 0:
            return
        word = malformed_word(text[found.start():stop])
        if word is None:
            continue
        value, form = word
        line = lines_before() + text.count(b"\n", 0, found.start()) + 1
        shown = excerpt(value.decode("utf-8", "replace"), 30)
        glued = _GLUED_WORD.fullmatch(value)
        if glued:  # `Y10E1`: most likely a blank left out, said in the file's own words
            first, second = value[:glued.start(1)].decode(), glued.group(1).decode()
            raise InputError(f"{name}: line {line}: {shown} runs two words together ({form.construct}): Marlin "
                             f"reads {first} and {second}, {_as_strtod(value[1:])}; write '{first} {second}'")
        raise InputError(f"{name}: line {line}: {shown} is not one plain decimal number ({form.construct}): "
                         f"{form.reading}; write each value as plain decimals")


_GLUED_WORD = re.compile(rb"[A-Z][ \t]*[+-]?[0-9.]+([EX][+-]?[0-9.]+)")
"""A word followed by an axis word without a blank between them (`Y10E1`), which strtod reads as one number."""


def _as_strtod(number: bytes) -> str:
    """How other readers take `number`, in words: C's strtod reads `10E1` as 100 and `0X10` as 16."""
    text = number.decode().strip()
    try:
        value = float.fromhex(text) if "X" in text.upper() else float(text)
    except ValueError:
        return f"a reader that takes {text[-len(text.lstrip('+-.0123456789')):][:1]} into the number something else"
    return f"a reader using C's strtod one number ({text} = {value:g})"


def ambiguous_line(name: str, line: int, text: bytes, rule: LineRule) -> InputError:
    """The one-line refusal of line number `line` (its `text`) by a row of `gcodearrays.LINE_RULES`."""
    shown = excerpt(text.decode("utf-8", "replace"), 40)
    return InputError(f"{name}: line {line}: {shown} {rule.reading}; {rule.advice}")


def _long_line(name: str, line: int) -> InputError:
    """The refusal of line number `line`, which is longer than MAX_LINE."""
    return InputError(f"{name} has a line of over {MAX_LINE} bytes, the limit (line {line}): not G-code as a printer "
                      "reads it (firmware line buffers hold about 100 bytes)")


def content_end(src: BinaryIO) -> int:
    """The stream's size without the NUL bytes that pad its end (a file copied off an SD card or written in fixed
    blocks ends in them), read backwards in SNIFF pieces."""
    end = stream_size(src)
    while end > 0:
        start = max(0, end - SNIFF)
        src.seek(start)
        piece = src.read(end - start).rstrip(b"\0")
        if piece:
            return start + len(piece)
        end = start
    return 0


def padding_note(name: str, total: int, end: int) -> str | None:
    """The note for NUL padding dropped from the end of a file, if any."""
    if end >= total:
        return None
    return f"{name}: the {total - end} NUL bytes that pad its end were dropped"


def _lines_before(src: BinaryIO, offset: int) -> int:
    """How many lines (LF, CRLF or CR ended) the stream's first `offset` bytes hold; the position is kept."""
    here = src.tell()
    src.seek(0)
    lines = 0
    while offset > 0 and (block := src.read(min(CHUNK, offset))):
        offset -= len(block)
        lines += block.count(b"\n") + len(re.findall(rb"\r(?!\n)", block))
    src.seek(here)
    return lines


def _without_nuls(text: bytes, name: str, lines_before: int, repaired: list[int] | None) -> bytes:
    """`text` (normalised, after `lines_before` whole lines) without its NUL bytes when `repaired` collects their
    line numbers; otherwise the InputError naming the first one's line."""
    runs = [lines_before + text.count(b"\n", 0, run.start()) + 1 for run in re.finditer(rb"\0+", text)]
    if repaired is None:
        raise InputError(f"{name} has a NUL byte inside its G-code on line {runs[0]} (a printer stalls on it); "
                         "`fabwire xyz convert --repair` drops such bytes")
    repaired.extend(line for line in runs if not repaired or line != repaired[-1])
    return text.replace(b"\0", b"")


def gcode_lines(src: BinaryIO, name: str, progress: Progress | None = None, total: int = 0, *,
                end: int | None = None, repaired: list[int] | None = None,
                odd: list[tuple[int, int]] | None = None) -> Iterator[bytes]:
    """The whole G-code from the file's start (to `end`, default its end) as LF-terminated, line-aligned chunks of
    at most about CHUNK bytes: BOM dropped, CRLF and CR made LF, a final newline added. Memory stays within
    CHUNK + MAX_LINE.

    A NUL byte before `end` is an InputError naming its line; when `repaired` is given, NULs are dropped instead and
    the line numbers they were on are appended to it. So is a G line with a word whose value is not one plain decimal
    number (`gcodearrays.NUMBER_FORMS`). When `odd` is given, the caller reads each chunk's numbers itself and lists
    there, before it asks for the next chunk, the (start, end) parts of the chunk outside which no such number is
    (`MoveAnalyzer.feed_chunk` does): only those parts, and the line a read cuts in two, are searched here; the
    errors and their order stay the same."""
    from fabwire.xyz.gcodearrays import SUSPECT_LINE

    src.seek(0)
    carry = b""
    carry_lines: Callable[[], int] = functools.partial(int, 0)  # counts the lines before `carry` (when asked)
    held_cr = False
    first = True
    done = 0
    left = stream_size(src) if end is None else end
    while left > 0 and (block := src.read(min(CHUNK, left))):
        left -= len(block)
        begin = done
        done += len(block)
        if first:
            block = block.removeprefix(BOM)
            first = False
        carried_cr = held_cr  # a CR held back from the previous block ends a line this block's text counts
        if held_cr:
            block = b"\r" + block
        held_cr = block.endswith(b"\r")
        if held_cr:
            block = block[:-1]
        text = normalise(block)
        if b"\0" in text:
            text = _without_nuls(text, name, _lines_before(src, begin) - carried_cr, repaired)
        lines_before = functools.partial(_lines_after_crs, src, begin, carried_cr)
        _check_lines(text, name, len(carry), lines_before)
        cut = text.rfind(b"\n") + 1
        if odd is None:
            checked = True
            _check_numbers(carry + text if carry else text, name, lines_before)  # carry holds no newline
        else:  # the line the read cuts is searched here, the others by the caller
            checked = cut == 0 or SUSPECT_LINE.search(text, cut) is not None
            if checked:
                _check_numbers(carry + text if carry else text, name, lines_before)
        if carry and len(carry) + max(0, text.find(b"\n")) > MAX_LINE:
            if not checked:  # an error in the lines before comes first
                _check_numbers(carry + text, name, lines_before)
            raise _long_line(name, lines_before() + 1)
        if cut == 0:
            carry += text
            if len(carry) > MAX_LINE:
                raise _long_line(name, lines_before() + 1)
            continue
        chunk = carry + text[:cut] if carry else text[:cut]
        yield chunk
        if odd:
            for start, stop in odd:
                _check_numbers(chunk, name, lines_before, start, stop)
            odd.clear()
        del chunk  # not held while the next block is read
        carry = text[cut:]
        carry_lines = functools.partial(_lines_after_crs, src, done, held_cr)  # counted only if ever asked
        if len(carry) > MAX_LINE:
            raise _long_line(name, carry_lines() + 1)
        if progress is not None:
            progress(done - len(carry), total)
    if carry or held_cr:
        _check_numbers(carry + b"\n", name, carry_lines)  # the last line, whole now
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


@functools.cache
def _byte_classes() -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Lookup tables by byte value: (a line starting with it needs the regular expression to find its command
    word, a digit or a dot). Built on first use: a .3w that is only sent never loads numpy."""
    import numpy as np

    odd_first, digit_or_dot = np.zeros(256, dtype=bool), np.zeros(256, dtype=bool)
    odd_first[list(b" \tNng")] = True
    digit_or_dot[list(b"0123456789.")] = True
    return odd_first, digit_or_dot


@dataclass(frozen=True, slots=True)
class Prepared:
    keys: bytes
    """The XYZ key lines (XYZprint's order) that open the body."""
    header: bytes
    """The .3w header: the keys plus the slicer's leading comments when they fit, else the keys alone."""
    metadata: GcodeMetadata
    analysed: bool
    """The moves were read once already to compute metadata (so progress counts two passes)."""
    end: int
    """Where the G-code ends (before any NUL padding)."""
    repaired: list[int] | None = None
    """With repair: the lines the body pass dropped NUL bytes from (filled as the body is read)."""
    expand_arcs: bool = False
    """The body pass turns G2/G3 arcs into line segments."""
    g0_words: list[NDArray[np.intp] | None] | None = None
    """Per chunk of the G-code, the offsets of the `0` of its G0/G00 command words, as the analysis found them
    (None for a chunk only the line reader read)."""

    @property
    def notes(self) -> tuple[str, ...]:
        """What the reader set aside or changed, for the user (complete once the body was read)."""
        if not self.repaired:
            return self.metadata.notes
        shown = ", ".join(map(str, self.repaired[:10])) + (" …" if len(self.repaired) > 10 else "")
        return (*self.metadata.notes, f"NUL bytes dropped from line{'s' if len(self.repaired) > 1 else ''} {shown}")


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
    """(the normalised first CHUNK of the G-code, its size without the NUL padding at its end); G-code without
    commands is refused."""
    total = content_end(src)
    src.seek(0)
    raw = src.read(min(CHUNK, total))
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


def prepare(src: BinaryIO, name: str, model: PrinterModel, filename: str, header_space: int,
            progress: Progress | None, *, repair: bool = False, force: bool = False,
            keep_arcs: bool = False) -> Prepared:
    """The XYZ key lines and the .3w header of a G-code for `model` (its metadata read, the moves always read
    for their extent and arcs); `header_space` is the room the container has for the (padded) header.

    `repair` drops NUL bytes inside the G-code (noted) instead of refusing the file; extrusions beyond the model's
    build volume are an InputError unless `force` (then noted); G2/G3 arcs become line segments unless
    `keep_arcs`, and a G-code whose arcs would become more than `arcwork.growth_room` bytes of segments is refused
    at the arc that passes it while the moves are read (`arcwork.TooMuchGrowth`), before anything is written."""
    from fabwire.xyz import arcwork
    from fabwire.xyz.gcodeinfo import finish

    head, total = check_gcode_head(src, name)
    g0_words: list[NDArray[np.intp] | None] = []
    stated, computed = _metadata(src, name, head, total, _first_half(progress), repair=repair, always=True,
                                 g0_words=g0_words, arcs_grow=not keep_arcs)
    outside = check_build_volume(stated.merged(computed) if computed else stated, name, model, force)
    meta = finish(stated, computed)
    safe_name = re.sub(r"[\r\n]", "", filename) or "temp.3w"
    keys = (
        f"; filename = {safe_name}\n"
        f"; print_time = {meta.print_time_s}\n"
        f"; machine = {model.file_id}\n"
        f"; facets = {meta.facets}\n"
        f"; total_layers = {meta.layers}\n"
        f"; version = {XYZ_VERSION}\n"
        f"; total_filament = {meta.filament_mm:.2f}\n"
    ).encode("utf-8", "surrogateescape")  # a file name's undecodable bytes go into the header as they were
    comments = _leading_comments(head, header_space)
    fits = comments is not None and (len(keys + comments) // 16 + 1) * 16 <= header_space  # with its PKCS#7 pad
    header = keys + comments if comments is not None and fits else keys
    padding = padding_note(name, stream_size(src), total)
    notes = meta.notes + ((padding,) if padding else ()) + ((outside,) if outside else ())
    arcs = 0 if keep_arcs else meta.arcs
    if arcs:
        notes += (f"{arcs} G2/G3 arc{'s' if arcs > 1 else ''} converted to line segments within "
                  f"{arcwork.TOLERANCE_MM} mm (no public source shows da Vinci firmware running arcs; --keep-arcs "
                  "passes them through)",)
    return Prepared(keys, header, replace(meta, notes=notes), computed is not None, total, [] if repair else None,
                    arcs > 0, g0_words if computed is not None else None)


def _tail(src: BinaryIO, total: int) -> bytes:
    """The last TAIL_WINDOW bytes beyond the head window, from a line start (empty for a file the head covers)."""
    if total <= HEAD_WINDOW:
        return b""
    start = max(HEAD_WINDOW, total - TAIL_WINDOW)
    src.seek(start)
    tail = normalise(src.read(total - start))
    return tail[tail.find(b"\n") + 1:] if start > HEAD_WINDOW else tail


def _metadata(
    src: BinaryIO, name: str, head: bytes, total: int, progress: Progress | None = None, *, repair: bool = False,
    always: bool = False, g0_words: list[NDArray[np.intp] | None] | None = None, arcs_grow: bool = False,
) -> tuple[GcodeMetadata, GcodeMetadata | None]:
    """(what the slicer's comments state and are believed, what the moves say when the comments leave gaps or
    `always`); `g0_words` collects where the G0 command words are (see `MoveAnalyzer`) when the moves are read.
    `arcs_grow`: the arcs will become segments, and the arc whose segments take the file past
    `arcwork.growth_room` is refused as soon as the moves reach it (`arcwork.too_much_growth`)."""
    from fabwire.xyz import arcwork
    from fabwire.xyz.gcodearrays import Ambiguous, line_count
    from fabwire.xyz.gcodeinfo import ArcGrowth, MoveAnalyzer, header_metadata

    stated = header_metadata(head[:HEAD_WINDOW], _tail(src, total))
    if stated.complete and not always:
        return stated, None
    analyzer = MoveAnalyzer(timing=stated.print_time_s is None, g0_words=g0_words,  # a stated time: no planning
                            arc_room=arcwork.growth_room(total) if arcs_grow else math.inf)
    odd: list[tuple[int, int]] = []
    lines = 0
    for chunk in gcode_lines(src, name, progress, total, end=total, repaired=[] if repair else None, odd=odd):
        try:
            analyzer.feed_chunk(chunk, odd)
        except Ambiguous as exc:
            raise ambiguous_line(name, lines + chunk.count(b"\n", 0, exc.offset) + 1,
                                 chunk[exc.offset:chunk.find(b"\n", exc.offset)], exc.rule) from None
        except ArcGrowth as exc:
            raise arcwork.too_much_growth(name, exc.arc) from None
        lines += line_count(chunk)
    if analyzer.absurd:
        raise InputError(f"{name}: its moves go further than a number can hold, far beyond any printer's reach; "
                         "this is not a print file")
    computed = analyzer.result()
    _check_plausible(computed, name, "its moves add up to", "so its coordinates lie far beyond any printer's reach")
    return stated, computed


BUILD_MARGIN_MM = 1.0
"""How far past the build volume a move may reach before the file is refused (slicers' rounding)."""


def check_build_volume(meta: GcodeMetadata, name: str, model: PrinterModel, force: bool) -> str | None:
    """InputError when the moves (travel, extrusion and whole arcs, as `gcodeinfo.REACH` counts them) reach beyond
    `model`'s build volume (G-code sliced for a larger printer), naming the extent; with `force`, the note saying so
    instead. None when they fit or nothing moves."""
    if meta.extent is None:
        return None
    beyond = [axis for axis, (low, high), size in zip("XYZ", meta.extent, model.build_volume_mm, strict=True)
              if (axis != "Z" and low < -BUILD_MARGIN_MM) or high > size + BUILD_MARGIN_MM]
    if not beyond:
        return None
    reach = ", ".join(f"{axis} {low:.1f} to {high:.1f} mm" for axis, (low, high) in zip("XYZ", meta.extent,
                                                                                        strict=True))
    volume = " × ".join(str(v) for v in model.build_volume_mm)
    text = (f"{name} moves beyond the {model.name}'s build volume of {volume} mm ({reach}): it was sliced for "
            "another printer")
    if not force:
        raise InputError(f"{text}; slice it for this printer, or give --force to print it anyway")
    return text + "; converted anyway (--force)"


def _check_plausible(meta: GcodeMetadata, name: str, how: str, why: str) -> None:
    """InputError when the figures say the file is no print at all: coordinates far outside any build volume
    (a Z of 1e23 mm) add up to centuries of printing, and the printer would show that as its time left."""
    from fabwire.xyz import slicerfigures  # its wordings are for G-code: a .3w sent as it is never loads them

    too_long = meta.print_time_s is not None and meta.print_time_s > slicerfigures.MAX_PRINT_S
    too_much = meta.filament_mm is not None and not meta.filament_mm <= slicerfigures.MAX_FILAMENT_MM
    too_many = [f"{units.count(n, noun)}" for n, noun in ((meta.layers, "layer"), (meta.facets, "facet"))
                if n is not None and n > slicerfigures.MAX_COUNT]
    if too_long or too_much or too_many:
        what = (f"{units.duration(meta.print_time_s)} of printing" if too_long
                else f"{units.filament(meta.filament_mm)} of filament" if too_much else too_many[0])
        raise InputError(f"{name}: {how} {what}, {why}; this is not a print file")


def gcode_metadata(path: Path) -> tuple[GcodeMetadata, GcodeMetadata | None]:
    """What a G-code file's comments state, and what its moves say where the comments are silent."""
    with open_input(path) as src:
        return stream_metadata(src, str(path))


def stream_metadata(src: BinaryIO, name: str, *, every_line: bool = True, arcs_grow: bool = False,
                    ) -> tuple[GcodeMetadata, GcodeMetadata | None]:
    """`gcode_metadata` for an open G-code stream named `name` in messages; InputError for figures no print has,
    for lines no printer reads and for NUL bytes inside the G-code (NUL padding at its end is dropped, noted).
    `every_line=False`: only the lines read for the figures are checked, when the caller has the whole file
    checked anyway. `arcs_grow` (with `every_line`): arcs that would grow the file too much as segments are
    refused as a conversion refuses them (`arcwork.TooMuchGrowth`)."""
    head, total = check_gcode_head(src, name)
    stated, computed = _metadata(src, name, head, total, arcs_grow=arcs_grow)
    if computed is None and every_line:  # the comments told everything: the lines are still each checked, as a
        _metadata(src, name, head, total, always=True, arcs_grow=arcs_grow)  # conversion checks them
    padding = padding_note(name, stream_size(src), total)
    return (replace(stated, notes=(*stated.notes, padding)) if padding else stated), computed


def _process(chunk: bytes) -> bytes:
    """LF line ends, and G0/G00 command words as G1/G01 (the printers do not know G0)."""
    if not chunk:
        return chunk
    import numpy as np

    odd_first, digit_or_dot = _byte_classes()
    data = np.frombuffer(chunk, dtype=np.uint8)
    starts = np.insert(np.flatnonzero(data[:-1] == 10) + 1, 0, 0)
    c0, c1, c2, c3 = (np.take(data, starts + i, mode="clip") for i in range(4))
    if (odd_first[c0] | ((c0 == 71) & ((c1 == 32) | (c1 == 9)))).any():  # blanks, line numbers or lower case
        return _G0_WORD.sub(rb"\n\g<1>1", b"\n" + chunk)[1:]
    # Every line starts with its command: the `0` of each G0/G00 becomes `1` in place.
    g0 = (c0 == 71) & (c1 == 48)
    return _as_g1(chunk, np.concatenate((starts[g0 & ~digit_or_dot[c2]] + 1,
                                         starts[g0 & (c2 == 48) & ~digit_or_dot[c3]] + 2)))


def _as_g1(chunk: bytes, ones: NDArray[np.intp]) -> bytes:
    """`chunk` with a `1` at each of the offsets `ones` (the `0` of a G0 or G00 command word)."""
    if not len(ones):
        return chunk
    import numpy as np

    out = bytearray(chunk)
    np.frombuffer(out, dtype=np.uint8)[ones] = ord("1")
    return bytes(out)


def processed_body(src: BinaryIO, name: str, prepared: Prepared, progress: Progress | None) -> Iterator[bytes]:
    """The body: the XYZ keys, the slicer's leading comments without XYZ key lines, then the processed code."""
    yield prepared.keys
    if prepared.analysed:
        progress = _second_half(progress)
    leading = True
    from fabwire.xyz import arcwork

    arcs = arcwork.ArcExpander(name, prepared.end) if prepared.expand_arcs else None
    checked: list[tuple[int, int]] | None = [] if prepared.analysed else None  # the first read searched every line
    g0_words = prepared.g0_words if arcs is None else None  # the analysis read these very chunks
    for index, chunk in enumerate(gcode_lines(src, name, progress, prepared.end, end=prepared.end,
                                              repaired=prepared.repaired, odd=checked)):
        skipped = 0
        if leading:
            found = _FIRST_CODE_LINE.search(chunk)
            end = len(chunk) if found is None else found.start()
            yield b"".join(line + b"\n" for line in chunk[:end].split(b"\n")[:-1] if not _XYZ_KEY_LINE.match(line))
            if found is None:
                continue
            leading = False
            chunk, skipped = chunk[end:], end
        ones = g0_words[index] if g0_words is not None and index < len(g0_words) else None
        if arcs is not None:
            yield from (_process(piece) for piece in arcs.expand(chunk))
        elif ones is not None:
            yield _as_g1(chunk, ones - skipped if skipped else ones)
        else:
            yield _process(chunk)
