"""Fixtures every device's tests share: running the real `fabwire` CLI and simulators as subprocesses."""

from __future__ import annotations

import os
import selectors
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

STARTUP_TIMEOUT = 20.0


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--soak", action="store_true", help="also run the long soak profiles")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--soak"):
        return
    skip = pytest.mark.skip(reason="soak profile: run with --soak")
    for item in items:
        if "soak" in item.keywords:
            item.add_marker(skip)


def cli_env(tmp_path: Path | None = None) -> dict[str, str]:
    """A clean environment: no user config file, unbuffered output, no colour codes."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("FABWIRE_")}
    env["PYTHONUNBUFFERED"] = "1"
    env["NO_COLOR"] = "1"
    env["TERM"] = "dumb"
    env["COLUMNS"] = "120"
    if tmp_path is not None:
        env["FABWIRE_CONFIG"] = str(tmp_path / "no-such-config.toml")
    return env


def run_cli(*args: str, timeout: float = 60.0, env: dict[str, str] | None = None,
            input_text: str | None = None) -> subprocess.CompletedProcess[str]:
    """Run `fabwire ARGS` as a real subprocess and capture its output."""
    return subprocess.run(
        [sys.executable, "-m", "fabwire", *args],
        capture_output=True, text=True, timeout=timeout, env=env or cli_env(), input=input_text,
    )


@dataclass
class RunningSimulator:
    process: subprocess.Popen[str]
    where: list[str]
    """What the simulator announced: `tcp://host:port` URLs and/or pty paths, in order."""

    @property
    def url(self) -> str:
        return self.where[0]

    def stop(self) -> str:
        """Stop with SIGTERM (as a user's Ctrl-C would) and return what it printed on stderr."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        err = self.process.stderr.read() if self.process.stderr else ""
        for stream in (self.process.stdout, self.process.stderr):
            if stream:
                stream.close()
        return err


def start_simulator(*args: str, announcements: int = 1, env: dict[str, str] | None = None) -> RunningSimulator:
    """Start `fabwire sim ARGS` and wait until it has announced `announcements` places it serves on."""
    process = subprocess.Popen(
        [sys.executable, "-m", "fabwire", "sim", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env or cli_env(),
    )
    where: list[str] = []
    assert process.stdout is not None

    with selectors.DefaultSelector() as sel:
        sel.register(process.stdout, selectors.EVENT_READ)
        while len(where) < announcements:
            if not sel.select(STARTUP_TIMEOUT):
                process.kill()
                raise RuntimeError(f"simulator {args} did not announce itself in {STARTUP_TIMEOUT} s")
            line = process.stdout.readline()
            if not line:
                err = process.stderr.read() if process.stderr else ""
                raise RuntimeError(f"simulator {args} exited early: {err}")
            if " listening on " in line:
                where.append(line.split(" listening on ", 1)[1].split(" (link")[0].strip())
    return RunningSimulator(process, where)


SimulatorStarter = Callable[..., RunningSimulator]


@pytest.fixture
def simulator() -> Iterator[SimulatorStarter]:
    """`simulator("mmu", "--listen", "127.0.0.1:0")` starts one; all are stopped after the test."""
    started: list[RunningSimulator] = []

    def start(*args: str, announcements: int = 1) -> RunningSimulator:
        sim = start_simulator(*args, announcements=announcements)
        started.append(sim)
        return sim

    yield start
    for sim in started:
        sim.stop()
