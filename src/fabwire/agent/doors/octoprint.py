"""The OctoPrint-compatible door: what slicers' "send to printer", Home Assistant's OctoPrint integration and
OctoPrint apps call (field meanings from docs.octoprint.org, REST API: version, server, settings, connection,
printer, job, files, login, printer profiles; the Application Keys plugin).

A translation of `MachineView`, the library and the agent's jobs; nothing here decides anything. What a machine
cannot do (set a temperature, take raw G-code, slice) answers 409 with the reason, as does a job that cannot
start now.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import json
import uuid
from collections.abc import Awaitable, Callable
from typing import Any
from urllib.parse import quote

from fastapi import FastAPI, Request
from fastapi.responses import FileResponse, JSONResponse, Response

from fabwire import __version__
from fabwire.agent.appkeys import AppKeys
from fabwire.agent.boundary import connection_headers
from fabwire.agent.core import Agent
from fabwire.agent.doors import (
    JSON_BODY,
    MULTIPART_BODY,
    PREFIXES,
    base_url,
    door_router,
    file_name_of,
    machine_of,
    read_upload,
)
from fabwire.agent.model import MachineView
from fabwire.agent.offload import while_connected
from fabwire.agent.session import JobClaim
from fabwire.errors import FabwireError, InputError

OCTOPRINT_VERSION = "1.10.0"
"""The OctoPrint release whose API this door follows."""
API_VERSION = "0.1"
TRUE = frozenset({"true", "yes", "y", "1", "on"})
"""Form values OctoPrint reads as true (octoprint.server.api: valid_boolean_trues)."""
UUID_NAMESPACE = uuid.UUID("5a3f6f7e-4b8d-4c1e-9a57-6661627769c0")

STATE_TEXT: dict[str, str] = {
    "standby": "Operational", "printing": "Printing", "pausing": "Pausing", "paused": "Paused",
    "resuming": "Resuming", "cancelling": "Cancelling", "done": "Operational", "busy": "Operational",
    "error": "Error", "offline": "Offline",
}
"""Phase → OctoPrint's state string (octoprint.printer.standard: get_state_string)."""

CANNOT: dict[str, str] = {
    "tool": "a da Vinci heats its nozzle as the print file says: it takes no temperature commands",
    "bed": "a da Vinci heats its bed as the print file says: it takes no temperature commands",
    "chamber": "none of these machines has a heated chamber",
    "command": "these machines take whole files, not raw G-code commands: upload a file and print it",
    "sd": "the machine's own storage is not reachable here: upload to local",
    "slice": "fabwire does not slice: slice in your slicer and send the G-code",
    "connection": "the agent keeps the connection to each machine itself (and reconnects after a drop)",
    "restart": "a da Vinci cannot restart a print from the beginning: cancel it and start the file again",
    "folder": "the library keeps files, not empty folders: upload a file with its path instead",
}
"""What OctoPrint offers that these machines or this door cannot do, in words (HTTP 409)."""


def unique_id(view: MachineView) -> str:
    """The machine's stable UUID (OctoPrint's `plugins.discovery.upnpUuid`, Home Assistant's unique id): derived
    from the agent's device id, which is unique across agents and stable across restarts."""
    return str(uuid.uuid5(UUID_NAMESPACE, view.id))


def _error(status: int, message: str) -> JSONResponse:
    return JSONResponse({"error": message, "message": message}, status_code=status,
                        headers=connection_headers(status))


def _true(value: object) -> bool:
    return isinstance(value, str) and value.strip().lower() in TRUE


async def _json(request: Request) -> dict[str, Any]:
    raw = await request.body()
    try:
        body = json.loads(raw) if raw.strip() else {}
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise InputError("send the command as JSON, e.g. {\"command\": \"pause\", \"action\": \"pause\"}") from None
    if not isinstance(body, dict):
        raise InputError("the body must be a JSON object such as {\"command\": \"start\"}")
    return body


