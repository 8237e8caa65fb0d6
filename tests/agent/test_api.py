"""The HTTP API against a running agent on real simulator processes."""

from __future__ import annotations

import json
import re
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from clitools import cli_env, run_cli
from fabwire.samples import SAMPLE_GCODE, sample_path
from fabwire.xyz.codes import PRINTING
from fabwire.xyz.models import find_model
from fabwire.xyz.threew import write_3w

from .agenttools import device_of, summary, wait_for
from .conftest import Bench, start_bench, stop_bench


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Bench]:
    """One bench for this module: each test leaves the machines usable for the next, in any order."""
    running = start_bench(Path(tmp_path_factory.mktemp("api")) / "state")
    yield running
    stop_bench(running)


def _error(response: httpx.Response, status: int, exit_code: int) -> dict[str, Any]:
    assert response.status_code == status, response.text
    body = response.json()
    assert set(body) == {"message", "exit_code", "error"}, body
    assert body["exit_code"] == exit_code, body
    assert body["message"], body
    return dict(body)


def test_devices_come_online_with_identity_and_state(bench: Bench) -> None:
    with bench.agent.client() as client:
        devices = wait_for(lambda: (d := client.get("/api/v1/devices").json()) and all(x["state"]["online"] for x in d)
                           and d, "all three devices online")
        by_kind = {d["kind"]: d for d in devices}
        assert set(by_kind) == {"xyz", "lineus", "mmu"}
        printer = by_kind["xyz"]
        assert printer["serial"]
        assert printer["id"] == f"xyz-{printer['serial'].lower()}"
        assert printer["model"] == "da Vinci mini w"
        assert printer["name"] == "printer"
        assert printer["address"] == bench.xyz.url
        state = client.get(f"/api/v1/devices/{printer['id']}/state").json()
        assert state["online"] is True
        assert state["ts"].endswith("Z")
        assert state["status"]["serial"] == printer["serial"]  # the `--json status` dict, as the CLI prints it
        assert state["summary"]["state"] in ("idle", "printing", "done")
        assert state["summary"]["extruder_temp_c"] is not None
        mmu = by_kind["mmu"]
        assert mmu["firmware"].startswith("3.0.4")
        assert summary(client, mmu["id"])["filament_position"]


def test_mmu_tool_change_through_the_api(bench: Bench) -> None:
    with bench.agent.client() as client:
        mmu = device_of(client, "mmu")
        wait_for(lambda: summary(client, mmu["id"])["state"] == "idle", "the MMU idle")
        response = client.post(f"/api/v1/devices/{mmu['id']}/actions/tool_change", json={"slot": 0})
        assert response.json() == {"started": "tool_change"}
        done = wait_for(lambda: (s := summary(client, mmu["id"]))["active_slot"] == 0 and s["state"] == "idle"
                        and "T0 finished" in s["state_text"] and s, "T0 finished")
        assert done["finda"] is True
        assert done["filament_position"] == "loaded past FINDA"
        events = client.get(f"/api/v1/devices/{mmu['id']}/history").json()["events"]
        progress = [e["event"]["name"] for e in events if e["type"] == "event" and e["event"]["event"] == "progress"]
        assert "FEEDING_TO_FINDA" in progress


