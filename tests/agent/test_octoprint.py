"""The OctoPrint-compatible routes of `fabwire serve --demo`, driven by Home Assistant's own OctoPrint client
(`pyoctoprintapi`) and by plain requests for what it does not cover: honest refusals, the library, the queue."""

from __future__ import annotations

import asyncio
import io
import socket
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import aiohttp
import httpx
import pytest
from PIL import Image
from pyoctoprintapi import OctoprintClient

from fabwire.agent.library import SLICER_OUTPUTS, SlicerOutput

from .agenttools import RunningAgent, start_agent, wait_for
from .doortools import XYZ, approve_key_requests, multipart, printing, prusaslicer_gcode, wait_idle

LONG = {"minutes": 90, "seconds": 0}
"""A print long enough to pause, resume and cancel (three minutes at the demo's 30x)."""


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningAgent]:
    agent = start_agent(tmp_path_factory.mktemp("octoprint") / "state", "--demo", "--speed", "30")
    yield agent
    agent.stop()


def send(client: httpx.Client, name: str, data: bytes, *, prefix: str = "", print_: bool = True,
         fields: list[tuple[str, str]] | None = None) -> httpx.Response:
    """PrusaSlicer's upload (src/slic3r/Utils/OctoPrint.cpp): print, path, then the file part."""
    body, ctype = multipart(fields if fields is not None else [("print", "true" if print_ else "false"),
                                                               ("path", "")], name, data)
    return client.post(f"{prefix}/api/files/local", content=body,
                       headers={"Content-Type": ctype, "X-Api-Key": "0123456789ABCDEF"})


def test_home_assistant_gets_a_key_and_follows_a_print(demo: RunningAgent) -> None:
    """Home Assistant's OctoPrint integration through pyoctoprintapi: the application-key flow approved by the
    owner, the server, the discovery id it uses as the unique id, the printer, the job, and pause, resume and
    cancel while the demo da Vinci prints."""
    host, port = urlsplit(demo.url).hostname, urlsplit(demo.url).port
    assert host is not None
    assert port is not None
    with demo.client() as client:
        wait_idle(client)

    async def scenario() -> dict[str, Any]:
        seen: dict[str, Any] = {}
        async with aiohttp.ClientSession() as session:
            octo = OctoprintClient(host, session, port, False, "/")
            asking = asyncio.ensure_future(octo.request_app_key("Home Assistant", "owner", 60))
            await asyncio.to_thread(approve_key_requests, demo, "Home Assistant")
            seen["key"] = await asking
            octo.set_api_key(seen["key"])
            seen["version"] = (await octo.get_server_info()).version
            seen["uuid"] = (await octo.get_discovery_info()).upnp_uuid
            for path in ("/printers/printer/", "/printers/line-us/"):
                other = OctoprintClient(host, session, port, False, path)
                other.set_api_key(seen["key"])
                seen[path] = (await other.get_discovery_info()).upnp_uuid
            idle = await octo.get_printer_info()
            seen["idle"] = (idle.state.text, idle.state.flags.ready, {t.name for t in idle.temperatures})

            with httpx.Client(base_url=demo.url.rstrip("/"), timeout=30) as client:
                response = await asyncio.to_thread(send, client, "long_square.gcode", prusaslicer_gcode(**LONG))
                assert response.status_code == 201, response.text
                await asyncio.to_thread(wait_for, lambda: printing(client), "printing")

            async def job_state(wanted: str) -> Any:
                for _ in range(240):
                    job = await octo.get_job_info()
                    if job.state == wanted:
                        return job
                    await asyncio.sleep(0.25)
                raise AssertionError(f"the job never became {wanted} (last {job.state})")

            job = await job_state("Printing")
            seen["job"] = (job.job.file.name, job.job.file.origin, job.job.estimated_print_time,
                           job.progress.completion is not None)
            printer = await octo.get_printer_info()
            seen["printing_flags"] = (printer.state.flags.printing, printer.state.flags.ready)
            await octo.pause_job()
            await job_state("Paused")
            await octo.resume_job()
            await job_state("Printing")
            await octo.cancel_job()
            await job_state("Operational")
        return seen

    seen = asyncio.run(scenario())
    assert seen["key"] == (demo.state_dir / "access-token").read_text().strip()
    assert seen["version"] == "1.10.0"
    assert uuid.UUID(seen["uuid"])
    assert seen["/printers/printer/"] == seen["uuid"]
    assert seen["/printers/line-us/"] != seen["uuid"]
    assert seen["idle"] == ("Operational", True, {"tool0", "bed"})
    assert seen["job"] == ("long_square.gcode", "local", 90 * 60, True)
    assert seen["printing_flags"] == (True, False)
    with demo.client() as client:
        jobs = client.get("/api/v1/jobs", params={"device": XYZ}).json()
        assert jobs[0]["filename"] == "long_square.gcode"
        assert jobs[0]["state"] == "cancelled"


