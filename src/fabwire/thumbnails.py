"""Preview images that slicers embed in G-code comments, as blocks of base64 text between two marker lines.

    ; thumbnail begin 220x124 5488        <- WIDTHxHEIGHT and the length of the base64 text
    ; iVBORw0KGgoAAAANSUhEUgAAANwAAAB8...  <- the image, base64, wrapped at 78 characters
    ; thumbnail end

`BLOCKS` is the table of the markers slicers write, each row naming its source. The blocks sit in the leading
comments, before the first command; `read_thumbnails` looks no further than `MAX_SCAN` bytes. The library shows
them as browser images (`Thumbnail.web_image`); notifications attach the largest as PNG (`best_png`).
"""

from __future__ import annotations

import base64
import binascii
import io
import logging
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

MAX_SCAN = 16 << 20
"""Bytes of leading comments read at most (a 600x600 PNG preview is well under 1 MB of base64)."""
MAX_IMAGE = 4 << 20
"""The largest single preview kept (decoded bytes; no slicer writes one this large)."""
MAX_PIXELS = 2048 * 2048
"""The most pixels (width × height, read from the image's own header) of a preview kept: PrusaSlicer takes
thumbnail sizes of 1 to 999 pixels a side (src/libslic3r/GCode/Thumbnails.cpp), so this is four times its largest;
a small file claiming more (a PNG of 30000×30000 compresses to under 1 MB) would decode to gigabytes."""

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Block:
    marker: str
    """The word before `begin`/`end`, as in `; thumbnail_JPG begin 16x16 640`."""
    format: str
    """"png", "jpg" or "qoi": what the decoded bytes are."""
    source: str


BLOCKS: tuple[Block, ...] = (
    Block("thumbnail", "png", "PrusaSlicer src/libslic3r/GCode/Thumbnails.cpp (format PNG); also SuperSlicer, "
          "OrcaSlicer and Cura's CreateThumbnail post-processing script"),
    Block("thumbnail_PNG", "png", "OrcaSlicer src/libslic3r/GCode/Thumbnails.cpp (PNG named explicitly)"),
    Block("thumbnail_JPG", "jpg", "PrusaSlicer src/libslic3r/GCode/Thumbnails.cpp (format JPG, 2.4+)"),
    Block("thumbnail_QOI", "qoi", "PrusaSlicer src/libslic3r/GCode/Thumbnails.cpp (format QOI, 2.6+, the Prusa "
          "MINI/MK4/XL preview)"),
)
_BY_MARKER = {b.marker.lower(): b for b in BLOCKS}
_BEGIN = re.compile(rb"^;[ \t]*(thumbnail(?:_[A-Za-z0-9]+)?)[ \t]+begin[ \t]+([0-9]+)[xX]([0-9]+)(?:[ \t]+([0-9]+))?",
                    re.IGNORECASE)
_MAGIC = {"png": b"\x89PNG\r\n\x1a\n", "jpg": b"\xff\xd8\xff", "qoi": b"qoif"}
_PILLOW = {"png": "PNG", "jpg": "JPEG", "qoi": "QOI"}
"""Pillow's name of each format, so that a block is decoded only as what its marker says."""


@dataclass(frozen=True, slots=True)
class Thumbnail:
    width: int
    height: int
    format: str
    """"png", "jpg" or "qoi" (as embedded)."""
    data: bytes
    """The image as the slicer encoded it."""

    def png(self) -> bytes:
        """The image as PNG bytes; ValueError when it does not decode."""
        if self.format == "png":
            return self.data
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(io.BytesIO(self.data), formats=[_PILLOW[self.format]]) as image:
                out = io.BytesIO()
                image.save(out, format="PNG")
        except (UnidentifiedImageError, OSError, SyntaxError, ValueError, Image.DecompressionBombError) as exc:
            raise ValueError(f"a {self.format.upper()} preview does not decode: {exc}") from None
        return out.getvalue()

    def web_image(self) -> tuple[bytes, str]:
        """(bytes, media type) a browser shows: PNG and JPG as they are, QOI converted to PNG (browsers have no
        QOI decoder; Moonraker converts it the same way). ValueError when a QOI preview does not decode."""
        if self.format == "jpg":
            return self.data, "image/jpeg"
        return self.png(), "image/png"

    @property
    def web_suffix(self) -> str:
        return ".jpg" if self.format == "jpg" else ".png"


