"""The Line-us commands inside real vpype pipelines (subprocesses of the installed `vpype`), drawing on
`fabwire sim lineus --record`."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import vpype_cli

from clitools import cli_env, run_cli
from fabwire.lineus.plot import parse_gcode

sys.path.insert(0, str(Path(__file__).parents[1] / "lineus"))
from test_draw_cli import recorded_strokes
from test_plot_support import hausdorff, resample

VPYPE = str(Path(sys.executable).with_name("vpype"))
MM = 20.0
"""Line-us machine units per mm."""
TWO_LAYERS = "rect 0 0 8cm 4cm circle --layer 2 2cm 2cm 1.5cm line --layer 2 0 0 8cm 4cm"


def vpype(*args: str, tmp_path: Path, stdin: str = "") -> subprocess.CompletedProcess[str]:
    env = cli_env(tmp_path)
    env["XDG_STATE_HOME"] = str(tmp_path / "state")
    return subprocess.run([VPYPE, *args], capture_output=True, text=True, timeout=120, env=env, input=stdin)


def machine_lines(document: object, layer_id: int) -> list[np.ndarray]:
    """A fitted document's layer in Line-us machine units: the page's top-left corner at (650, 1000), 96 px per
    inch, y up."""
    k = 25.4 / 96 * MM
    layer = document.layers[layer_id]  # type: ignore[attr-defined]
    return [np.column_stack([650 + line.real * k, 1000 - line.imag * k]) for line in layer]


def ink_length(lines: list[np.ndarray]) -> float:
    return sum(float(np.hypot(*np.diff(line, axis=0).T).sum()) for line in lines)


def fitted_lines() -> list[np.ndarray]:
    """What the test pipeline's document is after lineus-fit, computed in this process through vpype's API."""
    fitted = vpype_cli.execute(f"{TWO_LAYERS} lineus-fit")
    return machine_lines(fitted, 1) + machine_lines(fitted, 2)


def test_the_commands_appear_in_vpype_help(tmp_path: Path) -> None:
    result = vpype("--help", tmp_path=tmp_path)
    assert result.returncode == 0, result.stderr
    for name in ("lineus-fit", "lineus-stat", "lineus-preview", "lineus-draw", "lineus-gcode"):
        assert f"\n    {name} " in result.stdout
    assert "Line-us (fabwire)" in result.stdout


def test_pipeline_draws_each_layer_after_a_pen_change_and_the_ink_is_the_fitted_document(
        tmp_path: Path, simulator) -> None:  # type: ignore[no-untyped-def]
    record = tmp_path / "drawn.svg"
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0", "--record", str(record))
    result = vpype(*TWO_LAYERS.split(), "lineus-fit", "lineus-draw", "-d", sim.url, tmp_path=tmp_path, stdin="\n")
    assert result.returncode == 0, result.stderr
    assert result.stderr.count("pen change: put in the pen for layer 2") == 1
    assert "drew 3 of 3 strokes" in result.stderr
    sim.process.terminate()  # the simulator writes its record on exit
    sim.process.wait(20)
    expected = fitted_lines()
    drawn = recorded_strokes(record)
    # Every fitted line is on the paper and nothing else is (the record keeps 0.1-unit precision), once.
    assert hausdorff(resample(expected, 1.0), resample(drawn, 1.0)) < 0.7
    assert abs(ink_length(drawn) - ink_length(expected)) < 0.002 * ink_length(expected)


def test_no_answer_at_the_pen_change_stops_and_resume_draws_only_the_rest(
        tmp_path: Path, simulator) -> None:  # type: ignore[no-untyped-def]
    record = tmp_path / "drawn.svg"
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0", "--record", str(record))
    state = tmp_path / "progress.json"
    pipeline = [*TWO_LAYERS.split(), "lineus-fit", "lineus-draw", "-d", sim.url, "--state", str(state)]
    first = vpype(*pipeline, tmp_path=tmp_path)  # standard input is empty: nobody changes the pen
    assert first.returncode == 4, first.stderr
    assert "no answer on standard input for the pen change before layer 2" in first.stderr
    assert "--resume" in first.stderr
    assert "Traceback" not in first.stderr
    saved = json.loads(state.read_text())
    assert saved["done"] == 1
    assert saved["strokes"][1] == []
    second = vpype(*pipeline, "--resume", tmp_path=tmp_path, stdin="\n")
    assert second.returncode == 0, second.stderr
    assert "pen change: put in the pen for layer 2" in second.stderr
    assert "drew 2 of 3 strokes" in second.stderr
    assert not state.exists()
    sim.process.terminate()
    sim.process.wait(20)
    drawn, expected = recorded_strokes(record), fitted_lines()
    assert hausdorff(resample(expected, 1.0), resample(drawn, 1.0)) < 0.7
    assert abs(ink_length(drawn) - ink_length(expected)) < 0.002 * ink_length(expected)  # nothing drawn twice


def test_no_pause_draws_all_layers_without_asking(tmp_path: Path, simulator) -> None:  # type: ignore[no-untyped-def]
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    result = vpype(*TWO_LAYERS.split(), "lineus-fit", "lineus-draw", "-d", sim.url, "--no-pause", "-l", "2",
                   tmp_path=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "pen change" not in result.stderr
    assert "drew 2 of 2 strokes" in result.stderr


def test_gcode_file_is_the_plan_and_the_line_us_stores_it(tmp_path: Path, simulator) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "drawing.gcode"
    result = vpype(*TWO_LAYERS.split(), "lineus-fit", "lineus-stat", "--json", "--no-optimize", "lineus-gcode",
                   "--no-optimize", str(out), tmp_path=tmp_path)
    assert result.returncode == 0, result.stderr
    stat = json.loads(result.stdout)
    assert [layer["layer"] for layer in stat["layers"]] == [1, 2]
    expected = fitted_lines()
    parsed = parse_gcode(out)
    assert len(parsed) == len(expected)
    for got, want in zip(parsed, expected, strict=True):
        np.testing.assert_allclose(got, want, atol=1e-3)
    preview = run_cli("--json", "lineus", "preview", str(out), "--no-optimize", env=cli_env(tmp_path))
    assert preview.returncode == 0, preview.stderr
    assert json.loads(preview.stdout)["pen_down_length_mm"] == stat["pen_down_length_mm"]
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    stored = run_cli("--json", "lineus", "-d", sim.url, "files", "save", str(out), "3", env=cli_env(tmp_path))
    assert stored.returncode == 0, stored.stderr


def test_preview_writes_pictures(tmp_path: Path) -> None:
    svg, png = tmp_path / "plan.svg", tmp_path / "plan.png"
    result = vpype(*TWO_LAYERS.split(), "lineus-fit", "lineus-preview", "-o", str(svg), "-o", str(png),
                   tmp_path=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "all 2 layers" in result.stdout
    assert svg.read_text().count("<polyline") >= 3
    assert png.read_bytes().startswith(b"\x89PNG")


def test_unplaced_document_is_refused_with_a_hint(tmp_path: Path) -> None:
    result = vpype("rect", "0", "0", "30cm", "30cm", "lineus-stat", tmp_path=tmp_path)
    assert result.returncode == 4
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "lie outside the reachable area" in lines[0]
    assert "lineus-fit" in lines[0]


def test_empty_document_and_unreachable_device_fail_in_one_line(tmp_path: Path) -> None:
    empty = vpype("lineus-fit", tmp_path=tmp_path)
    assert empty.returncode == 4
    assert "empty" in empty.stderr
    assert "Traceback" not in empty.stderr
    with socket.socket() as s:  # a loopback port that nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    closed = vpype("rect", "0", "0", "2cm", "2cm", "lineus-fit", "lineus-draw", "-d", f"127.0.0.1:{port}",
                   "--timeout", "2", tmp_path=tmp_path)
    assert closed.returncode == 8, closed.stderr
    assert "Traceback" not in closed.stderr


def test_clip_keeps_only_the_reachable_part(tmp_path: Path) -> None:
    result = vpype("rect", "0", "0", "30cm", "30cm", "lineus-fit", "--no-scale", "--clip", "lineus-stat", "--json",
                   tmp_path=tmp_path)
    assert result.returncode == 0, result.stderr
    stat = json.loads(result.stdout)
    assert 0 < stat["pen_down_length_mm"] < 1200  # part of the 1200 mm outline


PLOTTING_ONLY = ("fabwire.lineus.draw_cli", "fabwire.lineus.render", "fabwire.vpype.drawing", "fabwire.lineus.client",
                 "rich", "PIL")
"""What only lineus-draw, lineus-preview and the text figures use (modules and packages)."""
PROBE = """
import runpy, sys
sys.argv = [VPYPE, "rect", "0", "0", "4cm", "3cm", "lineus-fit", "lineus-stat", "--json"]
try:
    runpy.run_path(VPYPE, run_name="__main__")
except SystemExit as exc:
    assert not exc.code, exc.code
print(sorted(m for m in sys.modules if m in PLOTTING_ONLY or m.split(".")[0] in PLOTTING_ONLY), file=sys.stderr)
"""


def test_vpype_starts_without_the_drawing_machinery(tmp_path: Path) -> None:
    """vpype loads every plugin each time it starts, whatever the pipeline: placing and planning (lineus-fit,
    lineus-stat --json) run without importing the link, the progress bars or the picture code."""
    script = f"VPYPE = {VPYPE!r}\nPLOTTING_ONLY = {PLOTTING_ONLY!r}\n{PROBE}"
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
                            env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["strokes"] == 1
    assert result.stderr.strip().splitlines()[-1] == "[]"


@pytest.mark.parametrize("budget", ["nan", "inf", "-1", "1e20", "1e308", "601"])
def test_an_ordering_budget_out_of_range_is_one_line_not_a_traceback(budget: str, tmp_path: Path) -> None:
    result = vpype("rect", "0", "0", "10", "10", "lineus-stat", "--optimize-time", budget, tmp_path=tmp_path)
    assert result.returncode != 0
    assert "Traceback" not in result.stderr
    assert "600" in result.stderr.strip().splitlines()[-1]  # the limit is named
