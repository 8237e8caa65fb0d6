"""Slicer previews embedded in G-code: every row of the block table, damaged blocks, and any input at all."""

from __future__ import annotations

import base64
import io

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from agent.doortools import preview, prusaslicer_gcode, thumbnail_block
from fabwire.thumbnails import BLOCKS, read_thumbnails


@pytest.mark.parametrize("block", BLOCKS, ids=lambda b: b.marker)
def test_each_slicer_block_is_read_and_shown_as_a_browser_image(block: object) -> None:
    """Each row of `BLOCKS` (its source is in the row): the block PrusaSlicer/Orca/Cura write is found before the
    first command, decoded to the stated size, and served as PNG or JPEG (QOI converted, as Moonraker does)."""
    fmt = block.format  # type: ignore[attr-defined]
    data = prusaslicer_gcode(thumbs=[(16, 16, "png"), (96, 64, fmt)])
    found = read_thumbnails(io.BytesIO(data))
    assert [(t.width, t.height, t.format) for t in found] == [(16, 16, "png"), (96, 64, fmt)]
    image, media = found[1].web_image()
    assert media == ("image/jpeg" if fmt == "jpg" else "image/png")
    with Image.open(io.BytesIO(image)) as decoded:
        assert decoded.size == (96, 64)
        assert decoded.format == ("JPEG" if fmt == "jpg" else "PNG")


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
