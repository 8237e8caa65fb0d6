"""Keys while `xyz print` follows a job on a terminal (a real pty): space pauses and resumes, `c` twice cancels,
and the live view's footer says so."""

from __future__ import annotations

import json
import os
import pty
import select
import subprocess
import sys
import time
from pathlib import Path

from clitools import SimulatorStarter, cli_env, run_cli

GCODE = b";TIME:600\n;LAYER_COUNT:3\n;Filament used: 0.25m\nG28\nG1 X10 Y10 F3000\nG1 X20 Y20 E1 F1200\nM84\n"


def _state(dev: str) -> str:
    done = run_cli("--json", "xyz", "-d", dev, "status", env=cli_env())
    return str(json.loads(done.stdout)["state_name"])


def _wait(predicate: object, what: str, limit: float = 30.0) -> None:
    end = time.monotonic() + limit
    while time.monotonic() < end:
        if predicate():  # type: ignore[operator]
            return
        time.sleep(0.2)
    raise AssertionError(f"never {what}")


class Terminal:
    """A process on a pseudo-terminal, with what it wrote so far."""

    def __init__(self, argv: list[str]) -> None:
        self.master, slave = pty.openpty()
        env = cli_env() | {"TERM": "xterm", "COLUMNS": "100", "LINES": "40"}
        env.pop("NO_COLOR", None)
        self.process = subprocess.Popen(argv, stdin=slave, stdout=slave, stderr=slave, env=env, close_fds=True)
        os.close(slave)
        self.seen = b""

    def read(self) -> bytes:
        while select.select([self.master], [], [], 0.05)[0]:
            try:
                chunk = os.read(self.master, 65536)
            except OSError:
                break
            if not chunk:
                break
            self.seen += chunk
        return self.seen

    def press(self, key: bytes) -> None:
        os.write(self.master, key)

    def close(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait(10)
        os.close(self.master)


def test_space_pauses_and_resumes_and_c_twice_cancels(simulator: SimulatorStarter, tmp_path: Path) -> None:
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "5")
    dev = sim.url.removeprefix("tcp://")
    src = tmp_path / "cube.gcode"
    src.write_bytes(GCODE)
    term = Terminal([sys.executable, "-m", "fabwire", "xyz", "-d", dev, "print", str(src)])
    try:
        _wait(lambda: b"space: pause/resume" in term.read() and _state(dev) == "printing", "printing with keys")
        term.press(b" ")
        _wait(lambda: "paused" in _state(dev), "paused by space")
        term.press(b" ")
        _wait(lambda: "paused" not in _state(dev), "resumed by space")
        term.press(b"c")
        _wait(lambda: b"press c again" in term.read(), "asked for a second c")
        assert "print" in _state(dev)  # one c alone cancels nothing
        term.press(b"c")
        _wait(lambda: term.process.poll() is not None, "the print ended", 60)
        said = term.read().decode(errors="replace")
        assert _state(dev) not in ("printing", "print paused")
        assert term.process.returncode == 130  # ended as its user asked: an interruption, not a device fault
        assert "cube.gcode: the print was cancelled as asked" in " ".join(said.split()), said[-400:]
    finally:
        term.close()


def test_no_keys_without_a_terminal(simulator: SimulatorStarter, tmp_path: Path) -> None:
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000")
    src = tmp_path / "cube.gcode"
    src.write_bytes(GCODE)
    done = run_cli("xyz", "-d", sim.url.removeprefix("tcp://"), "print", str(src), env=cli_env(), input_text=" c c")
    assert done.returncode == 0, done.stderr
    assert "space: pause" not in done.stdout + done.stderr
    assert done.stdout.endswith("cube.gcode: print finished\n")