def test_a_print_that_cannot_start_now_is_refused_with_the_reason(demo: RunningAgent) -> None:
    """Never 201-then-failed: while printing, and while a finished print waits to be taken off (the da Vinci's
    "print removed"), an upload with print=true answers 409 with the reason and keeps nothing; the native
    /api/v1 upload says the same."""
    with demo.client() as client:
        wait_idle(client)
        assert send(client, "first.gcode", prusaslicer_gcode()).status_code == 201
        wait_for(lambda: printing(client), "printing")
        refused = send(client, "second.gcode", prusaslicer_gcode())
        assert refused.status_code == 409
        assert "printing" in refused.json()["error"]
        assert client.get("/api/files/local/second.gcode").status_code == 404
        # the first print ends and waits on the bed
        wait_for(lambda: client.get(f"/api/v1/devices/{XYZ}/state").json()["summary"]["state"] == "done",
                 "the print finished", 90)
        wait_for(lambda: client.get("/api/job").json()["state"] == "Operational", "the job over")
        for response in (send(client, "second.gcode", prusaslicer_gcode()),
                         client.post(f"/api/v1/devices/{XYZ}/jobs", params={"filename": "second.gcode"},
                                     content=prusaslicer_gcode())):
            assert response.status_code == 409, response.text
            assert "acknowledge" in response.text
            assert "on the bed" in response.text
        assert client.get("/api/printer").json()["state"]["flags"]["ready"] is False
        # "Print removed": once the action answers, the machine is ready for the very next upload
        assert client.post(f"/api/v1/devices/{XYZ}/actions/acknowledge", json={}).status_code == 200
        assert client.get("/api/printer").json()["state"]["flags"]["ready"] is True
        sent = send(client, "second.gcode", prusaslicer_gcode())
        assert sent.status_code == 201, sent.text
        wait_for(lambda: printing(client), "printing the second file")


def test_the_queue_holds_prints_until_the_machine_is_free_and_acknowledged(demo: RunningAgent) -> None:
    """With the queue on (Moonraker's queue_gcode_uploads), a print sent while the machine is busy waits, and
    starts once the finished print before it is acknowledged."""
    with demo.client() as client:
        wait_idle(client)
        assert client.put(f"/api/v1/devices/{XYZ}/queue", json={"enabled": True}).status_code == 200
        try:
            assert send(client, "queue_a.gcode", prusaslicer_gcode()).status_code == 201
            wait_for(lambda: printing(client), "printing queue_a")
            queued = send(client, "queue_b.gcode", prusaslicer_gcode())
            assert queued.status_code == 201
            assert queued.json()["queued"] is True
            assert queued.json()["effectivePrint"] is False
            assert client.get(f"/api/v1/devices/{XYZ}/library").json()["queue"] == ["queue_b.gcode"]
            wait_for(lambda: client.get(f"/api/v1/devices/{XYZ}/state").json()["summary"]["state"] == "done",
                     "queue_a finished", 90)
            assert client.get(f"/api/v1/devices/{XYZ}/library").json()["queue"] == ["queue_b.gcode"]
            client.post(f"/api/v1/devices/{XYZ}/actions/acknowledge", json={})
            wait_for(lambda: any(j["filename"] == "queue_b.gcode" and j["state"] in ("running", "done")
                                 for j in client.get("/api/v1/jobs", params={"device": XYZ}).json()),
                     "queue_b started by the queue", 60)
            assert client.get(f"/api/v1/devices/{XYZ}/library").json()["queue"] == []
        finally:
            client.put(f"/api/v1/devices/{XYZ}/queue", json={"enabled": False})


