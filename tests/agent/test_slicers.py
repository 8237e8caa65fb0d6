"""Slicers' "send to printer", replayed request by request as their public source makes them, against
`fabwire serve --demo`: each row of `SLICERS` names the file it was read from."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import httpx
import pytest

from .agenttools import RunningAgent, start_agent, summary, wait_for
from .doortools import XYZ, approve_key_requests, multipart, printing, prusaslicer_gcode, wait_idle

KEY = "0123456789ABCDEF0123456789ABCDEF"


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningAgent]:
    agent = start_agent(tmp_path_factory.mktemp("slicers") / "state", "--demo", "--speed", "30")
    yield agent
    agent.stop()


def prusaslicer_octoprint(client: httpx.Client, host: str, name: str, data: bytes) -> None:
    """prusa3d/PrusaSlicer src/slic3r/Utils/OctoPrint.cpp: OctoPrint::test then upload_inner_with_host.
    GET {host}/api/version with X-Api-Key: the JSON needs `api`, and `text` (when present) must start with
    "OctoPrint" (else "Mismatched type of print host"); then POST {host}/api/files/local, multipart: print=true,
    path=<the upload's parent folder, here empty>, file typed application/octet-stream (Http.cpp form_add_file);
    any status >= 400 is an error."""
    version = client.get(f"{host}/api/version", headers={"X-Api-Key": KEY})
    assert version.status_code < 400
    info = version.json()
    assert "api" in info
    assert info["text"].startswith("OctoPrint")
    body, ctype = multipart([("print", "true"), ("path", "")], name, data)
    upload = client.post(f"{host}/api/files/local", content=body, headers={"Content-Type": ctype, "X-Api-Key": KEY})
    assert upload.status_code < 400, upload.text


def orcaslicer_octoprint(client: httpx.Client, host: str, name: str, data: bytes) -> None:
    """SoftFever/OrcaSlicer src/slic3r/Utils/OctoPrint.cpp ("Octo/Klipper" host): the same version check, then
    POST api/files/local with print="true"|"false" always present, path, an optional 1-based plateindex (servers
    that do not use it ignore it), then the file."""
    version = client.get(f"{host}/api/version", headers={"X-Api-Key": KEY}).json()
    assert "api" in version
    assert version["text"].startswith("OctoPrint")
    body, ctype = multipart([("print", "true"), ("path", ""), ("plateindex", "1")], name, data)
    upload = client.post(f"{host}/api/files/local", content=body, headers={"Content-Type": ctype, "X-Api-Key": KEY})
    assert upload.status_code < 400, upload.text


def prusaslicer_moonraker(client: httpx.Client, host: str, name: str, data: bytes) -> None:
    """supermerill/SuperSlicer src/slic3r/Utils/Moonraker.cpp (PrusaSlicer's Moonraker host, Prusa Research
    2023): Moonraker::test GET {host}/server/info with X-Api-Key — the first member of the JSON must be `result`
    holding `moonraker_version`; then POST {host}/server/files/upload, multipart: root=gcodes, path only when
    not empty, print=true, then the file."""
    info = client.get(f"{host}/server/info", headers={"X-Api-Key": KEY})
    assert info.status_code < 400
    parsed = json.loads(info.text)
    assert next(iter(parsed)) == "result"
    assert parsed["result"]["moonraker_version"]
    body, ctype = multipart([("root", "gcodes"), ("print", "true")], name, data)
    upload = client.post(f"{host}/server/files/upload", content=body,
                         headers={"Content-Type": ctype, "X-Api-Key": KEY})
    assert upload.status_code < 400, upload.text


def cura_octoprint_plugin(client: httpx.Client, host: str, name: str, data: bytes, agent: RunningAgent) -> None:
    """fieldOfView/Cura-OctoPrintPlugin: DiscoverOctoPrintAction.py (GET plugin/appkeys/probe → 204 means
    supported; POST plugin/appkeys/request {"app": "Cura"} → 201/202 and a Location to poll; polling it: 202
    pending, 200 {"api_key"}; then GET api/settings with the key → 200, reading feature.sdSupport, webcam and the
    plugins' names) and OctoPrintOutputDevice.py (connect: GET api/settings, api/version reading `server`,
    POST api/login {"passive": true}, GET api/printerprofiles with a `current` profile; polling api/printer and
    api/job; the upload: a multipart whose parts' Content-Disposition is "form-data; …" — path (the folder),
    file (application/octet-stream), then select=true and print=true when it starts the print in the upload;
    201 with a Location whose files/local/NAME end point it keeps; job commands POST api/job →204)."""
    assert client.get(f"{host}/plugin/appkeys/probe").status_code == 204
    asked = client.post(f"{host}/plugin/appkeys/request", json={"app": "Cura"})
    assert asked.status_code in (201, 202)
    poll = asked.headers["location"]
    assert client.get(poll).status_code == 202
    approve_key_requests(agent, "Cura")
    granted = client.get(poll)
    assert granted.status_code == 200
    key = granted.json()["api_key"]
    headers = {"X-Api-Key": key, "User-Agent": "Cura-OctoPrintPlugin/3.7"}
    settings = client.get(f"{host}/api/settings", headers=headers)
    assert settings.status_code == 200
    assert settings.json()["feature"]["sdSupport"] is False
    assert isinstance(settings.json()["plugins"], dict)
    assert "server" in client.get(f"{host}/api/version", headers=headers).json()
    assert client.post(f"{host}/api/login", json={"passive": True}, headers=headers).status_code == 200
    profiles = client.get(f"{host}/api/printerprofiles", headers=headers).json()["profiles"]
    assert any(p.get("current") and p["axes"]["x"]["speed"] for p in profiles.values())
    for end_point in ("printer", "job"):
        assert client.get(f"{host}/api/{end_point}", headers=headers).status_code == 200
    body, ctype = multipart([("path", ""), ("select", "true"), ("print", "true")], name, data, file_at=1)
    upload = client.post(f"{host}/api/files/local", content=body, headers={**headers, "Content-Type": ctype})
    assert upload.status_code == 201, upload.text
    end_point = upload.headers["location"].split("api/", 1)[1]
    assert end_point == f"files/local/{name}"


@dataclass(frozen=True)
class Slicer:
    name: str
    send: Callable[..., None]
    host_path: str
    """What the owner types after the address in the slicer's host field ("" or "/printers/printer")."""