def test_print_job_from_upload_to_done(bench: Bench) -> None:
    with bench.agent.client() as client:
        printer = device_of(client, "xyz")
        wait_for(lambda: summary(client, printer["id"])["state"] == "idle", "the printer idle")
        data = sample_path(SAMPLE_GCODE).read_bytes()
        response = client.post(f"/api/v1/devices/{printer['id']}/jobs", params={"filename": "square.gcode"},
                               content=data, headers={"content-type": "application/octet-stream"})
        assert response.status_code == 201, response.text
        job = response.json()
        assert job["device"] == printer["id"]
        assert job["filename"] == "square.gcode"
        assert job["size_bytes"] == len(data)
        heating = wait_for(lambda: (s := summary(client, printer["id"]))["extruder_target_c"] and s,
                           "the printer heating for the job")
        assert heating["busy"] is True
        wait_for(lambda: summary(client, printer["id"])["state"] == "printing", "the print under way")
        actions = f"/api/v1/devices/{printer['id']}/actions"
        assert client.post(f"{actions}/pause", json={}).json() == {"ok": True, "action": "pause"}
        paused = wait_for(lambda: (s := summary(client, printer["id"]))["state"] == "paused" and s, "paused")
        assert paused["actions"] == ["resume", "cancel"]
        assert client.post(f"{actions}/resume", json={}).status_code == 200
        # a second job while one runs is a conflict, with the CLI's input-error exit code
        busy = _error(client.post(f"/api/v1/devices/{printer['id']}/jobs", params={"filename": "b.gcode"},
                                  content=data), 409, 4)
        assert "is busy with job" in busy["message"]
        final = wait_for(lambda: (j := client.get(f"/api/v1/jobs/{job['id']}").json())["state"] != "running"
                         and j["state"] != "queued" and j, "the job ending", timeout=120)
        assert final["state"] == "done", final
        assert final["progress_percent"] == 100.0
        history = client.get(f"/api/v1/devices/{printer['id']}/history").json()
        temps = [s["extruder_temp_c"] for s in history["samples"] if s["extruder_temp_c"] is not None]
        assert max(temps) > min(temps) + 50  # it heated up, and the history kept the curve
        listed = client.get("/api/v1/jobs", params={"device": printer["id"]}).json()
        assert [j["id"] for j in listed] == [job["id"]]
        # the finished print waits on the bed until its owner takes it off: this module's next test finds it free
        assert summary(client, printer["id"])["actions"] == ["acknowledge"]
        assert client.post(f"/api/v1/devices/{printer['id']}/actions/acknowledge", json={}).status_code == 200
        wait_for(lambda: summary(client, printer["id"])["state"] == "idle", "the printer idle once acknowledged")


def test_errors_are_json_with_the_cli_exit_code(bench: Bench) -> None:
    with bench.agent.client() as client:
        _error(client.get("/api/v1/devices/nope/state"), 404, 4)
        mmu = device_of(client, "mmu")
        wait_for(lambda: summary(client, mmu["id"])["state"] == "idle", "the MMU idle")
        base = f"/api/v1/devices/{mmu['id']}/actions"
        assert "tool_change" in _error(client.post(f"{base}/fly", json={}), 400, 4)["message"]
        assert "0 to 4" in _error(client.post(f"{base}/tool_change", json={"slot": 7}), 400, 4)["message"]
        assert "number" in _error(client.post(f"{base}/tool_change", json={"slot": "x"}), 400, 4)["message"]
        assert "slot" in _error(client.post(f"{base}/tool_change", json={}), 400, 4)["message"]
        assert "colour" in _error(client.post(f"{base}/tool_change", json={"slot": 1, "colour": 2}), 400, 4)["message"]
        # destructive actions need the confirmation the CLI asks for
        assert "confirm" in _error(client.post(f"{base}/reset", json={}), 400, 4)["message"]
        _error(client.post("/api/v1/jobs/0000/cancel", json={"confirm": True}), 404, 4)
        _error(client.get("/api/v1/jobs", params={"limit": 0}), 422, 4)
        _error(client.get("/api/v1/no-such-route"), 404, 4)
        printer = device_of(client, "xyz")
        assert ".gcode" in _error(client.post(f"/api/v1/devices/{printer['id']}/jobs",
                                              params={"filename": "x.exe"}, content=b"G28\n"), 400, 4)["message"]


def test_openapi_documents_every_route(bench: Bench) -> None:
    with bench.agent.client() as client:
        spec = client.get("/api/v1/openapi.json").json()
    paths = spec["paths"]
    for path in ("/api/v1/devices", "/api/v1/devices/{device_id}/state", "/api/v1/devices/{device_id}/history",
                 "/api/v1/devices/{device_id}/actions/{action}", "/api/v1/devices/{device_id}/jobs",
                 "/api/v1/jobs", "/api/v1/jobs/{job_id}/cancel"):
        assert path in paths, path
    upload = paths["/api/v1/devices/{device_id}/jobs"]["post"]
    assert "application/octet-stream" in upload["requestBody"]["content"]
    assert "ErrorBody" in spec["components"]["schemas"]


