"""Suite-wide hooks and fixtures; the subprocess helpers live in clitools.py (importable from any test)."""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator

import pytest
from hypothesis import settings

from clitools import RunningSimulator, SimulatorStarter, start_simulator

# CI runs the same examples every time, so a landing is never decided by chance; `HYPOTHESIS_PROFILE=hunt` searches
# wider and at random for new counter-examples (add what it finds as an explicit case).
settings.register_profile("ci", derandomize=True, database=None)
settings.register_profile("hunt", max_examples=2000, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


# A suite started in the background of a shell without job control (`make test &`, nohup) inherits an ignored
# Ctrl-C, which every command it starts would inherit too: the tests of Ctrl-C need the user's default.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--soak", action="store_true", help="also run the long soak profiles")


SHARED_MACHINE_WIDE = {
    # xdist group: tests (by node id prefix) that use something one machine has once, so they run one after another
    "mdns": (  # mDNS: one responder on port 5353; two advertisements of the same name would be a name conflict
        "tests/lineus/test_discovery.py::",
        "tests/lineus/test_official_module.py::test_official_module_finds_advertised_simulator",
        "tests/lineus/test_cli.py::test_discover_finds_advertised_simulator",
        "tests/lineus/test_cli.py::test_local_names_resolve_by_mdns_with_the_advertised_port",
    ),
}


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        for group, prefixes in SHARED_MACHINE_WIDE.items():
            if item.nodeid.startswith(prefixes):
                item.add_marker(pytest.mark.xdist_group(group))
    if config.getoption("--soak"):
        return
    skip = pytest.mark.skip(reason="soak profile: run with --soak")
    for item in items:
        if "soak" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(autouse=True, scope="session")
def own_state_home(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Each test process (each xdist worker) keeps state (drawing progress, the agent's files) in a folder of its
    own, never the user's: parallel workers cannot meet in one state file."""
    before = os.environ.get("XDG_STATE_HOME")
    os.environ["XDG_STATE_HOME"] = str(tmp_path_factory.mktemp("state"))
    yield
    if before is None:
        os.environ.pop("XDG_STATE_HOME", None)
    else:
        os.environ["XDG_STATE_HOME"] = before


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
