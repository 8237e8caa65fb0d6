"""fabwire starts where termios/fcntl do not exist, and a missing optional package names the extra to install."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from clitools import cli_env


def run_blocked(blocked: list[str], argv: list[str]) -> subprocess.CompletedProcess[str]:
    """Run the CLI in a Python where importing each of `blocked` fails, as it would where they are absent."""
    code = (f"import sys\nfor name in {blocked!r}:\n    sys.modules[name] = None\n"
            f"from fabwire.cli import main\nsys.exit(main({argv!r}))\n")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=cli_env())


def test_no_termios_no_fcntl_still_talks_to_devices() -> None:
    result = run_blocked(["termios", "fcntl", "pty", "tty"], ["xyz", "-d", "sim://xyz?speed=1000", "status", "--json"])
    assert result.returncode == 0, result.stderr
    assert '"state"' in result.stdout or '"state_code"' in result.stdout


def test_no_termios_a_pty_simulator_says_why() -> None:
    result = run_blocked(["termios", "fcntl", "pty", "tty"], ["sim", "xyz", "--pty"])
    assert result.returncode == 4
    assert result.stderr.strip() == ("fabwire: error: --pty needs a POSIX system (Linux, macOS): "
                                     "serve on TCP with --listen")


def test_a_missing_drawing_stack_names_the_extra() -> None:
    result = run_blocked(["svgelements"], ["lineus", "draw", "picture.svg"])
    assert result.returncode == 3
    assert "pip install 'fabwire[lineus]'" in result.stderr
    assert "Traceback" not in result.stderr
    listed = run_blocked(["svgelements"], ["lineus", "--help"])  # the arm's commands need no drawing stack
    assert listed.returncode == 0
    assert {line.split()[0] for line in listed.stdout.splitlines() if "fabwire[lineus]" in line} == \
        {"draw", "preview", "text"}
    printers = run_blocked(["svgelements", "HersheyFonts", "zeroconf", "PIL", "shapely"],
                           ["xyz", "-d", "sim://xyz?speed=1000", "status", "--json"])
    assert printers.returncode == 0, printers.stderr


def test_the_demo_on_the_base_install_shows_what_it_drives(tmp_path: Path) -> None:
    out = str(tmp_path / "demo")
    asked = run_blocked(["shapely"], ["demo", "--only", "lineus", "--out", out])
    assert asked.returncode == 3
    assert "pip install 'fabwire[lineus]'" in asked.stderr
    tour = run_blocked(["shapely"], ["--json", "demo", "--speed", "50", "--out", out])
    assert tour.returncode == 0, tour.stderr
    assert "leaving out the Line-us: this needs 'shapely'" in tour.stderr
    assert {step["device"] for step in json.loads(tour.stdout)["steps"]} == {"all", "xyz", "mmu"}
