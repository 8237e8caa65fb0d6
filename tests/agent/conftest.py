"""A bench for the agent tests: three simulator processes and `fabwire serve` watching them."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest
from playwright.sync_api import Browser, sync_playwright

from clitools import RunningSimulator, start_simulator

from .agenttools import RunningAgent, start_agent

SPEED = "30"
LINEUS_SPEED = "4"
"""Slow enough that a drawing takes a few seconds, so its strokes can be watched arriving."""
MMU_FAULT = "finda-didnt-trigger@1:1"
"""The first feed to FINDA passes, the second (a tool change to T1 after T0) fails once."""


@dataclass
class Bench:
    xyz: RunningSimulator
    lineus: RunningSimulator
    mmu: RunningSimulator
    agent: RunningAgent

    @property
    def config(self) -> Path:
        return self.agent.state_dir.parent / "devices.toml"


def write_config(path: Path, sims: list[RunningSimulator]) -> Path:
    """The bench as named devices; the MMU's heartbeat follows its simulator's speed-up, and its errors wait for
    a person (no automatic Retry)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"""
[devices.printer]
kind = "xyz"
url = "{sims[0].url}"

[devices.arm]
kind = "lineus"
url = "{sims[1].url}"

[devices.mmu]
kind = "mmu"
url = "{sims[2].url}"
speed = {SPEED}
auto_retries = 0
""", encoding="utf-8")
    return path


def start_bench(state_dir: Path, *agent_args: str, printer_speed: str = SPEED) -> Bench:
    commands = [("xyz", "--listen", "127.0.0.1:0", "--speed", printer_speed),
                ("lineus", "--listen", "127.0.0.1:0", "--speed", LINEUS_SPEED),
                ("mmu", "--listen", "127.0.0.1:0", "--speed", SPEED, "--fault", MMU_FAULT)]
    with ThreadPoolExecutor(3) as pool:  # three interpreters start at once
        sims = list(pool.map(lambda args: start_simulator(*args), commands))
    config = write_config(state_dir.parent / "devices.toml", sims)
    try:
        agent = start_agent(state_dir, "--config", str(config), *agent_args)
    except BaseException:
        for sim in sims:
            sim.stop()
        raise
    return Bench(*sims, agent)


def stop_bench(bench: Bench) -> None:
    bench.agent.stop()
    for sim in (bench.xyz, bench.lineus, bench.mmu):
        sim.stop()


@pytest.fixture
def bench(tmp_path: Path) -> Iterator[Bench]:
    """A fresh bench per test: the MMU fault fires once, and jobs must not carry over."""
    running = start_bench(tmp_path / "state")
    yield running
    stop_bench(running)


def chromium_path() -> str:
    found = shutil.which("chromium") or ("/usr/bin/chromium" if os.path.exists("/usr/bin/chromium") else None)
    if found is None:
        pytest.fail("the browser tests need Debian's chromium: run scripts/ensure-system-packages "
                    "(or: sudo apt-get install chromium)")
    return found


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    """The distribution's Chromium, through Playwright."""
    with sync_playwright() as playwright:
        launched = playwright.chromium.launch(executable_path=chromium_path(), args=["--no-sandbox"])
        yield launched
        launched.close()
