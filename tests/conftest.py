"""Suite-wide hooks and fixtures; the subprocess helpers live in clitools.py (importable from any test)."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest
from hypothesis import settings

from clitools import RunningSimulator, SimulatorStarter, start_simulator

# CI runs the same examples every time, so a landing is never decided by chance; `HYPOTHESIS_PROFILE=hunt` searches
# wider and at random for new counter-examples (add what it finds as an explicit case).
settings.register_profile("ci", derandomize=True, database=None)
settings.register_profile("hunt", max_examples=2000, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--soak", action="store_true", help="also run the long soak profiles")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--soak"):
        return
    skip = pytest.mark.skip(reason="soak profile: run with --soak")
    for item in items:
        if "soak" in item.keywords:
            item.add_marker(skip)


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
