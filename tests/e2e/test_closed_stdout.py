"""A reader of fabwire's output that goes away (`fabwire trace show cap.jsonl | head`) ends the command quietly with
exit code 0: no traceback, no error line, not exit code 1."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from clitools import cli_env

RECORDS = 50_000
"""Far more output than a pipe buffers (64 KiB on Linux), so the writer meets the closed pipe."""


def _capture(path: Path) -> Path:
    header = {"trace": "fabwire", "version": 1, "url": "sim://lineus", "peer": "lineus simulator (in-process)",
              "started": "2026-12-03T13:12:32.814+00:00", "device": "lineus"}
    lines = [json.dumps(header)]
    for i in range(RECORDS):
        lines.append(json.dumps({"t": i / 1000, "dir": ">" if i % 2 else "<",
                                 "data": "M114\u0000" if i % 2 else "ok X:1000.00 Y:1000.00 Z:1000.00\r\n\u0000"}))
    path.write_text("\n".join(lines) + "\n")
    return path


def _devices(path: Path) -> Path:
    path.write_text("".join(f"[devices.p{i}]\nkind = 'xyz'\nurl = '10.0.{i // 250}.{i % 250 + 1}'\n\n"
                            for i in range(3000)))
    return path


# Each command that writes to stdout, in each of its forms of output.
COMMANDS = {
    "trace-show": lambda tmp: ["trace", "show", str(_capture(tmp / "cap.jsonl"))],
    "trace-show-json": lambda tmp: ["--json", "trace", "show", str(_capture(tmp / "cap.jsonl"))],
    "devices-list": lambda tmp: ["devices", "list"],
    "devices-list-json": lambda tmp: ["--json", "devices", "list"],
    "help": lambda tmp: ["xyz", "--help"],
    "version": lambda tmp: ["--version"],
    "udev-rules": lambda tmp: ["service", "udev", "--output", "-"],
    "device-command": lambda tmp: ["lineus", "-d", "sim://lineus?speed=inf", "position"],
    "device-command-json": lambda tmp: ["--json", "mmu", "-d", "sim://mmu?speed=50", "version"],
}


def _env(tmp_path: Path) -> dict[str, str]:
    env = cli_env()
    env["FABWIRE_CONFIG"] = str(_devices(tmp_path / "devices.toml"))
    return env


@pytest.mark.parametrize("name", COMMANDS)
def test_a_closed_stdout_ends_the_command_quietly(name: str, tmp_path: Path) -> None:
    """stdout is a pipe whose reader has already closed it: every write fails with EPIPE."""
    args = COMMANDS[name](tmp_path)
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        done = subprocess.run([sys.executable, "-m", "fabwire", *args], stdout=write_end, stderr=subprocess.PIPE,
                              env=_env(tmp_path), timeout=120, text=True)
    finally:
        os.close(write_end)
    assert (done.returncode, done.stderr) == (0, "")


def test_trace_show_into_head_shows_the_first_lines_and_exits_0(tmp_path: Path) -> None:
    capture = _capture(tmp_path / "cap.jsonl")
    show = subprocess.Popen([sys.executable, "-m", "fabwire", "trace", "show", str(capture)], env=cli_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert show.stdout is not None
    assert show.stderr is not None
    head = subprocess.run(["head", "-n", "3"], stdin=show.stdout, capture_output=True, text=True, timeout=120)
    show.stdout.close()
    errors = show.stderr.read().decode()
    assert show.wait(timeout=120) == 0
    assert errors == ""
    assert head.stdout.splitlines() == ['  0.000000 <ok X:1000.00 Y:1000.00 Z:1000.00\\r\\n\\0',
                                        "  0.001000 >M114\\0", '  0.002000 <ok X:1000.00 Y:1000.00 Z:1000.00\\r\\n\\0']
