"""What `fabwire serve` says on its terminal while it runs (`fabwire.agent.terminal.TERMINAL_LINES`), with real
simulators and a real agent process: one `fabwire: NAME: …` line when a machine goes offline or turns out to be
another kind of machine, one when it is back, never one per retry, and never a timestamped log line without -v."""

from __future__ import annotations

import re
import socket
from pathlib import Path
from typing import Any

import httpx
import pytest
from playwright.sync_api import Browser, expect

from fabwire.agent.terminal import TERMINAL_LINES

from .agenttools import start_agent, wait_for

TIMESTAMPED = re.compile(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d")


def _offline_events(client: httpx.Client, device: str) -> int:
    events = client.get(f"/api/v1/devices/{device}/history").json()["events"]
    return sum(1 for e in events if e.get("type") == "offline")


def test_a_machine_of_another_kind_is_said_once_however_often_it_is_tried(tmp_path: Path, simulator: Any) -> None:
    robot = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    agent = start_agent(tmp_path / "state", "--device", f"wrong:xyz={robot.url}")
    with agent.client() as client:
        wait_for(lambda: _offline_events(client, "wrong") >= 3, "three attempts at the Line-us as a printer")
    code, stderr = agent.stop()
    assert code == 0, stderr
    said = [line for line in stderr.splitlines() if line.startswith("fabwire: wrong: ")]
    assert len(said) == 1, stderr
    assert "is not an XYZv3 printer: it is a Line-us" in said[0]
    assert not [line for line in stderr.splitlines() if TIMESTAMPED.match(line)], stderr


def test_a_machine_that_comes_back_is_said_to_be_online_again(tmp_path: Path, simulator: Any) -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    agent = start_agent(tmp_path / "state", "--device", f"later:lineus=127.0.0.1:{port}")
    with agent.client() as client:
        wait_for(lambda: _offline_events(client, "later") >= 2, "two attempts at a port where nothing listens")
        simulator("lineus", "--listen", f"127.0.0.1:{port}", "--speed", "0")
        wait_for(lambda: client.get("/api/v1/devices/later/state").json()["online"], "the Line-us online")
    code, stderr = agent.stop()
    assert code == 0, stderr
    said = [line for line in stderr.splitlines() if line.startswith("fabwire: later: ")]
    assert len(said) == 2, stderr
    assert f"connection refused by 127.0.0.1:{port}" in said[0]
    assert said[1] == "fabwire: later: online again"


def test_a_healthy_machine_is_not_announced(tmp_path: Path, simulator: Any) -> None:
    robot = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    agent = start_agent(tmp_path / "state", "--device", f"arm:lineus={robot.url}")
    with agent.client() as client:
        wait_for(lambda: client.get("/api/v1/devices/arm/state").json()["online"], "the Line-us online")
    code, stderr = agent.stop()
    assert code == 0, stderr
    assert "fabwire: arm:" not in stderr


COVERED = {
    "machine-offline": "test_a_machine_of_another_kind_is_said_once_however_often_it_is_tried",
    "machine-online": "test_a_machine_that_comes_back_is_said_to_be_online_again",
    "broker-failed": "mqtt/test_serve_mqtt.py::test_a_broker_that_is_not_there_yet_is_said_once_then_connected",
    "broker-connected": "mqtt/test_serve_mqtt.py::test_a_broker_that_is_not_there_yet_is_said_once_then_connected",
}


@pytest.mark.parametrize("row", TERMINAL_LINES, ids=[row[0] for row in TERMINAL_LINES])
def test_every_terminal_line_has_its_test(row: tuple[str, str, str, str]) -> None:
    file, _, name = COVERED[row[0]].rpartition("::")
    source = (Path(__file__).parents[1] / file if file else Path(__file__)).read_text()
    assert f"def {name}(" in source


def test_the_dashboard_and_library_say_offline_once_with_the_reason(browser: Browser, tmp_path: Path,
                                                                    simulator: Any) -> None:
    """The card's header says "offline"; the state line under it gives the reason alone, and the library's refusal
    says "offline" once too."""
    robot = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    agent = start_agent(tmp_path / "state", "--device", f"wrong:xyz={robot.url}")
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    try:
        with agent.client() as client:
            wait_for(lambda: _offline_events(client, "wrong") >= 1, "the first attempt")
            refusal = client.get("/api/v1/devices/wrong/library").json()["refusal"]
        assert refusal.startswith(f"wrong is offline ({robot.url.removeprefix('tcp://')} is not an XYZv3 printer"), \
            refusal
        assert refusal.count("offline") == 1, refusal
        page = context.new_page()
        page.goto(agent.url)
        card = page.locator("article[data-kind=xyz]")
        expect(card.locator("header .offline")).to_have_text("offline")
        expect(card.locator(".state")).to_contain_text("is not an XYZv3 printer: it is a Line-us")
        assert card.inner_text().count("offline") == 1, card.inner_text()
    finally:
        context.close()
        code, stderr = agent.stop()
        assert code == 0, stderr
