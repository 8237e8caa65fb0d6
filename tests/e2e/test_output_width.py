"""How wide output is laid out: click's rule for help on a terminal (its width), `MAX_WIDTH` off one (a pipe, a
file) or $COLUMNS when set; text lines off a terminal are never broken (a path stays whole) and table cells fold a
long path rather than cut it."""

from __future__ import annotations

import fcntl
import os
import pty
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

from clitools import cli_env
from fabwire.console import MAX_WIDTH

HELPS = [["--help"], ["xyz", "--help"], ["demo", "--help"], ["devices", "add", "--help"], ["mmu", "tool-change", "-h"]]
LONG_OPTION = ("  -d, --device DEVICE  Address (host[:port], tcp://…, /dev/tty…, sim://KIND) or a configured device "
               "name.")
"""A line of `fabwire xyz --help` of 104 columns: whole within MAX_WIDTH, broken at 80."""


def _env(columns: str | None) -> dict[str, str]:
    env = {k: v for k, v in cli_env().items() if k != "COLUMNS"}
    if columns is not None:
        env["COLUMNS"] = columns
    return env


def _help(args: list[str], columns: str | None) -> str:
    done = subprocess.run([sys.executable, "-m", "fabwire", *args], env=_env(columns), capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return done.stdout


@pytest.mark.parametrize("args", HELPS, ids=" ".join)
def test_help_to_a_pipe_is_laid_out_to_the_max_width_not_80(args: list[str]) -> None:
    text = _help(args, None)
    assert max(len(line) for line in text.splitlines()) <= MAX_WIDTH - 2
    if args == ["xyz", "--help"]:
        assert LONG_OPTION in text.splitlines()


@pytest.mark.parametrize("args", HELPS, ids=" ".join)
def test_help_follows_columns_when_set(args: list[str]) -> None:
    assert max(len(line) for line in _help(args, "60").splitlines()) <= 58


@pytest.mark.parametrize("width", [70, 100, 200])
def test_help_on_a_terminal_follows_its_width(width: int) -> None:
    """A real pty of `width` columns: click's rule, the terminal's width less 2, at most MAX_WIDTH - 2."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, width, 0, 0))
    try:
        proc = subprocess.Popen([sys.executable, "-m", "fabwire", "xyz", "--help"], env=_env(None), stdin=slave,
                                stdout=slave, stderr=slave)
        os.close(slave)
        chunks = []
        while True:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # EIO: the child closed the terminal
                break
            if not chunk:
                break
            chunks.append(chunk)
        assert proc.wait(timeout=60) == 0
    finally:
        os.close(master)
    lines = b"".join(chunks).decode().replace("\r\n", "\n").splitlines()
    assert max(len(line) for line in lines) <= min(width, MAX_WIDTH) - 2
    assert (LONG_OPTION in lines) == (width >= len(LONG_OPTION) + 2)


def test_the_demo_into_a_pipe_keeps_each_path_whole(tmp_path: Path) -> None:
    out = tmp_path / "an-output-folder-with-a-rather-long-name-so-that-its-paths-pass-any-width-a-table-has"
    done = subprocess.run([sys.executable, "-m", "fabwire", "demo", "--only", "xyz", "--out", str(out), "--speed",
                           "60"], env=_env(None), capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    target = out.resolve() / "calibration-square.3w"
    assert f"converted calibration-square.gcode → {target} for " in done.stderr  # on one line
    cells = [line.split("│")[5].strip() for line in done.stderr.splitlines() if line.count("│") == 6]
    # the table's output cell folds the path: nothing is cut (a fold at the space after it drops that space)
    assert str(target) in "".join(cells)
    assert "…" not in "".join(cells)
