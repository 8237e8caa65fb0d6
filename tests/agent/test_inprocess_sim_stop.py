"""An agent watching in-process simulators (`sim://`) stops cleanly after they worked: a simulator's own tasks (the
Line-us arm that moves) end with its link, never outliving the loop they run on."""

from __future__ import annotations

from pathlib import Path

import pytest

from .agenttools import start_agent, wait_for

SVG = (b'<svg xmlns="http://www.w3.org/2000/svg" width="50mm" height="50mm" viewBox="0 0 50 50">'
       b'<path d="M5 5 L45 45 M5 45 L45 5" stroke="black" fill="none"/></svg>')

ADDRESSES = [
    ("lineus", "arm:lineus=sim://lineus?speed=100"),
    ("xyz", "printer:xyz=sim://xyz?speed=100"),
    ("mmu", "unit:mmu=sim://mmu"),
]


@pytest.mark.parametrize(("kind", "device"), ADDRESSES, ids=[kind for kind, _ in ADDRESSES])
def test_sigterm_after_work_on_an_in_process_simulator_leaves_no_traceback(tmp_path: Path, kind: str,
                                                                           device: str) -> None:
    agent = start_agent(tmp_path / "state", "--device", device)
    try:
        with agent.client() as client:
            machine = wait_for(lambda: next((d for d in client.get("/api/v1/devices").json()
                                             if d["state"]["online"]), None), f"the {kind} simulator online")
            if kind == "lineus":
                job = client.post(f"/api/v1/devices/{machine['id']}/jobs", params={"filename": "x.svg"},
                                  content=SVG, headers={"content-type": "application/octet-stream"})
                assert job.status_code == 201, job.text
                wait_for(lambda: client.get("/api/v1/jobs").json()[0]["state"] == "done", "the drawing done")
    finally:
        code, stderr = agent.stop()
    assert code == 0, stderr
    for sign in ("Traceback", "Task was destroyed", "Exception ignored", "Event loop is closed"):
        assert sign not in stderr, stderr