class OctoPrintDoor:
    def __init__(self, agent: Agent, appkeys: AppKeys) -> None:
        self.agent = agent
        self.library = agent.library
        self.appkeys = appkeys
        self._background: set[asyncio.Task[Any]] = set()

    # ------------------------------------------------------------------------------------------ server

    async def version(self, request: Request) -> dict[str, Any]:
        return {"api": API_VERSION, "server": OCTOPRINT_VERSION,
                "text": f"OctoPrint {OCTOPRINT_VERSION} (fabwire {__version__})"}

    async def server(self, request: Request) -> dict[str, Any]:
        return {"version": OCTOPRINT_VERSION, "safemode": None}

    async def settings(self, request: Request) -> dict[str, Any]:
        view = machine_of(self.agent, request)
        return {"api": {"allowCrossOrigin": False}, "appearance": {"name": view.name},
                "feature": {"sdSupport": False, "gcodeViewer": False},
                "folder": {}, "gcodeAnalysis": {"runAt": "never"},
                "plugins": {"discovery": {"upnpUuid": unique_id(view), "publicHost": None, "publicPort": None,
                                          "httpUsername": None, "httpPassword": None}}}

    async def login(self, request: Request) -> dict[str, Any]:
        return {"name": "owner", "active": True, "admin": True, "user": True, "groups": ["admins"],
                "permissions": [], "needs": {}}

    async def currentuser(self, request: Request) -> dict[str, Any]:
        return {"name": "owner", "permissions": [], "groups": ["admins"]}

    async def connection(self, request: Request) -> dict[str, Any]:
        view = machine_of(self.agent, request)
        port = self.agent.session(view.id).spec.address
        return {"current": {"state": STATE_TEXT[view.phase] if view.online else "Closed", "port": port,
                            "baudrate": None, "printerProfile": "_default"},
                "options": {"ports": [port], "baudrates": [], "printerProfiles": [
                    {"id": "_default", "name": view.model or view.name}], "portPreference": port,
                    "baudratePreference": None, "printerProfilePreference": "_default", "autoconnect": True}}

    async def connection_command(self, request: Request) -> Response:
        view = machine_of(self.agent, request)
        command = (await _json(request)).get("command")
        if command == "connect" and view.online:
            return Response(status_code=204)
        if command == "connect":
            return _error(409, f"{view.name} is offline ({view.message}); {CANNOT['connection']}")
        return _error(409, CANNOT["connection"])

    async def printer_profiles(self, request: Request) -> dict[str, Any]:
        view = machine_of(self.agent, request)
        axes = {axis: {"speed": 6000 if axis != "e" else 300, "inverted": False} for axis in "xyze"}
        return {"profiles": {"_default": {
            "id": "_default", "name": view.name, "model": view.model or view.kind, "current": True, "default": True,
            "heatedBed": _heated_bed(view), "heatedChamber": False,
            "extruder": {"count": 1 if view.kind == "xyz" else 0}, "axes": axes,
            "resource": f"{base_url(request)}/api/printerprofiles/_default"}}}

    # ------------------------------------------------------------------------------------------ printer

    def _temperatures(self, view: MachineView) -> dict[str, Any]:
        """OctoPrint's temperature data: a heater is there only when the firmware reports its temperature
        (`comm.py` parses `T:`/`B:` from M105; `get_current_temperatures` leaves out what was never reported),
        always numbers: a sensor without a heater (the mini w's bed) reads `B:actual /0.0`."""
        temps: dict[str, Any] = {}
        for key, actual, target in (("tool0", view.extruder_c, view.extruder_target_c),
                                    ("bed", view.bed_c, view.bed_target_c)):
            if actual is not None:
                temps[key] = {"actual": actual, "target": target if target is not None else 0.0, "offset": 0}
        return temps

    @staticmethod
    def _state(view: MachineView) -> dict[str, Any]:
        phase = view.phase
        operational = phase not in ("offline", "error")
        flags = {"operational": operational, "printing": phase == "printing", "cancelling": phase == "cancelling",
                 "pausing": phase == "pausing", "resuming": phase == "resuming", "finishing": False,
                 "closedOrError": not operational, "error": phase == "error", "paused": phase == "paused",
                 "ready": operational and view.refusal() is None, "sdReady": False}
        text = STATE_TEXT[phase]
        if phase == "error" and view.error:
            text = f"Error: {view.error}"
        return {"text": text, "flags": flags, "error": view.error or ""}

    async def printer(self, request: Request) -> Response:
        view = machine_of(self.agent, request)
        if not view.online:  # OctoPrint: 409 when the printer is not operational
            return _error(409, f"Printer is not operational: {view.name} is offline ({view.message})")
        return JSONResponse({"temperature": self._temperatures(view), "sd": {"ready": False},
                             "state": self._state(view)})

    async def printer_part(self, request: Request) -> Response:
        """GET /api/printer/tool and /bed: the temperatures of that part."""
        view = machine_of(self.agent, request)
        part = request.url.path.rstrip("/").rsplit("/", 1)[-1]
        temps = self._temperatures(view)
        wanted = {k: v for k, v in temps.items() if (k.startswith("tool") if part == "tool" else k == part)}
        return JSONResponse(wanted)

    async def cannot(self, request: Request) -> Response:
        """409 with the reason for what these machines cannot do (the last path part names it)."""
        machine_of(self.agent, request)  # an unknown machine is still a 404
        part = request.url.path.rstrip("/").rsplit("/", 1)[-1]
        return _error(409, CANNOT.get(part, CANNOT["command"]))

    async def printhead(self, request: Request) -> Response:
        view = machine_of(self.agent, request)
        body = await _json(request)
        command = body.get("command")
        applicable = self._applicable(view)
        if command == "home" and "home" in applicable:
            await self.agent.act(view.id, "home", {})
            return Response(status_code=204)
        if command == "jog" and "jog" in applicable:
            moves = [(axis, body[axis]) for axis in "xyz" if axis in body]
            if not moves or body.get("absolute"):
                return _error(400, "jog takes relative distances: {\"command\": \"jog\", \"x\": 10}")
            for axis, distance in moves:
                await self.agent.act(view.id, "jog", {"axis": axis, "distance_mm": distance})
            return Response(status_code=204)
        return _error(409, f"{view.name} cannot {command or 'do that'} now (it is {view.phase})")

    def _applicable(self, view: MachineView) -> list[str]:
        return list((self.agent.state(view.id).get("summary") or {}).get("actions") or [])

    # ------------------------------------------------------------------------------------------ job

    def _file_ref(self, request: Request, view: MachineView, entry: dict[str, Any] | None,
                  job: dict[str, Any] | None = None) -> dict[str, Any]:
        if entry is None and job is None:
            return {"name": None, "path": None, "display": None, "size": None, "origin": None, "date": None}
        if entry is None:
            assert job is not None
            return {"name": job.get("filename"), "path": job.get("filename"), "display": job.get("filename"),
                    "size": job.get("size_bytes"), "origin": "local", "date": None}
        return {"name": entry["name"].rsplit("/", 1)[-1], "path": entry["name"],
                "display": entry["name"].rsplit("/", 1)[-1], "size": entry["size"], "origin": "local",
                "date": int(entry["uploaded"])}

    async def job(self, request: Request) -> dict[str, Any]:
        """GET /api/job: the running job, else the last one (as the Moonraker door's print_stats), else the
        selected file; a finished print shows completion 100 with its time, as OctoPrint's
        `on_comm_print_job_done` leaves it."""
        view = machine_of(self.agent, request)
        job = view.shown_job
        entry = self.library.file_of_job(job)
        if view.job is None and view.takes_jobs:
            selected = self.library.selected(view.id)
            if selected and (entry is None or entry["name"] != selected):  # chosen since the last job
                entry, job = self.library.get(view.id, selected), None
        figures = view.figures() if job is not None or view.printing else None
        meta = (entry or {}).get("meta") or (job or {}).get("file_meta") or {}
        length = meta.get("filament_mm")
        active = view.job is not None or view.printing
        done = not active and figures is not None and figures.state == "done"
        shown = figures is not None and (active or done)
        left = view.time_left_s if active else 0 if done else None
        body: dict[str, Any] = {
            "job": {"file": self._file_ref(request, view, entry, job),
                    "estimatedPrintTime": meta.get("print_time_s"),
                    "lastPrintTime": figures.total_s if done and figures else None,
                    "filament": {"tool0": {"length": length, "volume": None}} if length is not None else None,
                    "user": None},
            "progress": {"completion": round(figures.fraction * 100, 2) if shown and figures else None,
                         "filepos": figures.position if shown and figures and figures.size else None,
                         "printTime": int(figures.total_s) if shown and figures else None,
                         "printTimeLeft": int(left) if left is not None else None,
                         "printTimeLeftOrigin": "estimate" if active and left is not None else None},
            "state": STATE_TEXT[view.phase]}
        if view.phase == "error":
            body["error"] = view.error or view.message
        return body

    async def job_command(self, request: Request) -> Response:
        view = machine_of(self.agent, request)
        body = await _json(request)
        command = body.get("command")
        if command == "start":
            selected = self.library.selected(view.id) if view.takes_jobs else None
            if selected is None:
                return _error(409, f"no file is selected on {view.name}: select one first (or upload with "
                                   "print=true)")
            await self.library.start_print(view.id, selected)
            return Response(status_code=204)
        if command == "restart":
            return _error(409, CANNOT["restart"])
        if command == "cancel":
            return await self._cancel(view)
        if command == "pause":
            return await self._pause(view, body.get("action", "toggle"))
        return _error(400, f"unknown job command {command!r}: start, cancel, pause, restart")

    async def _cancel(self, view: MachineView) -> Response:
        if not view.printing and view.job is None:
            return _error(409, f"{view.name} is not printing: there is nothing to cancel")
        if "cancel" not in self._applicable(view) and view.job is None:
            return _error(409, f"{view.name} cannot cancel now (it is {view.phase})")
        self.library.machines.requested(view.id, "cancelling")
        job = view.job
        if job is not None:
            work = self.agent.cancel_job(job["id"], confirm=True)
        else:
            work = self.agent.act(view.id, "cancel", {"confirm": True})
        task = asyncio.ensure_future(work)  # the machine takes its time to stop; its end arrives as events
        self._background.add(task)
        task.add_done_callback(self._background.discard)
        with contextlib.suppress(TimeoutError, asyncio.TimeoutError):
            await asyncio.wait_for(asyncio.shield(task), 2.0)
        return Response(status_code=204)

    async def _pause(self, view: MachineView, action: object) -> Response:
        if action not in ("pause", "resume", "toggle"):
            return _error(400, f"pause takes the action pause, resume or toggle, not {action!r}")
        if action == "toggle":
            action = "resume" if view.phase == "paused" else "pause"
        applicable = self._applicable(view)
        if (action, view.phase) in (("pause", "paused"), ("resume", "printing")):
            return Response(status_code=204)  # already so
        if action not in applicable:
            return _error(409, f"{view.name} cannot {action} now (it is {view.phase})")
        await self.agent.act(view.id, str(action), {})
        self.library.machines.requested(view.id, "pausing" if action == "pause" else "resuming")
        return Response(status_code=204)

    # ------------------------------------------------------------------------------------------ files

    def _entry(self, request: Request, view: MachineView, entry: dict[str, Any]) -> dict[str, Any]:
        base = base_url(request)
        path = quote(entry["name"])
        meta = entry["meta"]
        item: dict[str, Any] = {
            "name": entry["name"].rsplit("/", 1)[-1], "display": entry["name"].rsplit("/", 1)[-1],
            "path": entry["name"], "type": "machinecode", "typePath": ["machinecode", "gcode"],
            "origin": "local", "size": entry["size"], "date": int(entry["uploaded"]), "hash": entry["sha256"],
            "refs": {"resource": f"{base}/api/files/local/{path}", "download": f"{base}/downloads/files/local/{path}"},
            "gcodeAnalysis": {"estimatedPrintTime": meta.get("print_time_s"),
                              "filament": {"tool0": {"length": meta.get("filament_mm"), "volume": None}}},
            "prints": entry["prints"],
        }
        if entry["thumbnails"]:  # as the PrusaSlicer Thumbnails plugin adds it: a path relative to the base
            item["thumbnail"] = f"plugin/prusaslicerthumbnails/thumbnail/{path}"
            item["thumbnail_src"] = "prusaslicerthumbnails"
        return item

    async def files(self, request: Request) -> dict[str, Any]:
        view = machine_of(self.agent, request)
        entries = self.library.files(view.id) if view.takes_jobs else []
        free, total = self.library.disk()
        return {"files": [self._entry(request, view, e) for e in entries], "free": free, "total": total}

    async def sdcard_files(self, request: Request) -> dict[str, Any]:
        machine_of(self.agent, request)
        return {"files": [], "free": 0, "total": 0}

    async def file_info(self, request: Request, path: str) -> dict[str, Any]:
        view = machine_of(self.agent, request)
        return self._entry(request, view, self.library.get(view.id, path))

    async def upload(self, request: Request) -> Response:
        """POST /api/files/local: multipart `file`, `path` (its folder), `select`, `print` ("true"). With print
        sent before the file (PrusaSlicer, OrcaSlicer), the machine is claimed before the file is read."""
        view = machine_of(self.agent, request)
        view.require_files()
        claims: list[JobClaim] = []
        sinks: list[Callable[[bytes], Awaitable[None]]] = []

        def before_file(fields: dict[str, str], filename: str) -> None:
            if _true(fields.get("print")):
                claim = self.library.claim_print(view.id, f"{fields.get('path', '')}/{filename}")
                if claim is not None:
                    claims.append(claim)
                    sinks.append(claim.write)  # the job's copy is written as the file arrives

        try:
            form = await read_upload(request, self.agent.jobs.max_upload_bytes, before_file,
                                     self.library.staging(view.id), sinks)
            try:
                fields = form.fields
                if form.file is None:
                    if fields.get("foldername"):
                        return _error(409, CANNOT["folder"])
                    return _error(400, "send the file as the multipart field 'file'")
                start = _true(fields.get("print"))
                select = start or _true(fields.get("select"))
                name = f"{fields.get('path', '')}/{file_name_of(form.filename)}"
                result = await while_connected(request, self.library.add(  # dropped if the slicer hangs up
                    view.id, name, form.adopt(), start=start, select=select, claim=claims[0] if claims else None,
                    claim_fed=bool(claims)))
            finally:
                form.close()
        finally:
            for claim in claims:
                claim.release()
        entry = result["file"]
        item = self._entry(request, view, entry)
        body = {"files": {"local": {"name": item["name"], "display": item["display"], "path": item["path"],
                                    "origin": "local", "refs": item["refs"]}},
                "done": True, "effectiveSelect": select, "effectivePrint": result["job"] is not None,
                "queued": result["queued"]}
        return JSONResponse(body, status_code=201, headers={"Location": item["refs"]["resource"]})

    async def file_command(self, request: Request, path: str) -> Response:
        view = machine_of(self.agent, request)
        entry = self.library.get(view.id, path)
        body = await _json(request)
        command = body.get("command")
        if command == "select":
            if body.get("print") is True:
                await self.library.start_print(view.id, entry["name"])
            else:
                await self.library.select(view.id, entry["name"])
            return Response(status_code=204)
        if command == "unselect":
            await self.library.select(view.id, None)
            return Response(status_code=204)
        if command == "analyse":
            return Response(status_code=204)  # analysed when it was uploaded
        if command == "slice":
            return _error(409, CANNOT["slice"])
        return _error(409, f"this library does not {command or 'do that'}: it keeps, prints and deletes files")

    async def delete(self, request: Request, path: str) -> Response:
        view = machine_of(self.agent, request)
        await self.library.delete(view.id, path)
        return Response(status_code=204)

    async def download(self, request: Request, path: str) -> Response:
        view = machine_of(self.agent, request)
        entry = self.library.get(view.id, path)
        return FileResponse(str(self.library.path_of(view.id, entry)), media_type="text/x.gcode",
                            filename=entry["name"].rsplit("/", 1)[-1])

    async def thumbnail(self, request: Request, path: str) -> Response:
        view = machine_of(self.agent, request)
        image, media = self.library.thumbnail(view.id, path)
        return Response(image, media_type=media, headers={"cache-control": "no-cache"})

    # ------------------------------------------------------------------------------------------ app keys

    async def appkeys_probe(self, request: Request) -> Response:
        return Response(status_code=204)

    async def appkeys_request(self, request: Request) -> Response:
        body = await _json(request)
        client = request.client.host if request.client else "?"
        key_request = self.appkeys.request(body.get("app"), body.get("user"), client)
        poll = f"{base_url(request)}/plugin/appkeys/request/{key_request.token}"
        return JSONResponse({"app_token": key_request.token, "auth_dialog": str(request.base_url)},
                            status_code=201, headers={"Location": poll})

    async def appkeys_poll(self, request: Request, app_token: str) -> Response:
        status, body = self.appkeys.poll(app_token)
        return JSONResponse(body, status_code=status)


