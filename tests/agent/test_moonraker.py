"""The Moonraker-compatible routes of `fabwire serve --demo`, driven by Home Assistant's Moonraker client
(`moonraker-api`): connect, query objects, subscribe, and follow a print through `notify_status_update`."""

from __future__ import annotations

import asyncio
import io
from collections.abc import Iterator
from typing import Any
from urllib.parse import urlsplit

import httpx
import pytest
from moonraker_api import MoonrakerClient, MoonrakerListener
from PIL import Image

from .agenttools import RunningAgent, start_agent, wait_for
from .doortools import XYZ, multipart, printing, prusaslicer_gcode, wait_idle


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningAgent]:
    agent = start_agent(tmp_path_factory.mktemp("moonraker") / "state", "--demo", "--speed", "30")
    yield agent
    agent.stop()


class Listener(MoonrakerListener):  # type: ignore[misc]
    def __init__(self) -> None:
        self.updates: list[dict[str, Any]] = []

    async def on_notification(self, method: str, data: Any) -> None:
        if method == "notify_status_update":
            self.updates.append(data[0])


def moonraker_upload(client: httpx.Client, name: str, data: bytes, prefix: str = "") -> httpx.Response:
    """The Moonraker host's upload (supermerill/SuperSlicer src/slic3r/Utils/Moonraker.cpp): root=gcodes,
    print=true, then the file; `path` only when the upload names a folder."""
    body, ctype = multipart([("root", "gcodes"), ("print", "true")], name, data)
    return client.post(f"{prefix}/server/files/upload", content=body, headers={"Content-Type": ctype})


def test_home_assistant_moonraker_client_follows_a_print(demo: RunningAgent) -> None:
    host, port = urlsplit(demo.url).hostname, urlsplit(demo.url).port
    with demo.client() as client:
        wait_idle(client)

    async def scenario() -> dict[str, Any]:
        listener = Listener()
        moon = MoonrakerClient(listener, host, port)
        seen: dict[str, Any] = {}
        assert await moon.connect()
        try:
            seen["server"] = await moon.get_server_info()
            seen["klipper"] = await moon.get_klipper_status()
            seen["host"] = await moon.get_host_info()
            seen["modules"] = await moon.get_supported_modules()
            seen["ws_id"] = await moon.get_websocket_id()
            seen["subscribed"] = await moon.call_method("printer.objects.subscribe", objects={
                "print_stats": None, "virtual_sdcard": ["progress", "is_active"], "extruder": ["temperature"]})
            with httpx.Client(base_url=demo.url.rstrip("/"), timeout=30) as client:
                response = await asyncio.to_thread(moonraker_upload, client, "moon_square.gcode",
                                                   prusaslicer_gcode(minutes=20))
                seen["upload"] = (response.status_code, response.json())

            def progress_seen() -> bool:
                return any((u.get("virtual_sdcard") or {}).get("progress", 0) > 0 for u in listener.updates)

            for _ in range(400):
                if progress_seen():
                    break
                await asyncio.sleep(0.25)
            seen["updates"] = list(listener.updates)
            seen["query"] = await moon.call_method("printer.objects.query",
                                                   objects={"print_stats": ["state", "filename"],
                                                            "heater_bed": None, "no_such_object": None})
            seen["metadata"] = await moon.call_method("server.files.metadata", filename="moon_square.gcode")
            seen["history"] = await moon.call_method("server.history.list", limit=5)
            seen["unknown"] = await moon.call_method("printer.no.such.method")
            seen["cancel"] = await moon.call_method("printer.print.cancel")
        finally:
            await moon.disconnect()
        return seen

    seen = asyncio.run(scenario())
    assert seen["server"]["klippy_state"] == "ready"
    assert seen["klipper"] == "ready"
    assert seen["host"]["state"] == "ready"
    assert {"print_stats", "extruder", "heater_bed", "virtual_sdcard", "display_status"} <= set(seen["modules"])
    assert seen["ws_id"]["websocket_id"] > 0
    assert seen["subscribed"]["status"]["print_stats"]["state"] == "standby"
    assert set(seen["subscribed"]["status"]["virtual_sdcard"]) == {"progress", "is_active"}
    status, body = seen["upload"]
    assert status == 201
    assert body["result"]["print_started"] is True
    assert body["result"]["item"] == {**body["result"]["item"], "path": "moon_square.gcode", "root": "gcodes"}
    states = [u["print_stats"]["state"] for u in seen["updates"] if "state" in u.get("print_stats", {})]
    assert "printing" in states
    progress = [u["virtual_sdcard"]["progress"] for u in seen["updates"] if "progress" in u.get("virtual_sdcard", {})]
    assert progress == sorted(progress)
    assert progress[-1] > 0
    assert all(set(u) <= {"print_stats", "virtual_sdcard", "extruder"} for u in seen["updates"])
    assert seen["query"]["status"]["print_stats"] == {"state": "printing", "filename": "moon_square.gcode"}
    assert "no_such_object" not in seen["query"]["status"]
    assert set(seen["query"]["status"]["heater_bed"]) >= {"temperature", "target"}
    meta = seen["metadata"]
    assert meta["estimated_time"] == 20 * 60 + 2
    assert meta["filament_total"] == pytest.approx(43.21)
    assert meta["layer_count"] == 3
    assert meta["slicer"] == "prusaslicer"
    assert [(t["width"], t["height"]) for t in meta["thumbnails"]] == [(16, 16), (220, 124)]
    assert seen["history"]["jobs"][0]["filename"] == "moon_square.gcode"
    assert seen["history"]["jobs"][0]["status"] == "in_progress"
    assert seen["unknown"]["error"]["code"] == -32601
    assert seen["cancel"] == "ok"
    with demo.client() as client:
        image = client.get(f"/server/files/gcodes/{meta['thumbnails'][-1]['relative_path']}")
        assert image.status_code == 200
        assert Image.open(io.BytesIO(image.content)).size == (220, 124)
        wait_for(lambda: client.get("/printer/objects/query", params={"print_stats": ""}).json()
                 ["result"]["status"]["print_stats"]["state"] == "cancelled", "the print cancelled (Klipper's word)")
        assert client.get("/printer/objects/query", params={"webhooks": ""}).json()["result"]["status"][
            "webhooks"]["state"] == "ready"
        history = client.get("/server/history/list").json()["result"]["jobs"]
        assert history[0]["status"] == "cancelled"


