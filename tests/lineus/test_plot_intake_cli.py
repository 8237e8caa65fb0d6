"""Drawings through the command line: standard input and compressed files, text with letters the font lacks,
rotation before the size check, the app area versus the whole area, preview resolution."""

from __future__ import annotations

import gzip
import json
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from clitools import cli_env, run_cli
from fabwire.errors import InputError
from fabwire.lineus.plot import PlanOptions, intake, plan_file, plan_text, text_lines

DATA = Path(__file__).parent / "data" / "svg"


def run_bytes(tmp_path: Path, data: bytes, *args: str) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run([sys.executable, "-m", "fabwire", *args], input=data, capture_output=True, timeout=60,
                          env=cli_env(tmp_path))


def figures(stdout: str | bytes) -> dict[str, object]:
    data: dict[str, object] = json.loads(stdout)
    return {k: data[k] for k in ("strokes", "segments", "pen_down_length_mm", "pen_up_travel_mm")}


def test_preview_and_draw_read_the_drawing_from_standard_input(tmp_path: Path) -> None:
    from_file = run_cli("lineus", "preview", str(DATA / "arcs.svg"), "--json", env=cli_env(tmp_path))
    assert from_file.returncode == 0, from_file.stderr
    piped = run_cli("lineus", "preview", "-", "--json", "-o", str(tmp_path / "p.svg"), env=cli_env(tmp_path),
                    input_text=(DATA / "arcs.svg").read_text())
    assert piped.returncode == 0, piped.stderr
    assert figures(piped.stdout) == figures(from_file.stdout)
    assert (tmp_path / "p.svg").read_text().count("<polyline") > 0
    packed = run_bytes(tmp_path, gzip.compress((DATA / "arcs.svg").read_bytes()), "--json", "lineus", "draw", "-",
                       "--dry-run")
    assert packed.returncode == 0, packed.stderr
    assert figures(packed.stdout) == figures(from_file.stdout)


def test_gcode_from_standard_input_and_junk_refused(tmp_path: Path) -> None:
    gcode = "G01 X900 Y300 Z1000\nG01 X900 Y-300 Z0\nG01 X1200 Y-300 Z0\nG01 Z1000\n"
    result = run_cli("--json", "lineus", "draw", "-", "--dry-run", env=cli_env(tmp_path), input_text=gcode)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["segments"] == 1  # the pen lands at (900, -300), then one line
    junk = run_bytes(tmp_path, b"\x89PNG\r\n\x1a\n\x00\x00", "lineus", "preview", "-")
    assert junk.returncode == 4
    err = junk.stderr.decode()
    assert "standard input" in err
    assert "neither SVG nor G-code" in err
    assert "Traceback" not in err
    empty = run_bytes(tmp_path, b"", "lineus", "preview", "-")
    assert empty.returncode == 4
    assert b"standard input: nothing to draw: it has no pen-down moves" in empty.stderr


