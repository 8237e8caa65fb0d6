"""Every Klipper printer object attribute the Moonraker door serves (`klipper_objects.ATTRIBUTES`), in every
print_stats state a job goes through, and every Moonraker history field (`HISTORY_FIELDS`) by job status: read
from `fabwire serve` on simulated da Vincis over HTTP and through Home Assistant's `moonraker-api` client, each
checked against what the row's rule says. The OctoPrint door names the same last job, and reports a bed without a
heater in numbers."""

from __future__ import annotations

import asyncio
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import aiohttp
import httpx
import pytest
from moonraker_api import MoonrakerClient, MoonrakerListener
from pyoctoprintapi import OctoprintClient

from fabwire.agent.doors.klipper_objects import (
    ATTRIBUTES,
    HISTORY_FIELDS,
    HISTORY_STATES,
    IDLE_TIMEOUT_S,
    MIN_EXTRUDE_TEMP_C,
    STATES,
    Attribute,
    facts,
)
from fabwire.agent.history import epoch
from fabwire.agent.model import MachineView

from .agenttools import RunningAgent, start_agent, summary, wait_for
from .doortools import multipart, prusaslicer_gcode

FILAMENT_MM, LAYERS = 43.21, 3
LONG = prusaslicer_gcode(minutes=20, seconds=2, filament_mm=FILAMENT_MM, layers=LAYERS)
SHORT = prusaslicer_gcode(minutes=1, seconds=2, filament_mm=FILAMENT_MM, layers=LAYERS)
ESTIMATES = {"long.gcode": 20 * 60 + 2, "short.gcode": 62, "interrupted.gcode": 20 * 60 + 2, "fails.gcode": 20 * 60 + 2}
OBJECTS = sorted({a.obj for a in ATTRIBUTES})
TRANSPORTS = ("http", "moonraker-api")


@dataclass
class Snapshot:
    """The objects as each transport served them in one state, with the job and the machine read around them."""

    state: str
    device: str
    filename: str
    size: int
    served: dict[str, dict[str, Any]] = field(default_factory=dict)
    """transport → status (object → attributes)."""
    jobs: list[dict[str, Any]] = field(default_factory=list)
    """The job record read before and after the queries (none on standby)."""
    machine: list[dict[str, Any]] = field(default_factory=list)
    """The machine's summary before and after."""
    octoprint_job: dict[str, Any] | None = None
    history: list[dict[str, Any]] = field(default_factory=list)


class Quiet(MoonrakerListener):  # type: ignore[misc]
    pass


async def _client_query(url: str) -> dict[str, Any]:
    host, port = urlsplit(url).hostname, urlsplit(url).port
    moon = MoonrakerClient(Quiet(), host, port)
    assert await moon.connect()
    try:
        reply = await moon.call_method("printer.objects.query", objects=dict.fromkeys(OBJECTS))
    finally:
        await moon.disconnect()
    return dict(reply["status"])


def _upload(client: httpx.Client, device: str, name: str, data: bytes) -> dict[str, Any]:
    body, ctype = multipart([("root", "gcodes"), ("print", "true")], name, data)
    response = client.post(f"/printers/{device}/server/files/upload", content=body, headers={"Content-Type": ctype})
    assert response.status_code == 201, response.text
    return dict(response.json()["result"])


def _job(client: httpx.Client, device: str) -> dict[str, Any]:
    return dict(client.get("/api/v1/jobs", params={"device": device}).json()[0])


def _state_of(client: httpx.Client, device: str) -> str:
    return str(client.get(f"/printers/{device}/printer/objects/query", params={"print_stats": "state"}).json()
               ["result"]["status"]["print_stats"]["state"])


def _snapshot(agent: RunningAgent, client: httpx.Client, device: str, state: str, filename: str, size: int,
              *, default: bool) -> Snapshot:
    snap = Snapshot(state, device, filename, size)
    if filename:
        snap.jobs.append(_job(client, device))
    snap.machine.append(summary(client, device))
    snap.served["http"] = client.get(f"/printers/{device}/printer/objects/query",
                                     params=dict.fromkeys(OBJECTS, "")).json()["result"]["status"]
    if default:  # the client speaks to the agent's default machine
        snap.served["moonraker-api"] = asyncio.run(_client_query(agent.url))
    if filename:
        snap.jobs.append(_job(client, device))
    snap.machine.append(summary(client, device))
    snap.octoprint_job = client.get(f"/printers/{device}/api/job").json()
    snap.history = client.get(f"/printers/{device}/server/history/list").json()["result"]["jobs"]
    for status in snap.served.values():
        assert status["print_stats"]["state"] == state, status
    return snap


