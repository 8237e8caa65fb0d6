"""A command never destroys a user's file by writing over it: a preview named like its drawing, a capture named
like a G-code file. Earlier captures are still replaced (a trace file is reused run after run)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from clitools import run_cli

SVG = '<svg xmlns="http://www.w3.org/2000/svg" width="20" height="20"><path d="M1 1 L15 15" stroke="black"/></svg>'


@pytest.mark.parametrize("spelling", ["same", "relative", "symlink"])
def test_a_preview_over_its_own_drawing_is_refused(tmp_path: Path, spelling: str) -> None:
    drawing = tmp_path / "art.svg"
    drawing.write_text(SVG)
    output = {"same": str(drawing), "relative": os.path.relpath(drawing),
              "symlink": str(tmp_path / "link.svg")}[spelling]
    if spelling == "symlink":
        (tmp_path / "link.svg").symlink_to(drawing)
    result = run_cli("lineus", "preview", str(drawing), "-o", output, timeout=60)
    assert result.returncode == 4, result.stderr
    assert "is the drawing being previewed" in result.stderr
    assert drawing.read_text() == SVG


def test_a_capture_never_replaces_a_file_that_is_no_capture(tmp_path: Path) -> None:
    gcode = tmp_path / "part.gcode"
    gcode.write_text("G28\nG1 X10 Y10\n")
    refused = run_cli("xyz", "-d", "sim://xyz?speed=1000", "status", "--trace", str(gcode), timeout=60)
    assert refused.returncode == 4
    assert "is not a fabwire trace: not overwriting it" in refused.stderr
    assert gcode.read_text() == "G28\nG1 X10 Y10\n"
    capture = tmp_path / "run.trace"
    for _ in range(2):  # the second run replaces the first capture
        done = run_cli("xyz", "-d", "sim://xyz?speed=1000", "status", "--trace", str(capture), timeout=60)
        assert done.returncode == 0, done.stderr
    assert capture.read_text().count('"trace": "fabwire"') == 1
