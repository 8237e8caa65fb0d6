"""Ctrl-C at any moment of a run, even while the CLI is still importing, gives one line and exit code 130."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from clitools import cli_env

# The console script's own steps: import the entry point, then run it. The marker byte tells the test that the
# interpreter has finished its own start-up (which fabwire cannot shape), so delay 0 lands on fabwire's first import.
ENTRY = "import os, sys; from fabwire.__main__ import run; os.write(1, b'R'); sys.argv[0] = 'fabwire'; run()"


@pytest.fixture
def silent_port() -> Iterator[int]:
    """A TCP port that takes connections and never answers: the command waits until interrupted."""
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(8)
        yield server.getsockname()[1]


@pytest.mark.parametrize("delay", [0.0, 0.001, 0.01, 0.03, 0.06, 0.1, 0.2, 0.35, 0.6])
def test_sigint_at_any_moment_of_start_up_is_one_line_and_exit_130(tmp_path: Path, silent_port: int,
                                                                    delay: float) -> None:
    process = subprocess.Popen(
        [sys.executable, "-c", ENTRY, "mmu", "-d", f"tcp://127.0.0.1:{silent_port}", "--timeout", "60", "status"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=cli_env(tmp_path))
    try:
        assert process.stdout is not None
        assert process.stdout.read(1) == b"R"
        time.sleep(delay)
        process.send_signal(signal.SIGINT)
        stdout, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    text = stderr.decode(errors="replace")
    assert "Traceback" not in text
    assert process.returncode == 130, text
    assert text.strip().splitlines() == ["fabwire: interrupted"]
    assert stdout == b""


FINALISER = """
import signal, sys, time
import fabwire.__main__ as entry
signal.signal(signal.SIGINT, signal.default_int_handler)  # as `run` leaves it once the CLI is imported
sys.unraisablehook = entry._interrupt_from_finaliser
class Closing:
    def __del__(self):
        raise KeyboardInterrupt
try:
    Closing()  # collected at once: its KeyboardInterrupt cannot be raised where it happened
    for _ in range(10_000):
        time.sleep(0.001)
    print("never interrupted")
except KeyboardInterrupt:
    print("interrupted in the main thread")
"""


def test_ctrl_c_inside_a_finaliser_reaches_the_command_not_a_traceback(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-c", FINALISER], capture_output=True, text=True, timeout=60,
                          env=cli_env(tmp_path))
    assert done.stdout.strip() == "interrupted in the main thread"
    assert "Traceback" not in done.stderr
    assert "Exception ignored" not in done.stderr