def test_compressed_svg_through_the_cli(tmp_path: Path) -> None:
    result = run_cli("lineus", "preview", str(DATA / "compressed.svgz"), "--json", env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert data["strokes"] == 1
    assert data["segments"] == 4


def test_accented_letters_are_drawn_and_the_rest_named(tmp_path: Path) -> None:
    notes: list[str] = []
    plain = text_lines("Gre", notes=notes)
    accented = text_lines("Größe", notes=notes)
    assert len(accented) > len(plain) + 2  # o with two dots, and ß as "ss"
    sharp_s, ss = text_lines("ß"), text_lines("ss")
    assert len(sharp_s) == len(ss)
    assert all(np.allclose(a, b) for a, b in zip(sharp_s, ss, strict=True))
    assert "drawn as letters with accent strokes: 'ö' (U+00F6)" in notes
    assert "spelled with other characters: 'ß' (U+00DF) as 'ss'" in notes
    e_acute = text_lines("é")
    assert len(e_acute) == len(text_lines("e")) + 1
    # The accent sits above the letter's top.
    assert min(p[:, 1].min() for p in e_acute[-1:]) > max(p[:, 1].max() for p in text_lines("e"))
    result = run_cli("lineus", "text", "Café 漢字", "--size", "3", "--rotate", "auto", "--dry-run",
                     env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    assert "'漢'" in result.stderr
    assert "'字'" in result.stderr
    assert "'é'" in result.stderr
    nothing = run_cli("lineus", "text", "漢字", "--dry-run", env=cli_env(tmp_path))
    assert nothing.returncode == 4
    assert "no strokes" in nothing.stderr


def test_rotation_comes_before_the_size_check(tmp_path: Path) -> None:
    upright = run_cli("lineus", "text", "Line-us text", "--size", "8", "--rotate", "0", "--dry-run",
                      env=cli_env(tmp_path))
    assert upright.returncode == 4
    assert "--rotate auto" in upright.stderr
    by_default = run_cli("--json", "lineus", "text", "Line-us text", "--size", "8", "--dry-run", env=cli_env(tmp_path))
    assert by_default.returncode == 0, by_default.stderr  # text runs along the area's long side unless told
    for rotate in ("90", "auto"):
        turned = run_cli("--json", "lineus", "text", "Line-us text", "--size", "8", "--rotate", rotate, "--dry-run",
                         env=cli_env(tmp_path))
        assert turned.returncode == 0, turned.stderr
    plan = plan_text("Line-us text", PlanOptions(rotate_auto=True), size_mm=8)
    xs, ys = [s[:, 0] for s in plan.strokes], [s[:, 1] for s in plan.strokes]
    width = max(x.max() for x in xs) - min(x.min() for x in xs)
    height = max(y.max() for y in ys) - min(y.min() for y in ys)
    assert height > 3 * width  # runs along the area's long side
    bad = run_cli("lineus", "text", "Hi", "--rotate", "sideways", "--dry-run", env=cli_env(tmp_path))
    assert bad.returncode == 2
    assert "sideways" in bad.stderr


def test_app_area_by_default_whole_area_on_request(tmp_path: Path) -> None:
    default = run_cli("--json", "lineus", "preview", str(DATA / "transforms.svg"), env=cli_env(tmp_path))
    full = run_cli("--json", "lineus", "preview", str(DATA / "transforms.svg"), "--full-area", env=cli_env(tmp_path))
    assert default.returncode == 0, default.stderr
    assert full.returncode == 0, full.stderr
    assert json.loads(full.stdout)["pen_down_length_mm"] > 1.05 * json.loads(default.stdout)["pen_down_length_mm"]
    plan = plan_file(DATA / "transforms.svg")
    points = np.concatenate(plan.strokes)
    assert points[:, 0].min() >= 650 - 1e-6
    assert points[:, 0].max() <= 1775 + 1e-6
    assert np.abs(points[:, 1]).max() <= 1000 + 1e-6


@pytest.mark.parametrize("dpi", ["75", "300"])
def test_preview_resolution(tmp_path: Path, dpi: str) -> None:
    out = tmp_path / f"p{dpi}.png"
    result = run_cli("lineus", "preview", str(DATA / "use.svg"), "-o", str(out), "--dpi", dpi, env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    with Image.open(out) as image:
        width_mm = image.size[0] / float(dpi) * 25.4
    assert 110 < width_mm < 125  # the machine's frame (body to outer reach) at paper size, whatever the dpi


@pytest.mark.parametrize("packed", [False, True])
def test_an_oversized_drawing_is_refused_holding_no_more_than_the_limit(monkeypatch: pytest.MonkeyPatch,
                                                                        tmp_path: Path, packed: bool) -> None:
    limit = 8 << 20
    monkeypatch.setattr(intake, "MAX_INPUT", limit)
    body = b"<svg xmlns='http://www.w3.org/2000/svg'>" + b" " * (32 << 20) + b"</svg>"
    path = tmp_path / ("bomb.svgz" if packed else "big.svg")
    path.write_bytes(gzip.compress(body, 1) if packed else body)
    del body
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match=("expands to more than 8 MB" if packed else "larger than 8 MB")):
            intake.read_drawing(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < limit * 1.5  # the limit and a piece or two: never the whole expansion, never a second copy


@pytest.mark.parametrize(("text", "illegible"), [("hello world", False), ("a much longer line " * 4, True),
                                                 ("x" * 3000, True), ("\n".join(["line of text"] * 6), False)])
def test_text_fitted_too_small_to_read_is_called_out(tmp_path: Path, text: str, illegible: bool) -> None:
    result = run_cli("lineus", "text", text, "--dry-run", env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    assert ("too small to read" in result.stderr) is illegible
    if illegible:
        assert result.stderr.count("\n") == 1  # one line of warning before the figures on stdout


@pytest.mark.parametrize("d", ["M1 1 L1e308 5", "M1 1 L5 -1e308", "M1e308 1e308 L1 1", "M1 1 L3.5e38 1"])
def test_coordinates_beyond_a_browser_end_the_path_in_one_line_naming_the_file(tmp_path: Path, d: str) -> None:
    # Browsers hold path numbers in single precision: one beyond it is an error, and the path is drawn up to it.
    path = tmp_path / "far.svg"
    path.write_text(f"<svg xmlns='http://www.w3.org/2000/svg' width='10' height='10'><path d='{d}' "
                    "stroke='black'/></svg>")
    result = run_cli("lineus", "preview", str(path), "-o", str(tmp_path / "far.png"), env=cli_env(tmp_path))
    assert result.returncode == 4
    assert result.stderr == f"fabwire: error: {path}: nothing to draw: no shape in it has a visible stroke or fill " \
                            "(<path> data with an error (a number beyond what a browser can hold) is drawn up to the " \
                            "error, as browsers do)\n"  # no numpy warning before it


def test_preview_json_carries_the_plans_notes(tmp_path: Path) -> None:
    svg = tmp_path / "with-image.svg"
    svg.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100"><image href="a.png" '
                   'width="10" height="10"/><rect x="10" y="10" width="50" height="50"/></svg>')
    result = run_cli("lineus", "preview", str(svg), "--json", env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert any("image" in note for note in data["notes"]), data["notes"]
    assert all(note in result.stderr for note in data["notes"])