CANNOT: list[tuple[str, str, dict[str, Any], str]] = [
    ("/api/printer/tool", "POST", {"command": "target", "targets": {"tool0": 210}}, "temperature"),
    ("/api/printer/bed", "POST", {"command": "target", "target": 60}, "temperature"),
    ("/api/printer/command", "POST", {"command": "G28"}, "G-code"),
    ("/api/printer/sd", "POST", {"command": "init"}, "storage"),
    ("/api/job", "POST", {"command": "restart"}, "restart"),
    ("/api/connection", "POST", {"command": "disconnect"}, "connection"),
    ("/printers/mmu/api/job", "POST", {"command": "start"}, "selected"),
]
"""What OctoPrint offers and a da Vinci (or this door) cannot do: 409 with the reason, never 404 or 500."""


@pytest.mark.parametrize(("path", "method", "body", "reason"), CANNOT, ids=[c[0] + ":" + c[3] for c in CANNOT])
def test_what_a_da_vinci_cannot_do_is_409_with_the_reason(demo: RunningAgent, path: str, method: str,
                                                         body: dict[str, Any], reason: str) -> None:
    with demo.client() as client:
        response = client.request(method, path, json=body)
        assert response.status_code == 409, response.text
        assert reason in response.json()["error"]


def test_an_mmu_takes_no_files_and_unknown_machines_are_404(demo: RunningAgent) -> None:
    with demo.client() as client:
        body, ctype = multipart([("print", "true")], "x.gcode", prusaslicer_gcode())
        response = client.post("/printers/mmu/api/files/local", content=body, headers={"Content-Type": ctype})
        assert response.status_code == 409
        assert "takes no files" in response.text
        assert client.get("/printers/nope/api/job").status_code == 404
        assert client.get("/printers/printer/api/version").json()["text"].startswith("OctoPrint")


def test_the_library_keeps_figures_previews_and_files(demo: RunningAgent, tmp_path: Path) -> None:
    """An upload without print: listed with the intake's figures (estimatedPrintTime, filament) and the slicer's
    preview (OctoPrint `thumbnail`, served as an image), downloadable as sent, selectable, deletable."""
    data = prusaslicer_gcode(thumbs=[(16, 16, "png"), (120, 90, "qoi")], minutes=4, seconds=5, filament_mm=512.5)
    with demo.client() as client:
        wait_idle(client)
        response = send(client, "kept.gcode", data, print_=False,
                        fields=[("print", "false"), ("path", "parts")])
        assert response.status_code == 201, response.text
        assert response.headers["location"].endswith("/api/files/local/parts/kept.gcode")
        listing = client.get("/api/files").json()
        entry = next(f for f in listing["files"] if f["path"] == "parts/kept.gcode")
        assert entry["size"] == len(data)
        assert entry["origin"] == "local"
        assert entry["gcodeAnalysis"]["estimatedPrintTime"] == 245
        assert entry["gcodeAnalysis"]["filament"]["tool0"]["length"] == pytest.approx(512.5)
        image = client.get("/" + entry["thumbnail"])
        assert image.status_code == 200
        assert image.headers["content-type"] == "image/png"
        assert Image.open(io.BytesIO(image.content)).size == (120, 90)
        assert client.get(entry["refs"]["download"]).content == data
        assert client.post("/api/files/local/parts/kept.gcode", json={"command": "select"}).status_code == 204
        assert client.get("/api/job").json()["job"]["file"]["path"] == "parts/kept.gcode"
        assert client.delete("/api/files/local/parts/kept.gcode").status_code == 204
        assert client.get("/api/files/local/parts/kept.gcode").status_code == 404


@pytest.mark.parametrize(("folder", "name"), [("..", "escape.gcode"), ("a/../..", "b.gcode"), ("", "bad\x01name.gcode"),
                                            ("", "x" * 300 + ".gcode"), ("", "model.stl"), ("", "noextension")])
def test_file_names_no_library_keeps_are_400(demo: RunningAgent, folder: str, name: str) -> None:
    """Folders that climb out of the library, control characters, overlong names, files no da Vinci prints."""
    with demo.client() as client:
        response = send(client, name, prusaslicer_gcode(), fields=[("print", "false"), ("path", folder)])
        assert response.status_code == 400, response.text
        assert name not in [f["name"] for f in client.get("/api/files").json()["files"]]


@pytest.mark.parametrize("output", SLICER_OUTPUTS, ids=[o.suffix for o in SLICER_OUTPUTS])
def test_files_a_slicer_can_be_set_to_send_are_400_with_what_to_change(demo: RunningAgent,
                                                                       output: SlicerOutput) -> None:
    """Each row of SLICER_OUTPUTS (its source in the row): refused with the setting to change, nothing kept."""
    with demo.client() as client:
        response = send(client, f"part{output.suffix}", b"PK\x03\x04 not g-code")
        assert response.status_code == 400
        assert output.advice in response.json()["error"]
        assert f"part{output.suffix}" not in [f["name"] for f in client.get("/api/files").json()["files"]]


