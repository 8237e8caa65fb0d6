"""Safe by default: loopback unless a token guards the API, bounded uploads under generated names."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import httpx
import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from clitools import cli_env, run_cli

from .agenttools import device_of, start_agent, wait_for
from .conftest import Bench


def test_non_loopback_without_a_token_refuses_to_start(tmp_path: Path) -> None:
    result = run_cli("serve", "--listen", "0.0.0.0:0", "--no-token", "--state-dir", str(tmp_path),
                     env=cli_env(tmp_path))
    assert result.returncode == 4
    assert "refusing to listen on 0.0.0.0 without an access token" in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "access-token").exists()


def test_non_loopback_needs_the_token_which_is_shown_once(tmp_path: Path) -> None:
    agent = start_agent(tmp_path, "--listen", "0.0.0.0:0")
    try:
        token_file = tmp_path / "access-token"
        token = token_file.read_text().strip()
        assert stat.S_IMODE(token_file.stat().st_mode) == 0o600
        url = agent.url.replace("0.0.0.0", "127.0.0.1").rstrip("/")
        refused = httpx.get(f"{url}/api/v1/devices")
        assert refused.status_code == 401
        assert refused.json()["error"] == "AccessDenied"
        assert refused.json()["exit_code"] == 3
        assert httpx.get(f"{url}/api/v1/devices", headers={"Authorization": "Bearer wrong"}).status_code == 401
        allowed = httpx.get(f"{url}/api/v1/devices", headers={"Authorization": f"Bearer {token}"})
        assert allowed.status_code == 200
        assert allowed.json() == []
        assert httpx.get(f"{url}/").status_code == 200  # the page itself holds no data; it asks for the token
        ws_url = url.replace("http://", "ws://") + "/api/v1/events"
        with pytest.raises(InvalidStatus) as refused_ws, connect(ws_url):
            pass
        assert refused_ws.value.response.status_code == 401
        with connect(ws_url, subprotocols=["fabwire", f"fabwire.token.{token}"]) as ws:  # type: ignore[list-item]
            assert ws.subprotocol == "fabwire"
    finally:
        _, stderr = agent.stop()
    assert stderr.count(token) == 1  # shown when it was made …
    again = start_agent(tmp_path, "--listen", "0.0.0.0:0")
    _, stderr = again.stop()
    assert token not in stderr  # … and never again
    assert token_file.read_text().strip() == token


def test_upload_named_to_escape_lands_under_a_generated_name(bench: Bench) -> None:
    uploads = bench.agent.state_dir / "uploads"
    with bench.agent.client() as client:
        lineus = wait_for(lambda: (d := device_of(client, "lineus"))["state"]["online"] and d, "the Line-us online")
        svg = (b'<svg xmlns="http://www.w3.org/2000/svg" width="20mm" height="20mm">'
               b'<path d="M1 1 L19 19" stroke="black"/></svg>')
        response = client.post(f"/api/v1/devices/{lineus['id']}/jobs", params={"filename": "../../x.svg"},
                               content=svg)
        assert response.status_code == 201, response.text
        job = response.json()
    stored = list(uploads.iterdir())
    assert [p.name for p in stored] == [job["stored"]]
    assert job["stored"] == f"{job['id']}.svg"
    assert ".." not in job["stored"]
    assert stored[0].read_bytes() == svg
    assert not (bench.agent.state_dir.parent / "x.svg").exists()
    assert not (bench.agent.state_dir / "x.svg").exists()
    assert job["filename"] == "../../x.svg"  # kept only to show people what they sent


def test_uploads_over_the_limit_are_refused(tmp_path: Path, simulator: object) -> None:
    sim = simulator("xyz", "--listen", "127.0.0.1:0")  # type: ignore[operator]
    agent = start_agent(tmp_path / "state", "--device", f"p:xyz={sim.url}", "--max-upload", "0.01")
    try:
        with agent.client() as client:
            printer = wait_for(lambda: (d := device_of(client, "xyz"))["state"]["online"] and d, "the printer online")
            big = b"G1 X1\n" * 4000
            response = client.post(f"/api/v1/devices/{printer['id']}/jobs", params={"filename": "big.gcode"},
                                   content=big)
            assert response.status_code == 413
            assert response.json()["exit_code"] == 4
            assert "limit" in response.json()["message"]

            def chunks() -> object:
                yield from (big[i:i + 1000] for i in range(0, len(big), 1000))

            streamed = client.post(f"/api/v1/devices/{printer['id']}/jobs", params={"filename": "big.gcode"},
                                   content=chunks())  # no length declared: counted as it arrives
            assert streamed.status_code == 413
        assert not (tmp_path / "state" / "uploads").exists() or not os.listdir(tmp_path / "state" / "uploads")
    finally:
        agent.stop()
