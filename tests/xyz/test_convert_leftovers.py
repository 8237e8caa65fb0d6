"""`xyz convert` writes beside its output and renames at the end; a run killed half-way (a power cut, SIGKILL)
leaves a temporary that the next run removes, and never a partial output."""

from __future__ import annotations

import fcntl
import signal
import subprocess
import sys
import time
from pathlib import Path

from clitools import cli_env, run_cli
from fabwire.xyz.threew import convert_gcode_file, read_3w

GCODE = b";FLAVOR:Marlin\nG28\n" + b"".join(b"G1 X%d.%d Y%d E%d.1 F1200\n" % (i % 200, i % 10, (i * 7) % 200, i)
                                            for i in range(2000))


def test_leftovers_of_killed_runs_go_and_a_live_writers_stays(tmp_path: Path) -> None:
    src = tmp_path / "in.gcode"
    src.write_bytes(GCODE)
    same = tmp_path / ".out.3w.abcd1234.part"
    other = tmp_path / ".other.3w.efgh5678.part"
    unrelated = tmp_path / ".notes.txt.ijkl9012.part"  # not ours: left alone
    live = tmp_path / ".live.3w.mnop3456.part"
    for path in (same, other, unrelated, live):
        path.write_bytes(b"partial")
    with live.open("rb") as held:
        fcntl.flock(held.fileno(), fcntl.LOCK_EX)  # a convert still writing it
        convert_gcode_file(src, tmp_path / "out.3w")
        assert sorted(p.name for p in tmp_path.glob(".*.part")) == sorted([unrelated.name, live.name])
    assert read_3w(tmp_path / "out.3w")


def test_a_killed_convert_leaves_no_partial_output_and_the_next_run_cleans_up(tmp_path: Path) -> None:
    src = tmp_path / "big.gcode"
    src.write_bytes(b";FLAVOR:Marlin\nG28\n" + b"".join(
        b"G1 X%d.%d Y%d E%d.1 F1200\n" % (i % 200, i % 10, (i * 7) % 200, i) for i in range(400_000)))
    out = tmp_path / "out.3w"
    proc = subprocess.Popen([sys.executable, "-m", "fabwire", "xyz", "convert", str(src), str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=cli_env(tmp_path))
    while proc.poll() is None and not list(tmp_path.glob(".out.3w.*.part")):
        time.sleep(0.01)  # until it writes (or has finished)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    if out.exists():  # it finished before the kill: then whole
        assert run_cli("xyz", "info", str(out), env=cli_env(tmp_path)).returncode == 0
    result = run_cli("xyz", "convert", str(src), str(tmp_path / "again.3w"), env=cli_env(tmp_path), timeout=300)
    assert result.returncode == 0, result.stderr
    assert list(tmp_path.glob(".*.part")) == []
