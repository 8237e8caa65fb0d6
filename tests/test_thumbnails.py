"""Slicer previews embedded in G-code: every row of the block table (as browser images and as the PNG a
notification attaches), damaged blocks, and any input at all."""

from __future__ import annotations

import base64
import io
import logging
import struct
import zlib
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from agent.doortools import preview, prusaslicer_gcode, thumbnail_block
from fabwire.thumbnails import BLOCKS, MAX_PIXELS, Block, best_png, image_size, read_thumbnails

BACKGROUND, LINE = (40, 120, 200), (250, 250, 250)  # the colours of doortools.preview


def _sliced(*blocks: str) -> bytes:
    """A PrusaSlicer G-code file with these preview blocks in its leading comments."""
    head, _, body = prusaslicer_gcode(thumbs=[]).partition(b"\n;\n")
    return head + b"\n;\n" + "".join(blocks).encode() + body


@pytest.mark.parametrize("block", BLOCKS, ids=lambda b: b.marker)
def test_each_slicer_block_is_read_and_shown_as_a_browser_image(block: Block) -> None:
    """Each row of `BLOCKS` (its source is in the row): the block the slicer writes is found before the first
    command, decoded to the stated size, and served as PNG or JPEG (QOI converted, as Moonraker does)."""
    data = _sliced(thumbnail_block(16, 16, "png"), thumbnail_block(96, 64, block.format, marker=block.marker))
    found = read_thumbnails(io.BytesIO(data))
    assert [(t.width, t.height, t.format) for t in found] == [(16, 16, "png"), (96, 64, block.format)]
    image, media = found[1].web_image()
    assert media == ("image/jpeg" if block.format == "jpg" else "image/png")
    with Image.open(io.BytesIO(image)) as decoded:
        assert decoded.size == (96, 64)
        assert decoded.format == ("JPEG" if block.format == "jpg" else "PNG")


@pytest.mark.parametrize("block", BLOCKS, ids=lambda b: b.marker)
def test_each_slicer_block_gives_its_largest_preview_as_png(block: Block, tmp_path: Path) -> None:
    """What a notification attaches: the largest preview of the file, whatever its format, as PNG bytes."""
    path = tmp_path / "part.gcode"
    path.write_bytes(_sliced(thumbnail_block(16, 16, block.format, marker=block.marker),
                             thumbnail_block(220, 124, block.format, marker=block.marker)))
    png = best_png(path)
    assert png is not None
    assert png.startswith(b"\x89PNG\r\n\x1a\n")
    with Image.open(io.BytesIO(png)) as image:
        assert image.size == (220, 124)
        if block.format != "jpg":  # PNG and QOI are lossless
            rgb = image.convert("RGB")
            assert rgb.getpixel((0, 100)) == BACKGROUND
            assert rgb.getpixel((110, 62)) == LINE


@pytest.mark.parametrize("damage", [
    lambda b: b.replace(b"; thumbnail end", b"G28"),  # a block cut short by a command
    lambda b: b.replace(b"; iVBOR", b"; !!!!!"),  # not base64
    lambda b: b.replace(b"begin 16x16", b"begin 16by16"),  # not a begin line
], ids=["cut-short", "not-base64", "not-a-begin-line"])
def test_a_file_whose_only_block_is_broken_has_no_png(damage: object, tmp_path: Path) -> None:
    path = tmp_path / "part.gcode"
    path.write_bytes(damage(_sliced(thumbnail_block(16, 16, "png"))))  # type: ignore[operator]
    assert best_png(path) is None


def test_a_file_that_cannot_be_read_has_no_png(tmp_path: Path) -> None:
    assert best_png(tmp_path / "gone.gcode") is None


def test_blocks_after_the_first_command_are_not_searched() -> None:
    data = b"G28\n" + thumbnail_block(16, 16, "png").encode() + b"G1 X1\n"
    assert read_thumbnails(io.BytesIO(data)) == []