SLICERS = (
    Slicer("PrusaSlicer OctoPrint", prusaslicer_octoprint, ""),
    Slicer("PrusaSlicer OctoPrint, machine by name", prusaslicer_octoprint, "/printers/printer"),
    Slicer("OrcaSlicer Octo/Klipper", orcaslicer_octoprint, ""),
    Slicer("PrusaSlicer Moonraker", prusaslicer_moonraker, ""),
    Slicer("PrusaSlicer Moonraker, machine by name", prusaslicer_moonraker, "/printers/printer"),
    Slicer("Cura OctoPrint plugin", cura_octoprint_plugin, ""),
)


@pytest.mark.parametrize("slicer", SLICERS, ids=[s.name for s in SLICERS])
def test_send_to_printer_prints(demo: RunningAgent, slicer: Slicer) -> None:
    """Each slicer's requests, then the demo da Vinci prints the file it sent (its job carries the name)."""
    name = f"{slicer.name.split()[0].lower()}_{int(time.time() * 1000) % 100000}.gcode"
    with demo.client() as client:
        wait_idle(client)
        host = demo.url.rstrip("/") + slicer.host_path
        args = (client, host, name, prusaslicer_gcode())
        if slicer.send is cura_octoprint_plugin:
            cura_octoprint_plugin(*args, demo)
        else:
            slicer.send(*args)
        wait_for(lambda: printing(client), f"{slicer.name}: printing")
        jobs = client.get("/api/v1/jobs", params={"device": XYZ}).json()
        assert jobs[0]["filename"] == name
        assert summary(client, XYZ)["state"] == "printing"


def test_cura_selects_and_prints_after_the_upload(demo: RunningAgent) -> None:
    """OctoPrintOutputDevice.py's other path (when it waits for an analysis, or the upload only stores): upload
    without select/print, then POST files/local/NAME {"command": "select", "print": true} → 204, and the
    job commands pause (toggle) and cancel → 204."""
    with demo.client() as client:
        wait_idle(client)
        body, ctype = multipart([("path", "")], "cura_later.gcode", prusaslicer_gcode(minutes=60))
        upload = client.post("/api/files/local", content=body, headers={"Content-Type": ctype})
        assert upload.status_code == 201
        assert not printing(client)
        end_point = upload.headers["location"].split("api/", 1)[1]
        assert client.post(f"/api/{end_point}", json={"command": "select", "print": True}).status_code == 204
        wait_for(lambda: printing(client), "printing after select+print")
        assert client.post("/api/job", json={"command": "pause"}).status_code == 204
        wait_for(lambda: summary(client, XYZ)["state"] == "paused", "paused by Cura's toggle")
        assert client.post("/api/job", json={"command": "pause"}).status_code == 204
        wait_for(lambda: summary(client, XYZ)["state"] == "printing", "resumed by Cura's toggle")
        assert client.post("/api/job", json={"command": "cancel"}).status_code == 204
        wait_for(lambda: summary(client, XYZ)["state"] == "idle", "cancelled")