def test_a_folder_in_the_file_part_name_is_dropped(demo: RunningAgent) -> None:
    """The folder is the form's `path`; a client that puts one in the part's file name (Windows' too) does not
    reach outside it."""
    with demo.client() as client:
        response = send(client, "..\\..\\evil.gcode", prusaslicer_gcode(), print_=False)
        assert response.status_code == 201, response.text
        assert response.json()["files"]["local"]["path"] == "evil.gcode"
        assert client.delete("/api/files/local/evil.gcode").status_code == 204


def test_a_selected_file_starts_with_the_job_command_whatever_its_name(demo: RunningAgent) -> None:
    """A name with spaces, accents, Greek and brackets round-trips through both doors; the OctoPrint job
    command `start` prints the selected file."""
    name = "Kühlkörper Ω v2 (1).gcode"
    with demo.client() as client:
        wait_idle(client)
        response = send(client, name, prusaslicer_gcode(minutes=30), print_=False)
        assert response.status_code == 201, response.text
        resource = response.headers["location"]
        assert client.get(resource).json()["name"] == name
        assert client.get("/server/files/metadata", params={"filename": name}).json()["result"]["filename"] == name
        assert client.post(resource, json={"command": "select"}).status_code == 204
        assert client.post("/api/job", json={"command": "start"}).status_code == 204
        wait_for(lambda: printing(client), "printing the selected file")
        assert client.get("/api/job").json()["job"]["file"]["name"] == name
        assert client.post("/api/job", json={"command": "start"}).status_code == 409
        assert client.post("/api/job", json={"command": "cancel"}).status_code == 204
        wait_for(lambda: client.get("/api/job").json()["state"] == "Operational", "cancelled")


def test_a_line_us_takes_a_drawing_through_its_own_prefix(demo: RunningAgent) -> None:
    """A Line-us job is a drawing: an SVG sent to /printers/line-us/ is kept and drawn; a print file is not one."""
    svg = (b"<svg xmlns='http://www.w3.org/2000/svg' width='60mm' height='40mm' viewBox='0 0 60 40'>"
           b"<path d='M5 5 L55 5 L55 35 Z' stroke='black' fill='none'/></svg>")
    with demo.client() as client:
        lineus = "lineus-demo"
        wait_for(lambda: client.get(f"/api/v1/devices/{lineus}/state").json()["summary"]["state"] == "idle",
                 "the Line-us idle")
        response = send(client, "triangle.svg", svg, prefix="/printers/line-us")
        assert response.status_code == 201, response.text
        wait_for(lambda: any(j["filename"] == "triangle.svg" for j in
                             client.get("/api/v1/jobs", params={"device": lineus}).json()), "the drawing started")
        listed = client.get("/printers/line-us/api/files").json()["files"]
        assert [f["name"] for f in listed] == ["triangle.svg"]
        assert "triangle.svg" not in [f["name"] for f in client.get("/api/files").json()["files"]]
        refused = send(client, "part.3w", b"3DPFNKG13WTW", prefix="/printers/line-us", print_=False)
        assert refused.status_code == 400


def test_a_print_refused_is_answered_before_the_file_is_sent(demo: RunningAgent) -> None:
    """The machine is claimed when the file part begins (PrusaSlicer sends print=true first): while it prints,
    a second upload's 409 comes back although only the start of its 20 MB file has been sent."""
    with demo.client() as client:
        wait_idle(client)
        assert send(client, "busy.gcode", prusaslicer_gcode(minutes=30)).status_code == 201
        wait_for(lambda: printing(client), "printing")
        url = urlsplit(demo.url)
        body, ctype = multipart([("print", "true"), ("path", "")], "late.gcode", b"G1 X1\n" * 4_000_000)
        head = (f"POST /api/files/local HTTP/1.1\r\nHost: {url.netloc}\r\nContent-Type: {ctype}\r\n"
                f"Content-Length: {len(body)}\r\n\r\n").encode()
        with socket.create_connection((url.hostname, url.port), timeout=60) as conn:
            conn.sendall(head + body[:64 * 1024])  # the fields and the start of the file, no more
            answer = b""
            while b"\r\n\r\n" not in answer:
                chunk = conn.recv(4096)
                assert chunk, "the agent closed without answering"
                answer += chunk
        assert answer.startswith(b"HTTP/1.1 409")
        assert client.post("/api/job", json={"command": "cancel"}).status_code == 204


