"""Simulators as real child processes (`python -m fabwire sim …`) on loopback TCP, always stopped afterwards:
by `stop_all`, or by their lifeline when this process ends without it (`fabwire.lifeline`)."""

from __future__ import annotations

import contextlib
import os
import selectors
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import IO

from fabwire.errors import FabwireError, LinkError
from fabwire.lifeline import spawn

STARTUP_TIMEOUT = 20.0
STOP_TIMEOUT = 10.0
ANNOUNCEMENT = " simulator listening on "


class SimulatorFailed(LinkError):
    """A simulator process would not start, announce itself or stop."""


def _child_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONUNBUFFERED"] = "1"
    return env


@dataclass
class SimulatorProcess:
    """One `fabwire sim DEVICE` child: its announced URL, its stderr (kept in a file), and how to stop it."""

    device: str
    process: subprocess.Popen[bytes]
    log: IO[bytes]
    url: str = ""
    stopped_at: float | None = field(default=None)
    _terminated: bool = field(default=False, repr=False)

    @property
    def pid(self) -> int:
        return self.process.pid

    @property
    def port(self) -> int:
        return int(self.url.rsplit(":", 1)[1])

    def running(self) -> bool:
        return self.process.poll() is None

    def stderr_tail(self, lines: int = 3) -> str:
        if self.log.closed:
            return ""
        self.log.seek(0)
        text = self.log.read().decode("utf-8", "replace").strip().splitlines()
        return " | ".join(text[-lines:])

    def wait_for_url(self, deadline: float) -> str:
        """Read stdout until the simulator says where it listens; the process is killed if it never does."""
        stdout = self.process.stdout
        assert stdout is not None
        buffered = b""
        with selectors.DefaultSelector() as sel:
            sel.register(stdout, selectors.EVENT_READ)
            while True:
                left = deadline - time.monotonic()
                if left <= 0 or not sel.select(left):
                    self.kill()
                    raise SimulatorFailed(f"the {self.device} simulator did not announce itself within "
                                          f"{STARTUP_TIMEOUT:g} s")
                chunk = os.read(stdout.fileno(), 4096)
                if not chunk:
                    self.process.wait(STOP_TIMEOUT)
                    raise SimulatorFailed(f"the {self.device} simulator exited at start "
                                          f"(code {self.process.returncode}): {self.stderr_tail() or 'no message'}")
                buffered += chunk
                for line in buffered.decode("utf-8", "replace").splitlines():
                    if ANNOUNCEMENT in line:
                        self.url = line.split(ANNOUNCEMENT, 1)[1].split()[0]
                        return self.url

    def terminate(self) -> None:
        """SIGTERM, once: the simulator then writes what it records, and a second SIGTERM would kill it mid-file."""
        if not self._terminated and self.process.poll() is None:
            self._terminated = True
            with contextlib.suppress(OSError):
                self.process.send_signal(signal.SIGTERM)

    def stop(self, timeout: float = STOP_TIMEOUT) -> int:
        """SIGTERM (once), wait, and SIGKILL if it will not go."""
        if self.process.poll() is None:
            self.terminate()
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.kill()
        self._close_streams()
        self.stopped_at = time.monotonic()
        return self.process.returncode

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        self._close_streams()

    def _close_streams(self) -> None:
        for stream in (self.process.stdout, self.process.stdin):  # stdin: the child's lifeline, done with
            if stream is not None and not stream.closed:
                with contextlib.suppress(OSError):
                    stream.close()


def start_simulators(specs: Sequence[tuple[str, Sequence[str]]]) -> list[SimulatorProcess]:
    """Start `fabwire sim DEVICE --listen 127.0.0.1:0 ARGS…` for each (DEVICE, ARGS) at once, then wait for
    every announcement. If any fails, all that were started are stopped before the error is raised."""
    started: list[SimulatorProcess] = []
    try:
        for device, args in specs:
            log = tempfile.TemporaryFile()  # noqa: SIM115 - closed by stop_all
            command = [sys.executable, "-m", "fabwire", "sim", device, "--listen", "127.0.0.1:0", *args]
            try:
                process = spawn(command, stdout=subprocess.PIPE, stderr=log, env=_child_env())
            except OSError as exc:
                log.close()
                raise SimulatorFailed(f"cannot start the {device} simulator: {exc.strerror or exc}") from exc
            started.append(SimulatorProcess(device, process, log))
        deadline = time.monotonic() + STARTUP_TIMEOUT
        for sim in started:
            sim.wait_for_url(deadline)
    except BaseException:
        stop_all(started)
        raise
    return started


def stop_all(simulators: Sequence[SimulatorProcess]) -> list[FabwireError]:
    """Stop every simulator (SIGTERM to all first, so they wind down together); returns problems, never raises."""
    problems: list[FabwireError] = []
    for sim in simulators:
        sim.terminate()
    for sim in simulators:
        try:
            code = sim.stop()
        except OSError as exc:
            problems.append(SimulatorFailed(f"stopping the {sim.device} simulator: {exc}"))
            continue
        if code not in (0, -signal.SIGTERM, 130):
            problems.append(SimulatorFailed(f"the {sim.device} simulator ended with code {code}: "
                                            f"{sim.stderr_tail() or 'no message'}"))
        sim.log.close()
    return problems