def _acknowledge_when_done(client: httpx.Client, device: str) -> bool:
    state = summary(client, device)
    if "acknowledge" in state["actions"]:
        client.post(f"/api/v1/devices/{device}/actions/acknowledge", json={})
    return bool(state["state"] == "idle")


@pytest.fixture(scope="module")
def snapshots(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Snapshot]:
    """standby → printing → paused → (resumed) cancelled → complete (acknowledged) → a job the agent's stop
    interrupts, on one simulated mini w; an error on another whose extruder heater fails."""
    taken: dict[str, Snapshot] = {}
    state_dir = tmp_path_factory.mktemp("lifecycle") / "state"
    agent = start_agent(state_dir, "--device", "p:xyz=sim://xyz?speed=30")
    try:
        with agent.client() as client:
            wait_for(lambda: summary(client, "p")["state"] == "idle", "the printer ready")
            taken["standby"] = _snapshot(agent, client, "p", "standby", "", 0, default=True)

            _upload(client, "p", "long.gcode", LONG)
            taken["started"] = Snapshot("printing", "p", "long.gcode", len(LONG), served={"http": client.get(
                "/printers/p/printer/objects/query", params=dict.fromkeys(OBJECTS, "")).json()["result"]["status"]})
            wait_for(lambda: _job(client, "p")["progress_percent"] > 0, "the print under way")
            taken["printing"] = _snapshot(agent, client, "p", "printing", "long.gcode", len(LONG), default=True)

            assert client.post("/printers/p/printer/print/pause").status_code == 200
            wait_for(lambda: _state_of(client, "p") == "paused" and summary(client, "p")["state"] == "paused",
                     "the print paused")
            time.sleep(1.0)  # paused for a while: print_duration falls behind total_duration
            taken["paused"] = _snapshot(agent, client, "p", "paused", "long.gcode", len(LONG), default=True)

            assert client.post("/printers/p/printer/print/resume").status_code == 200
            wait_for(lambda: summary(client, "p")["state"] == "printing", "the print resumed")
            progress = _job(client, "p")["progress_percent"]
            wait_for(lambda: _job(client, "p")["progress_percent"] > progress, "the print going on")
            assert client.post("/printers/p/printer/print/cancel").status_code == 200
            wait_for(lambda: _state_of(client, "p") == "cancelled" and summary(client, "p")["state"] == "idle"
                     and _job(client, "p")["state"] == "cancelled", "the print cancelled")
            taken["cancelled"] = _snapshot(agent, client, "p", "cancelled", "long.gcode", len(LONG), default=True)

            _upload(client, "p", "short.gcode", SHORT)
            wait_for(lambda: _job(client, "p")["state"] == "done", "the short print done", 120)
            wait_for(lambda: _acknowledge_when_done(client, "p"), "the finished print taken off")
            taken["complete"] = _snapshot(agent, client, "p", "complete", "short.gcode", len(SHORT), default=True)

            _upload(client, "p", "interrupted.gcode", LONG)
            wait_for(lambda: _job(client, "p")["progress_percent"] > 0, "the next print under way")
        agent.stop()
        agent = start_agent(state_dir, "--device", "p:xyz=sim://xyz?speed=30")
        with agent.client() as client:
            interrupted = Snapshot("interrupted", "p", "interrupted.gcode", len(LONG))
            interrupted.jobs.append(_job(client, "p"))
            interrupted.history = client.get("/printers/p/server/history/list").json()["result"]["jobs"]
            taken["interrupted"] = interrupted
    finally:
        agent.stop()

    failing = start_agent(tmp_path_factory.mktemp("failing") / "state",
                          "--device", "e:xyz=sim://xyz?speed=30&fault=heater-failure")
    try:
        with failing.client() as client:
            wait_for(lambda: summary(client, "e")["state"] == "idle", "the failing printer ready")
            _upload(client, "e", "fails.gcode", LONG)
            wait_for(lambda: _state_of(client, "e") == "error" and _job(client, "e")["state"] == "failed",
                     "the print failed", 120)
            taken["error"] = _snapshot(failing, client, "e", "error", "fails.gcode", len(LONG), default=True)
    finally:
        failing.stop()
    return taken


