"""A G-code whose preview claims a decompression bomb's size is kept and prints, without that preview, through a
real `fabwire serve` (the Moonraker door's upload, metadata and thumbnail files, and the agent's library)."""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterator

import pytest

from .agenttools import RunningAgent, start_agent
from .doortools import multipart, prusaslicer_gcode, thumbnail_block


def png_bomb(width: int, height: int) -> bytes:
    """A small PNG whose IHDR (PNG spec §11.2.2) claims `width`×`height` 8-bit grey pixels."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\0" * (width + 1) * 8, 9)) + chunk(b"IEND", b""))


@pytest.fixture(scope="module")
def agent(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningAgent]:
    running = start_agent(tmp_path_factory.mktemp("thumbs") / "state", "--demo")
    yield running
    running.stop()


def test_a_bomb_preview_is_dropped_and_logged_and_the_file_kept(agent: RunningAgent) -> None:
    sliced = prusaslicer_gcode(thumbs=[(16, 16, "png")])
    head, _, body = sliced.partition(b"; thumbnail begin")
    gcode = head + thumbnail_block(30000, 30000, "png", png_bomb(30000, 30000)).encode() + b"; thumbnail begin" + body
    form, ctype = multipart([("root", "gcodes")], "bomb.gcode", gcode)
    with agent.client() as client:
        answer = client.post("/server/files/upload", content=form, headers={"Content-Type": ctype})
        assert answer.status_code == 201, answer.text
        meta = client.get("/server/files/metadata", params={"filename": "bomb.gcode"})
        assert meta.status_code == 200, meta.text
        thumbs = meta.json()["result"]["thumbnails"]
        assert [(t["width"], t["height"]) for t in thumbs] == [(16, 16)]
        image = client.get(f"/server/files/gcodes/{thumbs[0]['thumbnail_path']}")
        assert image.status_code == 200
        assert image.content.startswith(b"\x89PNG")
        assert b"IHDR\x00\x00u0" not in image.content
        listed = client.get("/server/files/list").json()["result"]
        assert "bomb.gcode" in [f["path"] for f in listed]
    _code, log = agent.stop()
    assert "preview is dropped" in log, log
    assert "Traceback" not in log, log
