"""The live stream through a link loss, and history that outlives the agent."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import pytest
from websockets.sync.client import ClientConnection, connect

from clitools import start_simulator
from fabwire.samples import SAMPLE_GCODE, sample_path

from .agenttools import device_of, start_agent, summary, wait_for
from .conftest import Bench


def _next_event(ws: ClientConnection, match: Any, what: str, timeout: float = 60.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    seen: list[str] = []
    while time.monotonic() < deadline:
        event = json.loads(ws.recv(timeout=max(0.1, deadline - time.monotonic())))
        seen.append(event["type"])
        if match(event):
            return dict(event)
    raise AssertionError(f"no {what} within {timeout:g} s (saw {seen[-20:]})")


def test_link_loss_and_reconnect_while_subscribed(bench: Bench) -> None:
    with bench.agent.client() as client:
        printer = wait_for(lambda: (d := device_of(client, "xyz"))["state"]["online"] and d, "the printer online")
    port = bench.xyz.url.rsplit(":", 1)[1]
    with connect(f"{bench.agent.ws_url}?device={printer['id']}", subprotocols=["fabwire"]) as ws:  # type: ignore[list-item]
        first = json.loads(ws.recv(timeout=10))
        assert first["type"] == "state"
        assert first["device"] == printer["id"]
        assert first["state"]["online"] is True
        bench.xyz.process.kill()  # the printer vanishes mid-session
        bench.xyz.stop()
        offline = _next_event(ws, lambda e: e["type"] == "offline", "offline event")
        assert offline["device"] == printer["id"]
        assert offline["reason"]
        down = _next_event(ws, lambda e: e["type"] == "state" and not e["state"]["online"], "offline state")
        assert down["state"]["summary"]["state"] == "offline"
        bench.xyz = start_simulator("xyz", "--listen", f"127.0.0.1:{port}", "--speed", "30")
        online = _next_event(ws, lambda e: e["type"] == "online", "online event after the printer came back")
        assert online["info"]["id"] == printer["id"]  # the same machine, the same id
        back = _next_event(ws, lambda e: e["type"] == "state" and e["state"]["online"], "fresh state")
        assert back["state"]["summary"]["state"] == "idle"
        # only the subscribed device's events arrive
        for _ in range(5):
            assert json.loads(ws.recv(timeout=10))["device"] == printer["id"]
    with bench.agent.client() as client:
        events = client.get(f"/api/v1/devices/{printer['id']}/history").json()["events"]
    kinds = [e["type"] for e in events]
    assert "offline" in kinds
    assert kinds.index("offline") < len(kinds) - 1 - kinds[::-1].index("online")


def test_a_job_ends_after_the_state_it_left(bench: Bench) -> None:
    """Whoever sees a print's job end sees the finished print on the bed (the OK button offered), never the
    state of a poll from before the end: a client that reads jobs and then the state acts on the machine as it is."""
    with bench.agent.client() as client:
        printer = wait_for(lambda: (d := device_of(client, "xyz"))["state"]["online"] and d, "the printer online")
        wait_for(lambda: summary(client, printer["id"])["state"] == "idle", "the printer idle")
        with connect(f"{bench.agent.ws_url}?device={printer['id']}", subprotocols=["fabwire"]) as ws:  # type: ignore[list-item]
            response = client.post(f"/api/v1/devices/{printer['id']}/jobs", params={"filename": "square.gcode"},
                                   content=sample_path(SAMPLE_GCODE).read_bytes(),
                                   headers={"content-type": "application/octet-stream"})
            assert response.status_code == 201, response.text
            states: list[dict[str, Any]] = []
            ended = _next_event(ws, lambda e: (e["type"] == "state" and states.append(e["state"]["summary"])) or (
                e["type"] == "job" and e["job"]["state"] not in ("queued", "running")), "the job's end", 180)
        assert ended["job"]["state"] == "done", ended
        assert (states[-1]["state"], states[-1]["actions"]) == ("done", ["acknowledge"]), states[-1]
        assert summary(client, printer["id"])["actions"] == ["acknowledge"]


def test_subscription_to_an_unknown_device_is_refused(bench: Bench) -> None:
    from websockets.exceptions import InvalidStatus

    with pytest.raises(InvalidStatus) as refused, connect(f"{bench.agent.ws_url}?device=nope"):
        pass
    response = refused.value.response
    assert response.status_code == 404
    assert json.loads(response.body or b"{}")["error"] == "UnknownDevice"


def test_restart_keeps_history_jobs_and_ids(bench: Bench, tmp_path: Path) -> None:
    with bench.agent.client() as client:
        lineus = wait_for(lambda: (d := device_of(client, "lineus"))["state"]["online"] and d, "the Line-us online")
        job = client.post(f"/api/v1/devices/{lineus['id']}/actions/text", json={"text": "ok"}).json()["job"]
        wait_for(lambda: client.get(f"/api/v1/jobs/{job['id']}").json()["state"] == "done", "the drawing done")
        before = client.get(f"/api/v1/devices/{lineus['id']}/history").json()
        ids = sorted(d["id"] for d in client.get("/api/v1/devices").json())
    code, _ = bench.agent.stop()
    assert code == 0
    bench.agent = start_agent(bench.agent.state_dir, "--config", str(bench.config))
    with bench.agent.client() as client:
        assert sorted(d["id"] for d in client.get("/api/v1/devices").json()) == ids
        jobs = client.get("/api/v1/jobs").json()
        assert [(j["id"], j["state"]) for j in jobs] == [(job["id"], "done")]
        after = client.get(f"/api/v1/devices/{lineus['id']}/history").json()
        assert len(after["samples"]) >= len(before["samples"]) >= 1
        assert after["samples"][: len(before["samples"])] == before["samples"]
        assert any(e["type"] == "job" and e["job"]["id"] == job["id"] for e in after["events"])


def test_job_running_when_the_agent_stops_is_marked_interrupted(bench: Bench) -> None:
    with bench.agent.client() as client:
        lineus = wait_for(lambda: (d := device_of(client, "lineus"))["state"]["online"] and d, "the Line-us online")
        job = client.post(f"/api/v1/devices/{lineus['id']}/actions/text",
                          json={"text": "a long line of words"}).json()["job"]
        wait_for(lambda: client.get(f"/api/v1/jobs/{job['id']}").json()["state"] == "running", "the drawing running")
    bench.agent.stop()
    bench.agent = start_agent(bench.agent.state_dir, "--config", str(bench.config))
    with bench.agent.client() as client:
        assert client.get(f"/api/v1/jobs/{job['id']}").json()["state"] == "interrupted"