# ------------------------------------------------------------------------------------------ what each fact must be


def _fractions(snap: Snapshot) -> tuple[float, float]:
    """The job's progress (0 … 1) before and after the queries."""
    done = [1.0 if j["state"] == "done" else j["progress_percent"] / 100 for j in snap.jobs]
    return done[0], done[-1]


def _between(value: float, low: float, high: float, slack: float = 0.0) -> bool:
    return low - slack <= value <= high + slack


def _total_ok(value: float, snap: Snapshot, status: dict[str, Any]) -> bool:
    """At least what the printer said it had printed, at most one of its minute steps past it plus the agent's
    time since (the job's record keeps both)."""
    job = snap.jobs[-1]
    until = epoch(job["finished"]) if job.get("finished") else time.time()
    if job.get("printer_elapsed") is None:  # the printer never said: the agent's time since the start
        return bool(0 < value <= until - epoch(job["started"]))
    said, since = job["printer_elapsed"]
    return bool(said <= value <= said + 60 + (until - since) and value > 0)


def _machine(snap: Snapshot, key: str) -> list[Any]:
    return [m.get(key) for m in snap.machine]


def _number_between(values: list[Any], default: float | None = None) -> Callable[[Any], bool]:
    known = [v if v is not None else default for v in values]

    def check(value: Any) -> bool:
        if any(v is None for v in known):
            return value in known
        return bool(_between(value, min(known), max(known)))

    return check


def fact_ok(fact: str, value: Any, snap: Snapshot, status: dict[str, Any]) -> bool:
    """Whether `value` is what the fact named `fact` is in this snapshot, from what the agent's own API says."""
    low, high = _fractions(snap) if snap.jobs else (0.0, 0.0)
    if fact == "state":
        return value == snap.state
    if fact == "filename":
        return value == snap.filename
    if fact == "size":
        return value == snap.size
    if fact == "fraction":
        return _between(value, low, high, 0.0001)
    if fact == "position":
        return _between(value, math.floor(low * snap.size) - 1, high * snap.size)
    if fact == "filament_used_mm":
        return _between(value, round(FILAMENT_MM * low, 2), round(FILAMENT_MM * high, 2), 0.01)
    if fact == "layers":
        return value == LAYERS
    if fact == "current_layer":
        return (value == LAYERS if snap.state == "complete" else
                _between(value, math.floor(low * LAYERS) + (low > 0), min(LAYERS, math.floor(high * LAYERS) + 1)))
    if fact == "total_s":
        return _total_ok(value, snap, status)
    if fact == "print_s":
        total = status["print_stats"]["total_duration"]
        return bool(0 < value < total) if snap.state in ("paused", "cancelled") else bool(0 < value <= total)
    if fact == "printing_s":
        return bool(0 < value <= status["print_stats"]["print_duration"])
    if fact == "estimated_s":
        return value == ESTIMATES[snap.filename]
    if fact == "error":
        return bool(value) and value in _machine(snap, "error")
    if fact == "klippy_state":
        return value == "ready"
    if fact == "klippy_message":
        return value == "Printer is ready"
    if fact == "machine_message":
        return value in _machine(snap, "state_text")
    if fact == "idle_state":
        finished = snap.jobs[-1].get("finished") if snap.jobs else None
        recent = finished is not None and time.time() - epoch(finished) < IDLE_TIMEOUT_S
        return value == ("Ready" if recent else "Idle")
    if fact == "extruder_c":
        return _number_between(_machine(snap, "extruder_temp_c"))(value)
    if fact == "extruder_target_c":
        return _number_between(_machine(snap, "extruder_target_c"), 0.0)(value)
    if fact == "can_extrude":
        return value == (status["extruder"]["temperature"] >= MIN_EXTRUDE_TEMP_C)
    if fact == "bed_c":
        return _number_between(_machine(snap, "bed_temp_c"))(value)
    if fact == "bed_target_c":
        return _number_between(_machine(snap, "bed_target_c"), 0.0)(value)
    raise AssertionError(f"no check for the fact {fact!r}")