def _heated_bed(view: MachineView) -> bool:
    """Whether the machine's bed heats: a da Vinci's from its model's row (`fabwire.xyz.models`, the vendor's
    specifications: the mini w reports a bed temperature but has no heater); other kinds have no bed."""
    if view.kind != "xyz" or view.model is None:
        return False
    from fabwire.xyz.models import find_model

    try:
        return find_model(view.model).heated_bed
    except InputError:  # a model fabwire does not know: a bed that reports a target heats
        return view.bed_target_c is not None


def mount(app: FastAPI, agent: Agent, appkeys: AppKeys) -> None:
    """Add the OctoPrint-compatible routes, for the default machine and under `/printers/NAME`."""
    door = OctoPrintDoor(agent, appkeys)
    routes: list[tuple[str, Any, list[str]]] = [
        ("/api/version", door.version, ["GET"]),
        ("/api/server", door.server, ["GET"]),
        ("/api/settings", door.settings, ["GET"]),
        ("/api/login", door.login, ["POST"]),
        ("/api/currentuser", door.currentuser, ["GET"]),
        ("/api/connection", door.connection, ["GET"]),
        ("/api/connection", door.connection_command, ["POST"]),
        ("/api/printerprofiles", door.printer_profiles, ["GET"]),
        ("/api/printer", door.printer, ["GET"]),
        ("/api/printer/tool", door.printer_part, ["GET"]),
        ("/api/printer/bed", door.printer_part, ["GET"]),
        ("/api/printer/tool", door.cannot, ["POST"]),
        ("/api/printer/bed", door.cannot, ["POST"]),
        ("/api/printer/chamber", door.cannot, ["GET", "POST"]),
        ("/api/printer/command", door.cannot, ["POST"]),
        ("/api/printer/sd", door.cannot, ["GET", "POST"]),
        ("/api/printer/printhead", door.printhead, ["POST"]),
        ("/api/job", door.job, ["GET"]),
        ("/api/job", door.job_command, ["POST"]),
        ("/api/files", door.files, ["GET"]),
        ("/api/files/local", door.files, ["GET"]),
        ("/api/files/local", door.upload, ["POST"]),
        ("/api/files/sdcard", door.sdcard_files, ["GET"]),
        ("/api/files/sdcard", door.cannot, ["POST"]),
        ("/api/files/local/{path:path}", door.file_info, ["GET"]),
        ("/api/files/local/{path:path}", door.file_command, ["POST"]),
        ("/api/files/local/{path:path}", door.delete, ["DELETE"]),
        ("/downloads/files/local/{path:path}", door.download, ["GET"]),
        ("/plugin/prusaslicerthumbnails/thumbnail/{path:path}", door.thumbnail, ["GET"]),
        ("/plugin/appkeys/probe", door.appkeys_probe, ["GET"]),
        ("/plugin/appkeys/request", door.appkeys_request, ["POST"]),
        ("/plugin/appkeys/request/{app_token}", door.appkeys_poll, ["GET"]),
    ]
    for prefix in PREFIXES:
        router = door_router(agent, prefix)
        for path, endpoint, methods in routes:
            body = MULTIPART_BODY if endpoint == door.upload else JSON_BODY if "POST" in methods else None
            router.add_api_route(path, _octoprint_errors(endpoint), methods=methods, openapi_extra=body)
        app.include_router(router)


def _octoprint_errors(endpoint: Callable[..., Awaitable[Any]]) -> Callable[..., Awaitable[Any]]:
    """Errors as OctoPrint words them, `{"error": message}` (with `message` too), under the status the native
    API gives the same error (404 unknown machine or file, 409 cannot now, 400 bad input, 413 too large)."""

    @functools.wraps(endpoint)
    async def wrapped(*args: Any, **kwargs: Any) -> Any:
        from fabwire.agent.api import _status_for

        try:
            return await endpoint(*args, **kwargs)
        except FabwireError as exc:
            return _error(_status_for(exc), str(exc))

    return wrapped