@pytest.mark.parametrize("damage", ["length", "base64", "format", "unended", "unknown-marker"])
def test_a_damaged_block_is_skipped_and_the_others_kept(damage: str) -> None:
    """A preview is an extra: a wrong stated length, broken base64, bytes that are not the stated format, a block
    that never ends or an unknown marker loses that preview only (never the print)."""
    good = thumbnail_block(16, 16, "png")
    if damage == "length":
        bad = thumbnail_block(32, 32, "png").replace("begin 32x32 ", "begin 32x32 1")
    elif damage == "base64":
        bad = thumbnail_block(32, 32, "png").replace("; iVBOR", "; iV*OR", 1)
    elif damage == "format":
        bad = thumbnail_block(32, 32, "jpg", preview(32, 32, "png"))
    elif damage == "unended":
        bad = "\n".join(thumbnail_block(32, 32, "png").splitlines()[:-2]) + "\n"
    else:
        text = base64.b64encode(preview(32, 32, "png")).decode()
        bad = f"; thumbnail_BMP begin 32x32 {len(text)}\n; {text}\n; thumbnail_BMP end\n"
    data = (good + bad + good + "G28\n").encode() if damage != "unended" else (good + bad + "G28\n").encode()
    found = read_thumbnails(io.BytesIO(data))
    assert all((t.width, t.height) == (16, 16) for t in found)
    assert len(found) == (2 if damage != "unended" else 1)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=4000), st.sampled_from(["", "; thumbnail begin 8x8 12\n", "; thumbnail_QOI begin 2x2\n"]))
def test_any_bytes_give_previews_or_none_never_an_error(junk: bytes, prefix: str) -> None:
    found = read_thumbnails(io.BytesIO(prefix.encode() + junk))
    assert all(t.width > 0 and t.height > 0 for t in found)


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_claiming(width: int, height: int) -> bytes:
    """A few hundred bytes of PNG whose IHDR claims `width`×`height` 8-bit grey pixels (PNG spec §11.2.2): the
    header a decompression bomb carries, with the first rows of zeros compressed after it."""
    rows = zlib.compress(b"\0" * (width + 1) * 4, 9)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
            + _chunk(b"IDAT", rows) + _chunk(b"IEND", b""))


def qoi_claiming(width: int, height: int) -> bytes:
    """A QOI header (qoiformat.org specification: magic, width, height, channels, colorspace) claiming a size,
    with the end marker and no pixels."""
    return b"qoif" + struct.pack(">IIBB", width, height, 3, 0) + b"\0" * 7 + b"\1"


def jpg_claiming(width: int, height: int) -> bytes:
    """A real 16×16 JPEG whose SOF0 frame header (ITU T.81 §B.2.2: length, precision, height, width) is rewritten
    to claim `width`×`height`."""
    data = bytearray(preview(16, 16, "jpg"))
    sof = data.index(b"\xff\xc0")
    data[sof + 5:sof + 9] = struct.pack(">HH", height, width)
    return bytes(data)


BOMBS = (
    # (format, width, height, the header's maker): beyond MAX_PIXELS; the first beyond Pillow's own bomb limit too
    ("png", 30000, 30000, png_claiming),
    ("png", 3000, 3000, png_claiming),
    ("png", 65535, 100, png_claiming),
    ("qoi", 20000, 20000, qoi_claiming),
    ("qoi", MAX_PIXELS + 1, 1, qoi_claiming),
    ("jpg", 65000, 65000, jpg_claiming),
    ("jpg", 4000, 2000, jpg_claiming),
)


@pytest.mark.parametrize(("fmt", "width", "height", "make"), BOMBS, ids=[f"{b[0]}-{b[1]}x{b[2]}" for b in BOMBS])
def test_a_preview_claiming_too_many_pixels_is_dropped_and_logged(fmt: str, width: int, height: int, make: Any,
                                                                  tmp_path: Path,
                                                                  caplog: pytest.LogCaptureFixture) -> None:
    bomb = make(width, height)
    assert len(bomb) < 2000
    assert image_size(bomb, fmt) in ((width, height), None)
    kept = thumbnail_block(16, 16, "png")
    path = tmp_path / "bomb.gcode"
    path.write_bytes(_sliced(thumbnail_block(width, height, fmt, bomb), kept))
    with caplog.at_level(logging.WARNING, logger="fabwire.thumbnails"), path.open("rb") as src:
        found = read_thumbnails(src)
    assert [(t.width, t.height) for t in found] == [(16, 16)]
    assert best_png(path) == found[0].data
    assert any("dropped" in r.getMessage() and fmt.upper() in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("fmt", ["png", "jpg", "qoi"])
def test_a_preview_at_the_pixel_limit_is_kept(fmt: str) -> None:
    side = int(MAX_PIXELS ** 0.5)
    data = {"png": png_claiming, "qoi": qoi_claiming, "jpg": jpg_claiming}[fmt](side, side)
    assert image_size(data, fmt) == (side, side)
    found = read_thumbnails(io.BytesIO(_sliced(thumbnail_block(side, side, fmt, data))))
    assert [(t.width, t.height) for t in found] == [(side, side)]