def _is_command(line: bytes) -> bool:
    stripped = line.strip()
    return bool(stripped) and not stripped.startswith(b";")


def read_thumbnails(src: BinaryIO) -> list[Thumbnail]:
    """Every well-formed preview block in the leading comments of a G-code stream, in file order.

    A block whose stated length disagrees with its text, whose base64 is damaged, whose bytes are not the
    stated format, or which never ends is skipped: a preview is an extra, never a reason to refuse a print."""
    found: list[Thumbnail] = []
    block: Block | None = None
    size = (0, 0)
    stated: int | None = None
    parts: list[bytes] = []
    read = 0
    for line in src:
        read += len(line)
        if read > MAX_SCAN or _is_command(line):
            break  # the leading comments are over (a block cut short by a command is no preview)
        if block is None:
            match = _BEGIN.match(line.lstrip(b"\xef\xbb\xbf"))
            if match is not None:
                block = _BY_MARKER.get(match.group(1).decode("ascii").lower())
                size = (int(match.group(2)), int(match.group(3)))
                stated = int(match.group(4)) if match.group(4) else None
                parts = []
            continue
        text = line.strip().lstrip(b";").strip()
        if text.lower() == f"{block.marker.lower()} end".encode():
            _finish(found, block, size, stated, b"".join(parts))
            block = None
        elif sum(len(p) for p in parts) > 2 * MAX_IMAGE:
            block = None
        else:
            parts.append(text)
    return found


def _finish(found: list[Thumbnail], block: Block, size: tuple[int, int], stated: int | None, text: bytes) -> None:
    if stated is not None and stated != len(text):
        return
    try:
        data = base64.b64decode(text, validate=True)
    except (binascii.Error, ValueError):
        return
    if not data.startswith(_MAGIC[block.format]) or len(data) > MAX_IMAGE or not all(size):
        return
    pixels = image_size(data, block.format)
    if pixels is None:
        log.warning("a %s preview is dropped: its header does not read or claims a decompression bomb (the file "
                    "still prints)", block.format.upper())
        return
    if pixels[0] * pixels[1] > MAX_PIXELS:
        log.warning("a %s preview of %dx%d pixels is dropped: more than %d pixels (the file still prints)",
                    block.format.upper(), pixels[0], pixels[1], MAX_PIXELS)
        return
    found.append(Thumbnail(size[0], size[1], block.format, data))


def image_size(data: bytes, fmt: str) -> tuple[int, int] | None:
    """(width, height) in pixels from the header of an image of `fmt` ("png", "jpg", "qoi"), without decoding its
    pixels; None when the header does not read or Pillow calls it a decompression bomb."""
    from PIL import Image, UnidentifiedImageError

    with warnings.catch_warnings():
        warnings.simplefilter("error", Image.DecompressionBombWarning)
        try:
            with Image.open(io.BytesIO(data), formats=[_PILLOW[fmt]]) as image:
                return image.size
        except (UnidentifiedImageError, OSError, SyntaxError, ValueError, Image.DecompressionBombError,
                Image.DecompressionBombWarning):
            return None


def best_png(path: Path) -> bytes | None:
    """The largest preview embedded in a G-code file as PNG bytes, or None when it has none that decodes (or the
    file cannot be read)."""
    try:
        with path.open("rb") as src:
            thumbnails = read_thumbnails(src)
    except OSError:
        return None
    for thumbnail in sorted(thumbnails, key=lambda t: t.width * t.height, reverse=True):
        try:
            return thumbnail.png()
        except ValueError:
            continue
    return None