@pytest.mark.parametrize("print_", [True, False])
def test_a_file_the_intake_refuses_is_400_and_not_kept_whether_printed_or_not(demo: RunningAgent,
                                                                              print_: bool) -> None:
    with demo.client() as client:
        wait_idle(client)
        response = send(client, "comment_only.gcode", b"; only a comment\n" * 10, print_=print_)
        assert response.status_code == 400
        assert "no commands" in response.json()["error"]
        assert "comment_only.gcode" not in [f["name"] for f in client.get("/api/files").json()["files"]]
        assert not printing(client)


EMPTY_PARTS = {"bare": b"\r\n\r\n", "unnamed headers": b"A:b\r\nC:d\r\n\r\n\r\n",
               "named empty": b'Content-Disposition: form-data; name=""\r\n\r\n\r\n'}
"""Parts that carry no field: no headers at all, headers without a Content-Disposition, an empty name."""


@pytest.mark.parametrize("file_first", [False, True], ids=["parts-then-file", "file-then-parts"])
@pytest.mark.parametrize("shape", EMPTY_PARTS, ids=list(EMPTY_PARTS))
def test_a_form_of_more_parts_than_a_slicer_sends_is_400_and_nothing_is_kept(demo: RunningAgent, shape: str,
                                                                           file_first: bool) -> None:
    """FIELDS_MAX + 1 parts that are no field, before or after a valid file part: refused at the part past
    PARTS_MAX, the file not kept."""
    from fabwire.agent.doors import FIELDS_MAX, PARTS_MAX

    boundary = "B" + uuid.uuid4().hex
    name = f"manyparts_{shape.replace(' ', '_')}_{file_first}.gcode"
    empties = (f"--{boundary}\r\n".encode() + EMPTY_PARTS[shape]) * (FIELDS_MAX + 1)
    file_part = (f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="{name}"\r\n'
                 "Content-Type: application/octet-stream\r\n\r\n").encode() + prusaslicer_gcode() + b"\r\n"
    body = (file_part + empties if file_first else empties + file_part) + f"--{boundary}--\r\n".encode()
    with demo.client() as client:
        response = client.post("/api/files/local", content=body,
                               headers={"Content-Type": f"multipart/form-data; boundary={boundary}"})
        assert response.status_code == 400, response.text
        assert f"over {PARTS_MAX} parts" in response.json()["error"]
        assert name not in [f["name"] for f in client.get("/api/files").json()["files"]]


def test_a_part_with_more_header_bytes_than_the_limit_is_400(demo: RunningAgent) -> None:
    """A few long header lines in one part, each and their count within python-multipart's own limits."""
    from fabwire.agent.doors import PART_HEADERS_MAX

    boundary = "B" + uuid.uuid4().hex
    pads = b"".join(b"X-Pad-%d: " % i + b"a" * 3000 + b"\r\n" for i in range(PART_HEADERS_MAX // 3000 + 1))
    body = (f"--{boundary}\r\n".encode() + pads
            + b'Content-Disposition: form-data; name="file"; filename="padded.gcode"\r\n\r\n'
            + prusaslicer_gcode() + f"\r\n--{boundary}--\r\n".encode())
    with demo.client() as client:
        response = client.post("/api/files/local", content=body,
                               headers={"Content-Type": f"multipart/form-data; boundary={boundary}"})
        assert response.status_code == 400, response.text
        assert "bytes of headers" in response.json()["error"]
        assert "padded.gcode" not in [f["name"] for f in client.get("/api/files").json()["files"]]


def test_a_form_of_as_many_fields_as_allowed_passes(demo: RunningAgent) -> None:
    """FIELDS_MAX fields (PrusaSlicer's print and path among them) and the file: PARTS_MAX parts, accepted."""
    from fabwire.agent.doors import FIELDS_MAX

    fields = [("print", "false"), ("path", "")] + [(f"extra{i}", "x") for i in range(FIELDS_MAX - 2)]
    with demo.client() as client:
        response = send(client, "manyfields.gcode", prusaslicer_gcode(), fields=fields)
        assert response.status_code == 201, response.text
        assert client.delete("/api/files/local/manyfields.gcode").status_code == 204
