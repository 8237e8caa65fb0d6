"""`fabwire demo` end to end: real simulator processes, real files, nothing left running."""

from __future__ import annotations

import json
from pathlib import Path

from clitools import cli_env, run_cli
from fabwire.samples import SAMPLE_GCODE, sample_path
from fabwire.xyz.threew import read_3w

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
SPEED = "60"


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False
    return state != "Z"


def _assert_png(path: Path) -> None:
    data = path.read_bytes()
    assert data.startswith(PNG_SIGNATURE), path
    assert len(data) > 2000, path


def test_full_demo_writes_valid_files_and_stops_every_simulator(tmp_path: Path) -> None:
    out = tmp_path / "out"
    done = run_cli("--json", "demo", "--out", str(out), "--speed", SPEED, timeout=120, env=cli_env(tmp_path))
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["ok"] is True
    assert {s["device"] for s in summary["steps"]} >= {"xyz", "lineus", "mmu"}
    files = {Path(f["path"]).name: Path(f["path"]) for f in summary["files"]}
    assert set(files) == {"calibration-square.3w", "lineus-preview.png", "lineus-drawn.png"}
    _assert_png(files["lineus-preview.png"])
    _assert_png(files["lineus-drawn.png"])
    gcode = read_3w(files["calibration-square.3w"]).gcode
    for line in sample_path(SAMPLE_GCODE).read_text().splitlines():
        if line.startswith(("G1 ", "G28")):
            assert line.encode() in gcode
    details = {s["step"]: s["detail"] for s in summary["steps"] if s["device"] == "mmu"}
    assert details["tool change T0"] == "finished"
    assert details["tool change T2"] == "finished"
    assert details["tool change T1"] == "recovered from 04101 FINDA DIDN'T TRIGGER (0x8001) by Retry"
    assert "pressing Retry" in done.stderr
    assert "print finished" in done.stderr
    pids = [s["pid"] for s in summary["simulators"]]
    assert len(pids) == 3
    assert not [pid for pid in pids if _alive(pid)]


def test_only_mmu_runs_only_the_mmu_and_prints_a_table(tmp_path: Path) -> None:
    out = tmp_path / "out"
    done = run_cli("demo", "--only", "mmu", "--out", str(out), "--speed", SPEED, timeout=90, env=cli_env(tmp_path))
    assert done.returncode == 0, done.stderr
    assert "tool change T2" in done.stderr
    assert ("the MMU stopped: 04101 FINDA DIDN'T TRIGGER (0x8001) during T1 — FINDA didn't trigger; check the "
            "filament path, then Retry") in " ".join(done.stderr.split())
    assert "da Vinci" not in done.stderr
    assert "Line-us" not in done.stderr
    assert done.stdout == ""
    assert list(out.iterdir()) == []


def test_json_only_xyz_lists_the_print_file(tmp_path: Path) -> None:
    done = run_cli("--json", "demo", "--only", "xyz", "--out", str(tmp_path), "--speed", SPEED, timeout=90,
                   env=cli_env(tmp_path))
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert [f["path"] for f in summary["files"]] == [str(tmp_path.resolve() / "calibration-square.3w")]
    assert [s["device"] for s in summary["simulators"]] == ["xyz"]
    assert not _alive(summary["simulators"][0]["pid"])


def test_unwritable_output_is_one_clear_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    done = run_cli("demo", "--out", str(blocker / "sub"), "--only", "mmu", env=cli_env(tmp_path))
    assert done.returncode == 4
    assert done.stderr.strip().startswith("fabwire: error: cannot create the output directory")
    assert "Traceback" not in done.stderr


def test_keep_running_shows_the_tour_table_before_waiting_and_ctrl_c_stops_the_simulators(tmp_path: Path) -> None:
    import signal
    import subprocess
    import sys

    process = subprocess.Popen([sys.executable, "-m", "fabwire", "--json", "demo", "--only", "mmu", "--out",
                                str(tmp_path / "out"), "--speed", SPEED, "--keep-running"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=cli_env(tmp_path))
    try:
        assert process.stdout is not None
        summary = json.loads(process.stdout.readline())  # while the simulators are still up
        assert summary["ok"] is True
        pids = [s["pid"] for s in summary["simulators"]]
        assert pids
        assert process.stderr is not None
        said = []  # the tour, then how to reach the simulators
        for line in iter(process.stderr.readline, ""):
            said.append(line)
            if line == "Press Ctrl-C to stop them.\n":
                break
        assert said[-1] == "Press Ctrl-C to stop them.\n", said
        assert all(_alive(pid) for pid in pids)
        process.send_signal(signal.SIGINT)
        process.wait(60)
        rest, err = process.stdout.read(), process.stderr.read()  # the same buffered readers as above
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(10)
    assert process.returncode == 0, err
    assert rest == ""  # the table is said once
    assert err == "stopping the simulators …\n"
    assert not [pid for pid in pids if _alive(pid)]


def test_keep_running_keeps_the_drawing_of_your_session(tmp_path: Path) -> None:
    import re
    import signal
    import subprocess
    import sys

    out = tmp_path / "out"
    process = subprocess.Popen([sys.executable, "-m", "fabwire", "demo", "--only", "lineus", "--out", str(out),
                                "--speed", SPEED, "--keep-running"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=cli_env(tmp_path))
    try:
        assert process.stderr is not None
        said = []
        for line in iter(process.stderr.readline, ""):
            said.append(line)
            if line == "Press Ctrl-C to stop them.\n":
                break
        advice = next(line for line in said if "fabwire lineus -d " in line)
        url = re.search(r"-d (\S+)", advice)
        assert url is not None, advice
        drawn = run_cli("lineus", "-d", url.group(1), "text", "hi", timeout=120, env=cli_env(tmp_path))
        assert drawn.returncode == 0, drawn.stderr
        process.send_signal(signal.SIGINT)
        process.wait(60)
        err = process.stderr.read()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(10)
    assert process.returncode == 0, err
    session = out / "lineus-session.png"
    assert f"what the arm drew in your session: {session}" in " ".join(err.split())
    _assert_png(session)