def test_devices_added_and_removed_at_run_time(bench: Bench, simulator: Any) -> None:
    second = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "30")
    with bench.agent.client() as client:
        first = device_of(client, "xyz")
        response = client.post("/api/v1/devices", json={"name": "second", "kind": "xyz", "address": second.url})
        assert response.status_code == 201, response.text
        added = response.json()
        # both simulators report one serial number: the second is told apart by its address
        assert added["id"] != first["id"]
        assert added["id"].startswith("xyz-")
        assert added["serial"] == first["serial"]
        ids = [d["id"] for d in client.get("/api/v1/devices").json()]
        assert len(ids) == len(set(ids)) == 4
        _error(client.post("/api/v1/devices", json={"name": "again", "kind": "xyz", "address": second.url}), 400, 4)
        _error(client.post("/api/v1/devices", json={"name": "bad name!", "kind": "xyz", "address": "x"}), 422, 4)
        for path in ("/etc/passwd", "serial:///dev/../etc/shadow", "/dev/sda", "/dev/ttyS0/../../etc/passwd"):
            refused = _error(client.post("/api/v1/devices", json={"name": "p", "kind": "xyz", "address": path}),
                             400, 4)
            assert "not a serial port" in refused["message"]
        for address in ("sim://xyz?state=/tmp/agent-state.json", "sim://xyz?store=/tmp/agent-store",
                        "sim://xyz?speed=5&store=/etc"):
            refused = _error(client.post("/api/v1/devices", json={"name": "p", "kind": "xyz", "address": address}),
                             400, 4)
            assert "takes no file or folder" in refused["message"]
        assert not Path("/tmp/agent-store").exists()
        _error(client.post("/api/v1/devices", json={"name": "p", "kind": "mmu", "address": second.url,
                                                     "options": {"sped": 3}}), 400, 4)
        assert client.delete(f"/api/v1/devices/{added['id']}").status_code == 204
        assert len(client.get("/api/v1/devices").json()) == 3


def test_cancelling_a_job_needs_confirmation(bench: Bench) -> None:
    with bench.agent.client() as client:
        arm = device_of(client, "lineus")
        wait_for(lambda: summary(client, arm["id"])["state"] == "idle", "the Line-us idle")
        job = client.post(f"/api/v1/devices/{arm['id']}/actions/text",
                          json={"text": "a longer line to cancel"}).json()["job"]
        wait_for(lambda: summary(client, arm["id"])["state"] == "drawing", "the drawing under way")
        assert "busy" in _error(client.post(f"/api/v1/devices/{arm['id']}/actions/text", json={"text": "more"}),
                                409, 4)["message"]
        assert "confirm" in _error(client.post(f"/api/v1/jobs/{job['id']}/cancel", json={}), 400, 4)["message"]
        for loose in ("yes", 1, "true"):  # only JSON true confirms
            assert "confirm" in _error(client.post(f"/api/v1/jobs/{job['id']}/cancel", json={"confirm": loose}),
                                       422, 4)["message"]
        assert client.get(f"/api/v1/jobs/{job['id']}").json()["state"] == "running"
        wait_for(lambda: 0 < next(j for j in client.get("/api/v1/jobs").json()
                                  if j["id"] == job["id"])["progress_percent"] < 100,
                 "the job list following the drawing's progress")
        cancelled = client.post(f"/api/v1/jobs/{job['id']}/cancel", json={"confirm": True})
        assert cancelled.json()["state"] == "cancelled", cancelled.text
        record = client.get(f"/api/v1/jobs/{job['id']}").json()
        assert record["state"] == "cancelled"
        assert record["progress_percent"] < 100
        idle = wait_for(lambda: (s := summary(client, arm["id"]))["state"] == "idle" and s, "the Line-us idle again")
        assert idle["pen_down"] is False  # the pen was lifted
        assert "not running" in _error(client.post(f"/api/v1/jobs/{job['id']}/cancel", json={"confirm": True}),
                                       400, 4)["message"]


