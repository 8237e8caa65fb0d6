"""The multi-layer progress bar as a person sees it on a terminal (vpype under a pseudo-terminal): after the pen
change it names the new layer and keeps moving within each stroke."""

from __future__ import annotations

import os
import pty
import re
import select
import sys
import time
from pathlib import Path

from clitools import cli_env

VPYPE = str(Path(sys.executable).with_name("vpype"))
WAIT = 120.0
"""Longest the drawing may take before the test gives up (a bound against hanging, not a pass/fail window)."""
# One long stroke per layer: a bar that moves only per stroke would stand still through all of layer 2.
ZIGZAGS = ("line 0 0 8cm 0 line 8cm 0 0 1cm line 0 1cm 8cm 1cm linemerge "
           "line --layer 2 0 2cm 8cm 2cm line --layer 2 8cm 2cm 0 3cm line --layer 2 0 3cm 8cm 3cm linemerge")


def test_the_bar_moves_after_the_pen_change(tmp_path: Path, simulator) -> None:  # type: ignore[no-untyped-def]
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "5")
    env = cli_env(tmp_path)
    env["XDG_STATE_HOME"] = str(tmp_path / "state")
    env["TERM"] = "xterm"
    env.pop("NO_COLOR", None)
    pid, fd = pty.fork()
    if pid == 0:  # the child: vpype on the terminal
        os.execve(VPYPE, [VPYPE, *ZIGZAGS.split(), "lineus-fit", "lineus-draw", "-d", sim.url], env)
    out = b""
    answered_at = -1
    deadline = time.monotonic() + WAIT
    try:
        while time.monotonic() < deadline:
            if select.select([fd], [], [], 0.2)[0]:
                try:
                    chunk = os.read(fd, 65536)
                except OSError:  # the child closed the terminal
                    break
                if not chunk:
                    break
                out += chunk
                if answered_at < 0 and b"press Enter" in out:
                    answered_at = len(out)
                    os.write(fd, b"\n")
        _, status = os.waitpid(pid, 0)
    finally:
        os.close(fd)
    assert os.waitstatus_to_exitcode(status) == 0, out[-2000:]
    assert answered_at >= 0, out[-2000:]
    after = out[answered_at:].decode(errors="replace")
    percents = [int(p) for p in re.findall(r"(\d+)%", after)]
    at_change = percents[0]
    assert any(at_change < p < 100 for p in percents), percents  # moving through layer 2's one stroke
    assert "layer 2" in after
