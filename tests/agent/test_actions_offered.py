"""An action the machine's summary does not offer in its current state, asked of a real `fabwire serve` with real
simulators: 409 at once, naming the state, and nothing sent to the machine (no error later in its history)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import httpx
import pytest

from fabwire.agent.session import JOB_ACTIONS
from fabwire.samples import SAMPLE_GCODE, sample_path

from .agenttools import device_of, summary, wait_for
from .conftest import Bench


def _printing(client: httpx.Client, device: str) -> str:
    started = client.post(f"/api/v1/devices/{device}/jobs", params={"filename": "sample.gcode"},
                          content=sample_path(SAMPLE_GCODE).read_bytes(),
                          headers={"Content-Type": "application/octet-stream"})
    assert started.status_code == 201, started.text
    wait_for(lambda: summary(client, device)["state"] == "printing", "the print running", timeout=120)
    return "printing"


def _idle(client: httpx.Client, device: str) -> str:
    wait_for(lambda: summary(client, device)["state"] == "idle", "the printer idle")
    return "idle"


def _drawing(client: httpx.Client, device: str) -> str:
    started = client.post(f"/api/v1/devices/{device}/actions/text", json={"text": "a long line of words to draw"})
    assert started.status_code == 200, started.text
    wait_for(lambda: summary(client, device)["state"] == "drawing", "the drawing running")
    return "drawing"


def _mmu_error(client: httpx.Client, device: str) -> str:
    wait_for(lambda: summary(client, device)["state"] == "idle", "the MMU idle")
    assert client.post(f"/api/v1/devices/{device}/actions/load", json={"slot": 1}).status_code == 200
    wait_for(lambda: summary(client, device)["state"] == "error", "the bench MMU's one FINDA fault", timeout=120)
    return "error"


NOT_OFFERED: dict[str, tuple[str, Callable[[httpx.Client, str], str], str, dict[str, Any]]] = {
    "xyz-jog-while-printing": ("xyz", _printing, "jog", {"axis": "x", "distance_mm": 10}),
    "xyz-acknowledge-while-printing": ("xyz", _printing, "acknowledge", {}),
    "xyz-confirm-with-no-step-waiting": ("xyz", _idle, "confirm", {}),  # (a flow's prompt offers confirm)
    "xyz-stop-flow-with-no-step-waiting": ("xyz", _idle, "stop_flow", {}),
    "xyz-cancel-with-nothing-printing": ("xyz", _idle, "cancel", {}),  # not asked to confirm what cannot happen
    "xyz-pause-with-nothing-printing": ("xyz", _idle, "pause", {}),
    "xyz-resume-while-printing": ("xyz", _printing, "resume", {}),
    "lineus-move-while-drawing": ("lineus", _drawing, "move", {"x": 1000, "y": 0}),
    "lineus-pen-up-while-drawing": ("lineus", _drawing, "pen_up", {}),
    "mmu-tool-change-in-error": ("mmu", _mmu_error, "tool_change", {"slot": 2}),
}
"""(kind, how to bring the machine to a state, an action that state's `actions` do not hold, its parameters):
each driver's table of what a state offers (xyz: printing offers pause and cancel, idle no flow's answers; Line-us:
drawing offers nothing; MMU3: an error offers retry or continue, and stop)."""


@pytest.mark.timeout(600)
@pytest.mark.parametrize("case", NOT_OFFERED, ids=list(NOT_OFFERED))
def test_an_action_not_offered_now_is_409_naming_the_state(bench: Bench, case: str) -> None:
    kind, bring, action, params = NOT_OFFERED[case]
    with bench.agent.client() as client:
        device = wait_for(lambda: (d := device_of(client, kind))["state"]["online"] and d, f"the {kind} online")["id"]
        state = bring(client, device)
        offered = summary(client, device)["actions"]
        assert action not in offered
        events = len(client.get(f"/api/v1/devices/{device}/history").json()["events"])
        refused = client.post(f"/api/v1/devices/{device}/actions/{action}", json=params)
        assert refused.status_code == 409, refused.text
        message = refused.json()["message"]
        assert (f"has nothing to {action}" if action in JOB_ACTIONS else f"cannot {action} now") in message
        assert "cannot be undone" not in message
        assert state in message
        later = client.get(f"/api/v1/devices/{device}/history").json()["events"][events:]
        assert not any(e.get("type") == "error" and action in str(e) for e in later), later


@pytest.mark.timeout(600)
def test_a_second_mmu_retry_right_after_the_first_is_409(bench: Bench) -> None:
    with bench.agent.client() as client:
        mmu = wait_for(lambda: (d := device_of(client, "mmu"))["state"]["online"] and d, "the MMU online")["id"]
        _mmu_error(client, mmu)
        assert "retry" in summary(client, mmu)["actions"]
        first = client.post(f"/api/v1/devices/{mmu}/actions/retry", json={})
        assert first.status_code == 200, first.text
        second = client.post(f"/api/v1/devices/{mmu}/actions/retry", json={})
        assert second.status_code == 409, second.text
        assert "cannot retry now" in second.json()["message"]
        wait_for(lambda: summary(client, mmu)["state"] == "idle", "the MMU recovered", timeout=120)