def test_moonraker_http_routes_answer_in_moonraker_shapes(demo: RunningAgent) -> None:
    """GET /server/info has `result` first with `moonraker_version` (what the slicers check); the objects query
    takes Moonraker's query form; what a da Vinci cannot do is 409 with the reason in Moonraker's error shape."""
    with demo.client() as client:
        info = client.get("/server/info").json()
        assert next(iter(info)) == "result"
        assert info["result"]["moonraker_version"]
        wait_for(lambda: client.get("/printer/objects/query", params={"webhooks": ""}).json()["result"]["status"]
                 ["webhooks"]["state"] == "ready", "the demo printer connected")  # a loaded machine is slower
        query = client.get("/printer/objects/query", params={"extruder": "temperature,target", "webhooks": ""})
        status = query.json()["result"]["status"]
        assert set(status["extruder"]) == {"temperature", "target"}
        assert status["webhooks"]["state"] == "ready"
        refused = client.post("/printer/gcode/script", params={"script": "G28"})
        assert refused.status_code == 409
        assert "G-code" in refused.json()["error"]["message"]
        assert client.get("/server/files/metadata", params={"filename": "nope.gcode"}).status_code == 404
        wait_for(lambda: client.get("/printers/line-us/server/info").json()["result"]["klippy_connected"] is True,
                 "the demo Line-us connected")
        assert client.get("/printers/nope/server/info").status_code == 404


def test_a_checksum_that_does_not_match_is_422_and_keeps_nothing(demo: RunningAgent) -> None:
    with demo.client() as client:
        wait_idle(client)
        body, ctype = multipart([("root", "gcodes"), ("checksum", "0" * 64)], "sum.gcode", prusaslicer_gcode())
        response = client.post("/server/files/upload", content=body, headers={"Content-Type": ctype})
        assert response.status_code == 422
        assert client.get("/server/files/metadata", params={"filename": "sum.gcode"}).status_code == 404
        assert not printing(client, XYZ)