def test_cancelling_a_print_stops_the_printer(bench: Bench) -> None:
    with bench.agent.client() as client:
        printer = device_of(client, "xyz")
        actions = f"/api/v1/devices/{printer['id']}/actions"
        if summary(client, printer["id"])["state"] == "done":  # a finished print waits to be taken off the bed
            assert client.post(f"{actions}/acknowledge", json={}).status_code == 200
        wait_for(lambda: summary(client, printer["id"])["state"] == "idle", "the printer idle")
        job = client.post(f"/api/v1/devices/{printer['id']}/jobs", params={"filename": "square.g"},
                          content=sample_path(SAMPLE_GCODE).read_bytes()).json()
        wait_for(lambda: summary(client, printer["id"])["state"] == "printing", "the print under way")
        assert "confirm" in _error(client.post(f"{actions}/cancel", json={}), 400, 4)["message"]
        cancelled = client.post(f"{actions}/cancel", json={"confirm": True})
        assert cancelled.status_code == 200, cancelled.text
        assert cancelled.json()["id"] == job["id"]
        assert client.get(f"/api/v1/jobs/{job['id']}").json()["state"] == "cancelled"
        wait_for(lambda: summary(client, printer["id"])["state"] == "idle", "the printer idle after cancelling")


DAMAGED_3W = bytes(b ^ (i == 9000) for i, b in enumerate(write_3w(b"G28\nG1 X10 Y10 E1\n" * 50,
                                                                  find_model("dv1MW0A000"), filename="part.3w")))


@pytest.mark.parametrize(("name", "data", "says"), [
    ("part.gcode", bytes(range(256)) * 8, "binary data"),
    ("part.gcode", b"; only a comment\n", "no commands"),
    ("part.gcode", b"G28\n" + b"G1 X1" * 300_000 + b"\nG28\n", "has a line of over"),
    ("part.3w", b"<svg xmlns='http://www.w3.org/2000/svg'/>", "SVG"),
    ("a.svg", b"not svg", "a.svg"),
    ("a.svg", b"<svg xmlns='http://www.w3.org/2000/svg' width='10' height='10'></svg>", "nothing to draw"),
    ("a.gcode", b"\xff\xfe\x00garbage", "a.gcode"),
    ("a.svg", b"<svg xmlns='http://www.w3.org/2000/svg' width='10' height='10'><path d='M1 1 L1e308 5' "
              b"stroke='black'/></svg>", "beyond what a browser can hold"),
    ("part.gcode", b"G28\nG1 X10 Y10 E1 F1200\nG1 Z" + b"9" * 40 + b"\n", "not a print file"),
    ("part.3w", DAMAGED_3W, "is damaged"),
    ("square.3w", write_3w(b"G28\nG1 X10 Y10 E1\n" * 50, find_model("miniMaker"), filename="square.3w"),
     "square.3w is a .3w for da Vinci miniMaker"),  # another model's file: refused as `xyz print` refuses it
])
def test_an_upload_no_intake_takes_is_refused_before_it_is_accepted(bench: Bench, name: str, data: bytes,
                                                                      says: str) -> None:
    with bench.agent.client() as client:
        kind = "lineus" if name.startswith("a.") else "xyz"
        device = wait_for(lambda: (d := device_of(client, kind))["state"]["online"] and d, f"the {kind} online")
        body = _error(client.post(f"/api/v1/devices/{device['id']}/jobs", params={"filename": name}, content=data,
                                  headers={"content-type": "application/octet-stream"}), 400, 4)
        assert says in body["message"], body
        assert name in body["message"], body
        assert "uploads" not in body["message"], body
        assert not re.search(r"(^|\s)/\w", body["message"]), body  # no path on the server
        assert not [j for j in client.get("/api/v1/jobs", params={"device": device["id"]}).json()
                    if j["filename"] == name and j["state"] == "failed"]


def test_an_upload_whose_content_type_is_a_list_is_refused_and_nothing_is_kept(bench: Bench) -> None:
    """Over a real socket: `text/plain,application/octet-stream` is no media type (a browser's Fetch would not
    send it): 415 before the body is read, no job."""
    with bench.agent.client() as client:
        before = client.get("/api/v1/jobs").json()
        for value in ("text/plain,application/octet-stream", "application/octet-stream, text/plain"):
            body = _error(client.post("/api/v1/devices/printer/jobs", params={"filename": "a.gcode"},
                                      content=b"G28\n", headers={"content-type": value}), 415, 4)
            assert body["message"] == f"Content-Type {value!r} is not one media type such as application/octet-stream"
        assert client.get("/api/v1/jobs").json() == before


