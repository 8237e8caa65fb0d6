"""Drawing for real: plans sent through the client to the simulator (in process and over TCP), and the
`draw` / `text` / `preview` commands as subprocesses."""

from __future__ import annotations

import asyncio
import json
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from clitools import cli_env, run_cli
from fabwire import units
from fabwire.lineus.client import LineUs
from fabwire.lineus.draw_cli import send_plan
from fabwire.lineus.plot import plan_file, plan_text
from fabwire.lineus.sim import LineUsSim, SimOptions
from fabwire.transport import memory_pair

sys.path.insert(0, str(Path(__file__).parent))
from test_plot_support import hausdorff, resample, segments, shape_distance

DATA = Path(__file__).parent / "data" / "svg"


async def draw_in_simulator(plan_strokes: object, plan: object, pen_z: float = 0.0) -> LineUsSim:
    sim = LineUsSim(SimOptions(speed=0))
    host, device = memory_pair("lineus")
    server = asyncio.create_task(sim.serve(device))
    async with asyncio.timeout(60):
        arm = await LineUs.connect(host)
        try:
            await send_plan(arm, plan, pen_z=pen_z)  # type: ignore[arg-type]
        finally:
            await arm.close()
        await server
    return sim


@pytest.mark.parametrize("name", ["transforms.svg", "arcs.svg", "use.svg", "text_paths.svg"])
async def test_simulator_draws_what_was_planned(name: str) -> None:
    plan = plan_file(DATA / name)
    sim = await draw_in_simulator(plan.strokes, plan)
    drawn = [np.asarray(s, dtype=float) for s in sim.arm.strokes]
    assert segments(drawn, 1) == segments(plan.strokes, 1)
    assert shape_distance(drawn, list(plan.strokes), flip_expected_y=False) < 1e-3
    assert not any(record.clamped for record in sim.arm.moves)


async def test_simulator_draws_text_with_a_lighter_pen() -> None:
    plan = plan_text("Line-us", size_mm=8)
    sim = await draw_in_simulator(plan.strokes, plan, pen_z=300)
    drawn = [np.asarray(s, dtype=float) for s in sim.arm.strokes]
    assert segments(drawn, 1) == segments(plan.strokes, 1)
    heights = {record.end[2] for record in sim.arm.moves}
    assert heights == {300.0, 1000.0}


def test_preview_json_and_pictures(tmp_path: Path) -> None:
    svg_out, png_out = tmp_path / "p.svg", tmp_path / "p.png"
    result = run_cli("lineus", "preview", str(DATA / "arcs.svg"), "-o", str(svg_out), "-o", str(png_out), "--json",
                     env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout)
    plan = plan_file(DATA / "arcs.svg")
    expected = plan.figures().as_dict()
    assert figures["strokes"] == expected["strokes"]
    assert figures["segments"] == expected["segments"]
    assert figures["pen_down_length_mm"] == pytest.approx(expected["pen_down_length_mm"], rel=1e-3)
    assert figures["estimated_s"] > 0
    assert ET.parse(svg_out).getroot().tag.endswith("svg")
    assert png_out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["preview", "{data}/truncated.svg"], "not a readable SVG"),
        (["preview", "{data}/empty.svg"], "empty.svg: nothing to draw: no shape in it has a visible stroke or fill"),
        (["preview", "{data}/arcs.svg", "-o", "{tmp}/x.pdf"], ".svg or .png"),
        (["draw", "{tmp}/far.gcode", "--dry-run"], "outside the reachable area"),
        (["text", "Far too long a line", "--size", "50", "--dry-run"], "does not fit"),
    ],
)
def test_bad_input_is_one_line_with_exit_code_4(tmp_path: Path, args: list[str], message: str) -> None:
    (tmp_path / "far.gcode").write_text("G01 X1000 Y0 Z0\nG01 X2600 Y0 Z0\n")
    argv = [a.format(data=DATA, tmp=tmp_path) for a in args]
    result = run_cli("lineus", *argv, env=cli_env(tmp_path))
    assert result.returncode == 4, result.stderr
    assert message in result.stderr
    assert "Traceback" not in result.stderr


