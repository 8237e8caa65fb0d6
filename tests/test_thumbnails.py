"""Slicer previews embedded in G-code: every row of the block table (as browser images and as the PNG a
notification attaches), damaged blocks, and any input at all."""

from __future__ import annotations

import base64
import io
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from agent.doortools import preview, prusaslicer_gcode, thumbnail_block
from fabwire.thumbnails import BLOCKS, Block, best_png, read_thumbnails

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