def served_value(attribute: Attribute, status: dict[str, Any]) -> Any:
    value: Any = status[attribute.obj]
    for part in attribute.name.split("."):
        value = value[part]
    return value


def _rule_ok(rule: str, value: Any, snap: Snapshot, status: dict[str, Any]) -> bool:
    if rule.startswith("="):
        expected = json.loads(rule[1:])
        return value == expected and type(value) is type(expected)
    return fact_ok(rule, value, snap, status)


# ------------------------------------------------------------------------------------------ the tables, row by row


@pytest.mark.parametrize("transport", TRANSPORTS)
@pytest.mark.parametrize("state", STATES)
@pytest.mark.parametrize("attribute", ATTRIBUTES, ids=lambda a: f"{a.obj}.{a.name}")
def test_printer_object_attribute_in_each_state(snapshots: dict[str, Snapshot], attribute: Attribute, state: str,
                                                transport: str) -> None:
    snap = snapshots[state]
    status = snap.served[transport]
    value = served_value(attribute, status)
    rule = attribute.rules[state]
    assert _rule_ok(rule, value, snap, status), (
        f"{attribute.obj}.{attribute.name} in {state} over {transport}: {value!r} is not {rule} "
        f"({attribute.source}); job {snap.jobs[-1:]}, machine {snap.machine[-1]}")


def test_every_served_attribute_is_in_the_table(snapshots: dict[str, Snapshot]) -> None:
    """Nothing is served that the table does not describe (a nested attribute by its dotted name)."""

    def names(prefix: str, values: dict[str, Any]) -> set[str]:
        out: set[str] = set()
        for key, value in values.items():
            name = f"{prefix}.{key}" if prefix else key
            out |= names(name, value) if isinstance(value, dict) else {name}
        return out

    described = {f"{a.obj}.{a.name}" for a in ATTRIBUTES}
    for snap in snapshots.values():
        for status in snap.served.values():
            for obj, values in status.items():
                assert names(obj, values) <= described


@pytest.mark.parametrize("status", HISTORY_STATES)
@pytest.mark.parametrize("history_field", HISTORY_FIELDS, ids=lambda a: a.name)
def test_history_field_by_job_status(snapshots: dict[str, Snapshot], history_field: Attribute, status: str) -> None:
    state = {"in_progress": "printing", "completed": "complete", "cancelled": "cancelled", "error": "error",
             "interrupted": "interrupted"}[status]
    snap = snapshots[state]
    job = snap.jobs[-1]
    entry = next(e for e in snap.history if e["job_id"] == job["id"])
    value = entry[history_field.name]
    rule = history_field.rules[status]
    ended = snap.served.get("http", {}).get("print_stats", {}) if state != "printing" else {}
    meta = {"size": snap.size, "estimated_time": ESTIMATES[snap.filename], "filament_total": FILAMENT_MM,
            "layer_count": LAYERS, "slicer": "prusaslicer"}
    checks: dict[str, Callable[[Any], bool]] = {
        "job_id": lambda v: v == job["id"], "filename": lambda v: v == snap.filename, "exists": lambda v: v is True,
        "status": lambda v: v == status, "start_time": lambda v: v == pytest.approx(epoch(job["started"])),
        "end_time": lambda v: v == pytest.approx(epoch(job["finished"])),
        "metadata": lambda v: v == meta,
        # an ended job's figures are print_stats' at its end: the same numbers
        "print_s": lambda v: v == ended["print_duration"] if ended else v >= 0,
        "total_s": lambda v: v == ended["total_duration"] if ended else v >= 0,
        "filament_used_mm": lambda v: v == ended["filament_used"] if ended else v >= 0,
    }
    if rule.startswith("="):
        assert _rule_ok(rule, value, snap, {}), (history_field.name, value, rule)
    elif state == "interrupted" and rule in ("print_s", "total_s", "filament_used_mm"):
        assert value >= 0  # no print_stats to compare with: the agent stopped during the job
    else:
        assert checks[rule](value), (history_field.name, status, value, rule, history_field.source)


def test_a_print_is_printing_as_soon_as_its_upload_is_answered(snapshots: dict[str, Snapshot]) -> None:
    """Klipper's print_stats says "printing" from SDCARD_PRINT_FILE on: so does the door while the file goes to the
    machine and it heats, before the machine reports any progress."""
    status = snapshots["started"].served["http"]
    assert status["print_stats"]["state"] == "printing"
    assert status["print_stats"]["filename"] == "long.gcode"
    assert status["virtual_sdcard"]["is_active"] is True
    assert status["virtual_sdcard"]["file_size"] == len(LONG)
    assert status["idle_timeout"]["state"] == "Printing"