def test_dry_run_estimates_without_a_device(tmp_path: Path) -> None:
    result = run_cli("--json", "lineus", "-d", "127.0.0.1:9", "draw", str(DATA / "use.svg"), "--dry-run",
                     "--preview", str(tmp_path / "use.png"), env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert data["strokes"] == 3
    assert data["segments"] == 9
    assert (tmp_path / "use.png").exists()
    result = run_cli("lineus", "text", "Hi", "--dry-run", env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    seconds = json.loads(run_cli("--json", "lineus", "text", "Hi", "--dry-run", env=cli_env(tmp_path)).stdout)
    assert f"estimated drawing time {units.duration(seconds['estimated_s'])}\n" in result.stdout
    assert re.search(r"^estimated drawing time (\d+m \d\ds|\d+s)$", result.stdout, re.MULTILINE), result.stdout


def recorded_strokes(path: Path) -> list[np.ndarray]:
    root = ET.parse(path).getroot()
    ns = {"svg": "http://www.w3.org/2000/svg"}
    group = root.find("svg:g[@id='strokes']", ns)
    assert group is not None
    out = []
    for line in group.findall("svg:polyline", ns):
        pts = [tuple(map(float, p.split(","))) for p in line.get("points", "").split()]
        out.append(np.array([(x, -y) for x, y in pts]))
    return out


def test_draw_over_tcp_then_resume_after_a_dropped_link(tmp_path: Path, simulator) -> None:  # type: ignore[no-untyped-def]
    record = tmp_path / "drawn.svg"
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0", "--record", str(record))
    state = tmp_path / "progress.json"
    drawing = DATA / "arcs.svg"
    env = cli_env(tmp_path)
    # The link drops part way through: the progress so far is kept.
    first = run_cli("lineus", "-d", sim.url, "--inject", "disconnect_after=5000", "draw", str(drawing),
                    "--state", str(state), env=env)
    assert first.returncode == 8, first.stderr
    assert "--resume" in first.stderr
    saved = json.loads(state.read_text())
    assert 0 < saved["done"] < len(saved["strokes"])
    second = run_cli("--json", "lineus", "-d", sim.url, "draw", str(drawing), "--state", str(state), "--resume",
                     env=env)
    assert second.returncode == 0, second.stderr
    result = json.loads(second.stdout)
    assert result["resumed_at"] == saved["done"]
    assert result["drawn"] == len(saved["strokes"]) - saved["done"]
    # the resume says how long the rest takes, in the shared duration style
    assert re.search(r"; about (\d+m \d\ds|\d+s) left$", second.stderr, re.MULTILINE), second.stderr
    finished = json.loads(state.read_text())
    assert finished["done"] == len(finished["strokes"])
    # Resuming a finished drawing draws nothing and says so.
    again = run_cli("--json", "lineus", "-d", sim.url, "draw", str(drawing), "--state", str(state), "--resume",
                    env=env)
    assert again.returncode == 0, again.stderr
    assert json.loads(again.stdout) == {"file": str(drawing), "complete": True, "strokes": len(saved["strokes"]),
                                        "drawn": 0}
    told = run_cli("lineus", "-d", sim.url, "draw", str(drawing), "--state", str(state), "--resume", env=env)
    assert "--restart" in told.stdout
    both = run_cli("lineus", "-d", sim.url, "draw", str(drawing), "--resume", "--restart", env=env)
    assert both.returncode == 4
    sim.process.terminate()  # the simulator writes its record on exit
    sim.process.wait(20)
    drawn = recorded_strokes(record)
    planned = [np.asarray(s) for s in saved["strokes"]]
    # Everything planned is on the paper, and nothing else is (the record keeps 0.1-unit precision) ...
    planned_pts = resample(planned, 1.0)
    drawn_pts = resample(drawn, 1.0)
    assert hausdorff(planned_pts, drawn_pts) < 0.7  # sampling every unit: at most half a unit apart
    # ... and the interrupted stroke carried on from its last acknowledged vertex instead of starting over: at most
    # the one segment the arm finished while its reply was lost is inked twice.
    def ink(lines: list[np.ndarray]) -> float:
        return sum(float(np.hypot(*np.diff(line, axis=0).T).sum()) for line in lines if len(line) > 1)

    longest = max(float(np.hypot(*np.diff(line, axis=0).T).max()) for line in planned if len(line) > 1)
    assert ink(planned) - 1 <= ink(drawn) <= ink(planned) + longest + 1


def test_progress_state_keeps_the_last_acknowledged_vertex(tmp_path: Path) -> None:
    from fabwire.errors import InputError
    from fabwire.lineus.draw_cli import DrawProgress

    path = tmp_path / "state.json"
    strokes = [[[900.0, 0.0], [1000.0, 0.0]], [[1100.0, 0.0], [1200.0, 0.0], [1300.0, 0.0], [1400.0, 0.0]]]
    progress = DrawProgress(path, "k", strokes)
    progress.reached(1, 2)  # stroke 2 drawn up to its third vertex
    progress.save()
    loaded = DrawProgress.load(path, "k")
    assert loaded is not None
    assert (loaded.done, loaded.point, loaded.complete) == (1, 2, False)
    rest = loaded.remaining()
    assert [s.tolist() for s in rest.strokes] == [[[1300.0, 0.0], [1400.0, 0.0]]]  # from where the pen was lifted
    whole_stroke = DrawProgress(path, "k", strokes[1:]).remaining().figures().estimated_seconds
    assert rest.figures().estimated_seconds < whole_stroke  # the time left counts only what is left
    for damaged in ({"done": 1, "point": 4}, {"done": 2, "point": 1}, {"done": 1, "point": -1},
                    {"done": 1, "point": "2"}):
        path.write_text(json.dumps({"version": 1, "key": "k", "strokes": strokes, **damaged}))
        with pytest.raises(InputError, match="damaged"):
            DrawProgress.load(path, "k")
    path.write_text(json.dumps({"version": 1, "key": "k", "strokes": strokes, "done": 2}))  # finished, older file
    finished = DrawProgress.load(path, "k")
    assert finished is not None
    assert finished.complete
