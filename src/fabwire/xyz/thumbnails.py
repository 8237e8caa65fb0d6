"""Preview pictures that slicers embed in G-code comments, read back as PNG (for notifications and the dashboard).

A block is `; <word> begin <W>x<H> <base64 length>`, then base64 lines each after `; `, then `; <word> end`.
The words, their image formats and where each is written are the table `FORMATS`. Blocks sit in the file's
leading comments (PrusaSlicer, SuperSlicer, OrcaSlicer; Cura with its thumbnail script), so only the head is read.
"""

from __future__ import annotations

import base64
import binascii
import io
import re
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

HEAD_BYTES = 8 << 20
"""How far into a file thumbnails are looked for (a 600x600 PNG is under 1 MiB of base64)."""
MAX_THUMBNAIL_BYTES = 4 << 20
"""A decoded picture larger than this is ignored (no slicer writes one)."""


@dataclass(frozen=True, slots=True)
class ThumbnailFormat:
    word: str
    """The block's keyword, as in `; thumbnail_JPG begin 16x16 640`."""
    image: str
    """Pillow's name of the encoded image format."""
    source: str


FORMATS: tuple[ThumbnailFormat, ...] = (
    ThumbnailFormat("thumbnail", "PNG", "PrusaSlicer src/libslic3r/GCode/Thumbnails.hpp (format PNG; also "
                    "SuperSlicer, OrcaSlicer, Cura's CreateThumbnail post-processing script)"),
    ThumbnailFormat("thumbnail_PNG", "PNG", "OrcaSlicer src/libslic3r/GCode/Thumbnails.hpp (PNG named explicitly)"),
    ThumbnailFormat("thumbnail_JPG", "JPEG", "PrusaSlicer src/libslic3r/GCode/Thumbnails.hpp (format JPG, 2.4+)"),
    ThumbnailFormat("thumbnail_QOI", "QOI", "PrusaSlicer src/libslic3r/GCode/Thumbnails.hpp (format QOI, 2.6+, "
                    "the Prusa MINI/MK4 preview)"),
)
_BY_WORD = {f.word: f for f in FORMATS}
_BEGIN = re.compile(rb"^;[ \t]*(thumbnail(?:_[A-Z]+)?) begin[ \t]+(\d+)x(\d+)[ \t]+(\d+)[ \t]*$")


@dataclass(frozen=True, slots=True)
class Thumbnail:
    width: int
    height: int
    format: ThumbnailFormat
    data: bytes
    """The picture as the slicer encoded it."""

    def png(self) -> bytes:
        """The picture as PNG bytes; ValueError when it does not decode."""
        if self.format.image == "PNG" and self.data.startswith(b"\x89PNG"):
            return self.data
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(io.BytesIO(self.data), formats=[self.format.image]) as image:
                out = io.BytesIO()
                image.save(out, "PNG")
        except (UnidentifiedImageError, OSError, SyntaxError) as exc:
            raise ValueError(f"a {self.format.word} block does not decode: {exc}") from None
        return out.getvalue()


def read_thumbnails(src: BinaryIO, limit: int = HEAD_BYTES) -> list[Thumbnail]:
    """Every well-formed thumbnail block in the first `limit` bytes, in file order; broken ones are skipped."""
    found: list[Thumbnail] = []
    current: tuple[ThumbnailFormat, int, int] | None = None
    chunks: list[bytes] = []
    read = 0
    for raw in src:
        read += len(raw)
        if read > limit:
            break
        line = raw.strip()
        if current is None:
            match = _BEGIN.match(line)
            if match and match.group(1).decode() in _BY_WORD:
                current = (_BY_WORD[match.group(1).decode()], int(match.group(2)), int(match.group(3)))
                chunks = []
            continue
        fmt, width, height = current
        if line.startswith(b";") and line[1:].strip() == f"{fmt.word} end".encode():
            current = None
            try:
                data = base64.b64decode(b"".join(chunks), validate=True)
            except (binascii.Error, ValueError):
                continue
            if 0 < len(data) <= MAX_THUMBNAIL_BYTES:
                found.append(Thumbnail(width, height, fmt, data))
            continue
        if not line.startswith(b";") or sum(map(len, chunks)) > MAX_THUMBNAIL_BYTES * 2:
            current = None  # the block ended without its end line: not a picture
            continue
        chunks.append(line[1:].strip())
    return found


def best_png(path: Path, *, limit: int = HEAD_BYTES) -> bytes | None:
    """The largest embedded picture of a G-code file as PNG bytes, or None when it has none that decodes."""
    try:
        with path.open("rb") as src:
            thumbnails = read_thumbnails(src, limit)
    except OSError:
        return None
    for thumbnail in sorted(thumbnails, key=lambda t: t.width * t.height, reverse=True):
        try:
            return thumbnail.png()
        except ValueError:
            continue
    return None