def test_the_cancelled_print_keeps_how_far_it_came(snapshots: dict[str, Snapshot]) -> None:
    """The job's progress, and with it the filament, stop where the print was cancelled, not at the printer's 0."""
    cancelled = snapshots["cancelled"]
    stats = cancelled.served["http"]["print_stats"]
    assert cancelled.jobs[-1]["progress_percent"] > 0
    assert stats["filament_used"] > 0
    assert stats["print_duration"] < stats["total_duration"]  # it was paused on the way
    assert stats["info"]["current_layer"] >= 1


@pytest.mark.parametrize("state", ["printing", "paused", "cancelled", "complete", "error"])
def test_the_octoprint_door_names_the_same_job(snapshots: dict[str, Snapshot], state: str) -> None:
    snap = snapshots[state]
    assert snap.octoprint_job is not None
    stats = snap.served["http"]["print_stats"]
    assert snap.octoprint_job["job"]["file"]["name"] == stats["filename"] == snap.filename
    progress = snap.octoprint_job["progress"]
    if state == "complete":  # OctoPrint's on_comm_print_job_done: completion 1.0, file position at the end
        assert progress["completion"] == 100.0
        assert progress["filepos"] == snap.size
        assert progress["printTimeLeft"] == 0
        assert snap.octoprint_job["job"]["lastPrintTime"] == stats["total_duration"]


def test_octoprint_reports_a_bed_without_heater_in_numbers(tmp_path: Path) -> None:
    """The mini w's bed has a sensor and no heater: `/api/printer` reports it as a firmware's `B:20.0 /0.0`,
    numbers as pyoctoprintapi (Home Assistant) reads them; never a null target."""
    agent = start_agent(tmp_path / "state", "--device", "p:xyz=sim://xyz?speed=30")
    try:
        with agent.client() as client:
            wait_for(lambda: summary(client, "p")["state"] == "idle", "the printer ready")
            raw = client.get("/printers/p/api/printer").json()["temperature"]
            profile = client.get("/printers/p/api/printerprofiles").json()["profiles"]["_default"]
        host, port = urlsplit(agent.url).hostname, urlsplit(agent.url).port

        async def read() -> dict[str, tuple[float, float]]:
            async with aiohttp.ClientSession() as session:
                octo = OctoprintClient(host, session, port, False, "/printers/p/")
                octo.set_api_key("unused")
                info = await octo.get_printer_info()
                return {t.name: (t.actual_temp, t.target_temp) for t in info.temperatures}

        temperatures = asyncio.run(read())
    finally:
        agent.stop()
    assert profile["heatedBed"] is False
    for name in ("tool0", "bed"):
        assert all(isinstance(raw[name][k], int | float) for k in ("actual", "target", "offset")), raw
    assert raw["bed"]["target"] == 0.0
    assert all(isinstance(v, int | float) for pair in temperatures.values() for v in pair), temperatures
    assert set(temperatures) == {"tool0", "bed"}


@pytest.mark.parametrize("attribute", [*ATTRIBUTES, *HISTORY_FIELDS], ids=lambda a: f"{a.obj}.{a.name}")
def test_every_row_names_its_source_and_a_rule_for_every_state(attribute: Attribute) -> None:
    view = MachineView(id="p", name="p", kind="xyz", model="dv1MW0A000", online=True, phase="standby",
                       message="idle", error=None, extruder_c=20.0, extruder_target_c=None, bed_c=20.0,
                       bed_target_c=None, job=None, progress_percent=None, elapsed_s=None, time_left_s=None,
                       takes_jobs=True)
    known = set(facts(view, None, "")) | {"job_id", "exists", "status", "start_time", "end_time", "metadata"}
    states = HISTORY_STATES if attribute in HISTORY_FIELDS else STATES
    assert set(attribute.rules) == set(states)
    assert "docs" in attribute.source or "Status_Reference" in attribute.source
    for rule in attribute.rules.values():
        if rule.startswith("="):
            json.loads(rule[1:])  # a literal is JSON
        else:
            assert rule in known, rule
