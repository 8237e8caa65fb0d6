"""The slicer and Home Assistant doors behind the agent's one boundary, with the token required (as off
loopback): `X-Api-Key` carries it, the application-key flow is the only way in without it, and a web page of
another origin cannot write through these routes either."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Iterator
from urllib.parse import urlsplit

import aiohttp
import httpx
import pytest

from .agenttools import RunningAgent, start_agent
from .doortools import multipart, prusaslicer_gcode, wait_idle


@pytest.fixture(scope="module")
def guarded(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningAgent]:
    agent = start_agent(tmp_path_factory.mktemp("guarded") / "state", "--demo", "--speed", "30", "--token")
    agent.token = (agent.state_dir / "access-token").read_text().strip()
    yield agent
    agent.stop()


def test_the_key_flow_is_open_and_hands_out_the_token_after_approval(guarded: RunningAgent) -> None:
    """Cura's and Home Assistant's way in (DiscoverOctoPrintAction.py; pyoctoprintapi request_app_key): probe,
    request and poll need no key; the key comes only after the owner approves (with the token) on the page."""
    with httpx.Client(base_url=guarded.url.rstrip("/"), timeout=30) as stranger:
        for prefix in ("", "/printers/printer"):
            assert stranger.get(f"{prefix}/plugin/appkeys/probe").status_code == 204
            asked = stranger.post(f"{prefix}/plugin/appkeys/request", json={"app": "Cura"})
            assert asked.status_code == 201
            poll = asked.headers["location"]
            assert stranger.get(poll).status_code == 202
            assert stranger.get("/api/v1/appkeys").status_code == 401  # deciding takes the token
            with guarded.client() as owner:
                request_id = asked.json()["app_token"]
                assert owner.post(f"/api/v1/appkeys/{request_id}/approve").status_code == 200
            granted = stranger.get(poll)
            assert granted.status_code == 200
            assert granted.json()["api_key"] == guarded.token
        denied = stranger.post("/plugin/appkeys/request", json={"app": "Unknown"})
        with guarded.client() as owner:
            assert owner.post(f"/api/v1/appkeys/{denied.json()['app_token']}/deny").status_code == 200
        assert stranger.get(denied.headers["location"]).status_code == 404


@pytest.mark.parametrize(("method", "path"), [("GET", "/api/version"), ("GET", "/api/job"),
                                              ("GET", "/printers/printer/api/settings"), ("GET", "/server/info"),
                                              ("GET", "/printer/objects/query?print_stats"),
                                              ("GET", "/printers/line-us/server/files/list")])
def test_every_door_route_takes_the_token_as_x_api_key(guarded: RunningAgent, method: str, path: str) -> None:
    with httpx.Client(base_url=guarded.url.rstrip("/"), timeout=30) as client:
        assert client.request(method, path).status_code == 401
        assert client.request(method, path, headers={"X-Api-Key": "not-the-token"}).status_code == 401
        assert client.request(method, path, headers={"X-Api-Key": guarded.token or ""}).status_code == 200


def test_a_slicer_with_a_wrong_key_sees_an_error_and_nothing_prints(guarded: RunningAgent) -> None:
    """PrusaSlicer shows any status >= 400 as an error (src/slic3r/Utils/Http.cpp)."""
    with guarded.client() as owner:
        wait_idle(owner)
    body, ctype = multipart([("print", "true"), ("path", "")], "wrong_key.gcode", prusaslicer_gcode())
    with httpx.Client(base_url=guarded.url.rstrip("/"), timeout=30) as client:
        response = client.post("/api/files/local", content=body, headers={"Content-Type": ctype, "X-Api-Key": "x"})
        assert response.status_code == 401
    with guarded.client() as owner:
        assert all(j["filename"] != "wrong_key.gcode" for j in owner.get("/api/v1/jobs").json())


@pytest.mark.parametrize("path", ["/api/files/local", "/server/files/upload", "/printers/printer/api/job"])
def test_a_foreign_web_page_cannot_write_through_the_doors(guarded: RunningAgent, path: str) -> None:
    """A page of another origin, even one that somehow knows the key, is refused before the route runs."""
    body, ctype = multipart([("print", "true")], "x.gcode", prusaslicer_gcode())
    headers = {"Origin": "http://evil.example", "X-Api-Key": guarded.token or "", "Content-Type": ctype}
    with httpx.Client(base_url=guarded.url.rstrip("/"), timeout=30) as client:
        if path.endswith("/job"):
            headers["Content-Type"] = "application/json"
            response = client.post(path, content=json.dumps({"command": "cancel"}), headers=headers)
        else:
            response = client.post(path, content=body, headers=headers)
        assert response.status_code == 403


def test_the_moonraker_websocket_takes_the_key_header(guarded: RunningAgent) -> None:
    url = urlsplit(guarded.url)

    async def connect(key: str) -> object:
        async with aiohttp.ClientSession() as session:
            try:
                async with session.ws_connect(f"ws://{url.netloc}/websocket", headers={"X-Api-Key": key}) as ws:
                    await ws.send_json({"jsonrpc": "2.0", "method": "server.info", "id": 7})
                    return (await ws.receive_json())["result"]["klippy_state"]
            except aiohttp.WSServerHandshakeError as exc:
                return exc.status

    states = [asyncio.run(connect(guarded.token or ""))]
    while states[-1] == "disconnected" and len(states) < 120:  # the demo printer may still be connecting
        time.sleep(0.5)
        states.append(asyncio.run(connect(guarded.token or "")))
    assert states[-1] == "ready", states[-3:]
    assert asyncio.run(connect("wrong")) in (401, 403)