def test_devices_answer_to_their_configured_name(bench: Bench) -> None:
    with bench.agent.client() as client:
        wait_for(lambda: device_of(client, "lineus")["state"]["online"], "the Line-us online")
        by_name = client.get("/api/v1/devices/printer").json()
        assert by_name["id"] == device_of(client, "xyz")["id"]
        assert client.get("/api/v1/devices/arm/state").json()["online"] is True
        assert client.get("/api/v1/devices/arm/history").json()["device"] == device_of(client, "lineus")["id"]
        assert "pen_up" in client.get("/api/v1/devices/arm/actions").json()["applicable"]
        assert _error(client.post("/api/v1/devices/arm/jobs", params={"filename": "a.exe"}, content=b"x"),
                      400, 4)["message"] == "arm takes .gc, .gcode, .nc, .ngc, .svg, .svgz files, not 'a.exe'"
        assert _error(client.post("/api/v1/devices/printer/jobs", params={"filename": "logo.svg"},
                                  content=b"<svg/>"), 400, 4)["message"] == \
            "printer takes .3w, .g, .gco, .gcode files, not 'logo.svg'"
        unknown = _error(client.get("/api/v1/devices/desk"), 404, 4)["message"]
        assert "printer" in unknown
        assert "arm" in unknown


def test_an_action_body_that_is_not_json_is_refused_with_the_fix(bench: Bench) -> None:
    """curl's default form encoding is never read as JSON (a browser form could send it cross-site): 415 with
    the header to send; a JSON body then names an unknown action."""
    with bench.agent.client() as client:
        mmu = wait_for(lambda: (d := device_of(client, "mmu"))["state"]["online"] and d, "the MMU online")
        base = f"/api/v1/devices/{mmu['id']}/actions"
        form = {"content-type": "application/x-www-form-urlencoded"}
        for action, body in (("bogus", b"{}"), ("bogus", b"slot=1"), ("tool_change", b"slot=1")):
            message = _error(client.post(f"{base}/{action}", content=body, headers=form), 415, 4)["message"]
            assert "Content-Type: application/json" in message
        assert "no action 'bogus'" in _error(client.post(f"{base}/bogus", json={}), 400, 4)["message"]
        assert "object" in _error(client.post(f"{base}/tool_change", json=[1]), 400, 4)["message"]


def test_a_print_cancelled_while_its_file_is_still_sent_never_runs(bench: Bench) -> None:
    """Cancelled during the upload to the printer, when there is no print to stop yet: the print that file would
    start is stopped too, and the job says cancelled only when the printer is not printing."""
    moves = b"".join(b"G1 X%.3f Y%.3f E%.5f\n" % (30 + i % 100 * 0.1, 30 + (i // 100) % 100 * 0.1, i * 0.001)
                     for i in range(150_000))
    with bench.agent.client() as client:
        printer = device_of(client, "xyz")
        if summary(client, printer["id"])["state"] == "done":
            assert client.post(f"/api/v1/devices/{printer['id']}/actions/acknowledge", json={}).status_code == 200
        wait_for(lambda: summary(client, printer["id"])["state"] == "idle", "the printer idle")
        job = client.post(f"/api/v1/devices/{printer['id']}/jobs", params={"filename": "long.gcode"},
                          content=b"G28\nG1 Z0.2 F600\n" + moves).json()
        cancelled = client.post(f"/api/v1/jobs/{job['id']}/cancel", json={"confirm": True}, timeout=120)
        assert cancelled.status_code == 200, cancelled.text
        assert cancelled.json()["state"] == "cancelled"
        wait_for(lambda: summary(client, printer["id"])["state"] == "idle", "the printer idle after cancelling")
        states = []
        for _ in range(6):  # a print started after the cancel would show on the printer itself
            said = run_cli("--json", "xyz", "-d", bench.xyz.url, "status", env=cli_env())
            assert said.returncode == 0, said.stderr
            states.append(json.loads(said.stdout)["state"])
            time.sleep(0.5)
        assert PRINTING not in states, states
        assert not any(9500 <= state <= 9508 for state in states), states
