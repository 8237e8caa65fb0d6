"""The Moonraker-compatible door: what PrusaSlicer's/SuperSlicer's/OrcaSlicer's Moonraker host and Moonraker clients
(Home Assistant's Moonraker integration through `moonraker-api`, mobile apps) call. Field meanings from
moonraker.readthedocs.io (external API: server, printer, file manager, history, JSON-RPC notifications) and
Klipper's status reference (print_stats, extruder, heater_bed, virtual_sdcard, display_status …).

One table of methods (`METHODS`) serves both transports: HTTP (`GET /server/info` answers `{"result": …}`) and
JSON-RPC 2.0 over the WebSocket `/websocket` (`server.info`), where `printer.objects.subscribe` is followed by
`notify_status_update` notifications carrying what changed. A translation of `MachineView`, the library and the
agent's jobs; nothing here decides anything.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import json
import socket
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, BinaryIO

from fastapi import FastAPI, Request, WebSocket, WebSocketDisconnect
from fastapi.responses import FileResponse, JSONResponse, Response

from fabwire import __version__
from fabwire.agent.boundary import connection_headers, parse_json, request_media_type
from fabwire.agent.core import Agent
from fabwire.agent.doors import (
    JSON_BODY,
    MULTIPART_BODY,
    PREFIXES,
    door_router,
    file_name_of,
    machine_of,
    read_upload,
)
from fabwire.agent.doors.klipper_objects import history_job, printer_objects
from fabwire.agent.model import MachineView, TakesNoJobs
from fabwire.agent.offload import while_connected
from fabwire.agent.session import JobClaim
from fabwire.errors import FabwireError, InputError
from fabwire.jsontext import parse_json as parse_message

MOONRAKER_VERSION = "v0.9.3"
"""The Moonraker release whose API this door follows."""
API_VERSION = (1, 5, 0)
ROOT = "gcodes"
THUMBS = ".thumbs"

MAX_MESSAGE = 64 << 10
"""The largest JSON-RPC message taken (bytes of UTF-8), as `fabwire serve` sets its WebSocket frames' limit (a larger
one is closed with 1009, RFC 6455 §7.4.1); Moonraker clients' requests are well under a kilobyte."""

PARSE_ERROR, INVALID_REQUEST = -32700, -32600


@dataclass(frozen=True, slots=True)
class Refusal:
    """One kind of WebSocket message that is no JSON-RPC 2.0 request, and its error reply."""

    what: str
    code: int
    check: Callable[[Any], bool]
    """True for a parsed message this row refuses (rows are tried in order)."""
    source: str


def _is_id(value: object) -> bool:
    return value is None or isinstance(value, str) or (isinstance(value, int | float) and not isinstance(value, bool))


REFUSALS: tuple[Refusal, ...] = (
    Refusal("a request must be a JSON object", INVALID_REQUEST, lambda m: not isinstance(m, dict),
            "JSON-RPC 2.0 §4 Request object; §6 (an empty batch or a batch item that is no object)"),
    Refusal('"jsonrpc" must be exactly "2.0"', INVALID_REQUEST, lambda m: m.get("jsonrpc") != "2.0",
            "JSON-RPC 2.0 §4 (jsonrpc: MUST be exactly \"2.0\"); Moonraker answers the same -32600"),
    Refusal('"method" must be a string', INVALID_REQUEST, lambda m: not isinstance(m.get("method"), str),
            "JSON-RPC 2.0 §4 (method: a String containing the name of the method)"),
    Refusal('"id" must be a string, a number or null', INVALID_REQUEST, lambda m: not _is_id(m.get("id")),
            "JSON-RPC 2.0 §4 (id: a String, Number, or Null)"),
    Refusal('"params" must be an object or an array', INVALID_REQUEST,
            lambda m: m.get("params") is not None and not isinstance(m["params"], dict | list),
            "JSON-RPC 2.0 §4 and §4.2 (params: a Structured value)"),
)
"""What a parsed message must be, in order (the parse errors come first: text that is not UTF-8 JSON within
`MAX_MESSAGE` bytes and `fabwire.jsontext.MAX_DEPTH` levels, NaN or Infinity, is -32700 by JSON-RPC 2.0 §5.1 and
RFC 8259 §6; a binary frame is -32600: Moonraker's JSON-RPC is text frames, RFC 6455 §5.6)."""

CANNOT_GCODE = "these machines take whole files, not G-code scripts: upload a file and print it"
ERROR_CODES = {"method": -32601, "params": -32602}


class RpcError(FabwireError):
    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


def _status_code(exc: BaseException) -> int:
    from fabwire.agent.api import _status_for

    return exc.code if isinstance(exc, RpcError) and exc.code > 0 else _status_for(exc)


@dataclass
class Call:
    """One method call: the machine addressed and the parameters (query/form/JSON for HTTP, `params` for RPC)."""

    view: MachineView
    params: dict[str, Any]
    base: str
    connection: Connection | None = None


Method = Callable[["MoonrakerDoor", Call], Awaitable[Any]]


class Connection:
    """A WebSocket client: its id and its subscription (object → attributes, None for all)."""

    counter = 0

    def __init__(self) -> None:
        Connection.counter += 1
        self.id = Connection.counter
        self.subscribed: dict[str, list[str] | None] = {}
        self.sent: dict[str, dict[str, Any]] = {}


class MoonrakerDoor:
    def __init__(self, agent: Agent) -> None:
        self.agent = agent
        self.library = agent.library
        self.connections: set[Connection] = set()
        self._background: set[asyncio.Task[Any]] = set()

    # ------------------------------------------------------------------------------------------ objects

    def objects(self, view: MachineView) -> dict[str, dict[str, Any]]:
        """Every printer object this machine has, with every attribute (`klipper_objects.ATTRIBUTES`)."""
        entry = self.library.file_of_job(view.shown_job)
        figures = view.figures()
        filename = entry["name"] if entry else (figures.filename if figures else "")
        return printer_objects(view, figures, filename)

    @staticmethod
    def _wanted(objects: object) -> dict[str, list[str] | None]:
        if not isinstance(objects, dict):
            raise RpcError(400, 'objects must be an object: {"objects": {"print_stats": null}}')
        wanted: dict[str, list[str] | None] = {}
        for name, attrs in objects.items():
            if attrs is not None and (not isinstance(attrs, list) or not all(isinstance(a, str) for a in attrs)):
                raise RpcError(400, f"the attributes of {name!r} must be a list of names or null")
            wanted[str(name)] = attrs or None
        return wanted

    @staticmethod
    def _pick(objects: dict[str, dict[str, Any]], wanted: dict[str, list[str] | None]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name, attrs in wanted.items():
            if name in objects:  # Klipper leaves out objects it does not have
                values = objects[name]
                out[name] = dict(values) if attrs is None else {a: values[a] for a in attrs if a in values}
        return out

    # ------------------------------------------------------------------------------------------ methods

    async def server_info(self, call: Call) -> dict[str, Any]:
        return {"klippy_connected": call.view.online, "klippy_state": "ready" if call.view.online else "disconnected",
                "components": ["file_manager", "history", "websockets", "octoprint_compat"],
                "failed_components": [], "registered_directories": [ROOT], "warnings": [],
                "websocket_count": len(self.connections), "moonraker_version": f"{MOONRAKER_VERSION}-fabwire",
                "missing_klippy_requirements": [], "api_version": list(API_VERSION),
                "api_version_string": ".".join(map(str, API_VERSION))}

    async def printer_info(self, call: Call) -> dict[str, Any]:
        view = call.view
        return {"state": "ready" if view.online else "shutdown",
                "state_message": "Printer is ready" if view.online else view.message,
                "hostname": socket.gethostname(), "software_version": f"fabwire {__version__}",
                "cpu_info": view.model or view.kind, "klipper_path": "", "python_path": "", "log_file": "",
                "config_file": "", "app": "fabwire"}

    async def objects_list(self, call: Call) -> dict[str, Any]:
        return {"objects": list(self.objects(call.view))}

    async def objects_query(self, call: Call) -> dict[str, Any]:
        wanted = self._wanted(call.params.get("objects", {}))
        return {"eventtime": time.monotonic(), "status": self._pick(self.objects(call.view), wanted)}

    async def objects_subscribe(self, call: Call) -> dict[str, Any]:
        wanted = self._wanted(call.params.get("objects", {}))
        status = self._pick(self.objects(call.view), wanted)
        if call.connection is not None:
            call.connection.subscribed = wanted
            call.connection.sent = json.loads(json.dumps(status))
        return {"eventtime": time.monotonic(), "status": status}

    async def print_start(self, call: Call) -> str:
        filename = call.params.get("filename")
        if not isinstance(filename, str) or not filename:
            raise RpcError(400, "printer.print.start needs the parameter filename")
        await self.library.start_print(call.view.id, filename.removeprefix(f"{ROOT}/"))
        return "ok"

    async def print_pause(self, call: Call) -> str:
        return await self._act(call.view, "pause", "pausing")

    async def print_resume(self, call: Call) -> str:
        return await self._act(call.view, "resume", "resuming")

    async def print_cancel(self, call: Call) -> str:
        view = call.view
        if view.job is None and not view.printing:
            raise TakesNoJobs(f"{view.name} is not printing: there is nothing to cancel")
        self.library.machines.requested(view.id, "cancelling")
        work = (self.agent.cancel_job(view.job["id"], confirm=True) if view.job is not None
                else self.agent.act(view.id, "cancel", {"confirm": True}))
        task = asyncio.ensure_future(work)  # the machine takes its time to stop; its end arrives as updates
        self._background.add(task)
        task.add_done_callback(self._background.discard)
        with contextlib.suppress(TimeoutError, asyncio.TimeoutError):
            await asyncio.wait_for(asyncio.shield(task), 2.0)
        return "ok"

    async def _act(self, view: MachineView, action: str, shown: str) -> str:
        applicable = (self.agent.state(view.id).get("summary") or {}).get("actions") or []
        if action not in applicable:
            raise TakesNoJobs(f"{view.name} cannot {action} now (it is {view.phase})")
        await self.agent.act(view.id, action, {})
        self.library.machines.requested(view.id, shown)
        return "ok"

    async def gcode_script(self, call: Call) -> str:
        raise TakesNoJobs(CANNOT_GCODE)

    def _file(self, entry: dict[str, Any]) -> dict[str, Any]:
        return {"path": entry["name"], "modified": entry["uploaded"], "size": entry["size"], "permissions": "rw"}

    async def files_list(self, call: Call) -> list[dict[str, Any]]:
        root = call.params.get("root", ROOT)
        if root != ROOT:
            raise RpcError(400, f"only the root {ROOT!r} is kept here, not {root!r}")
        return [self._file(e) for e in self.library.files(call.view.id)] if call.view.takes_jobs else []

    async def files_metadata(self, call: Call) -> dict[str, Any]:
        name = call.params.get("filename")
        if not isinstance(name, str) or not name:
            raise RpcError(400, "server.files.metadata needs the parameter filename")
        entry = self.library.get(call.view.id, name.removeprefix(f"{ROOT}/"))
        meta = entry["meta"]
        folder = entry["name"].rsplit("/", 1)[0] + "/" if "/" in entry["name"] else ""
        return {"filename": entry["name"], "size": entry["size"], "modified": entry["uploaded"],
                "slicer": meta.get("slicer"), "slicer_version": None, "layer_count": meta.get("layers"),
                "estimated_time": meta.get("print_time_s"), "filament_total": meta.get("filament_mm"),
                "print_start_time": None, "job_id": None,
                "thumbnails": [{"width": t["width"], "height": t["height"], "size": t["size"],
                                "relative_path": f"{THUMBS}/{t['stored']}",
                                "thumbnail_path": f"{folder}{THUMBS}/{t['stored']}"}
                               for t in sorted(entry["thumbnails"], key=lambda t: t["width"] * t["height"])]}

    async def files_delete(self, call: Call) -> dict[str, Any]:
        path = str(call.params.get("path", "")).removeprefix(f"{ROOT}/")
        entry = self.library.get(call.view.id, path)
        await self.library.delete(call.view.id, path)
        return {"item": {**self._file(entry), "root": ROOT}, "action": "delete_file"}

    async def history_list(self, call: Call) -> dict[str, Any]:
        try:
            limit = max(1, min(int(call.params.get("limit", 50)), 1000))
            start = max(0, int(call.params.get("start", 0)))
        except (TypeError, ValueError):
            raise RpcError(400, "limit and start must be whole numbers") from None
        jobs = await self.agent.jobs.list(call.view.id, limit + start)
        names = {e["name"].rsplit("/", 1)[-1] for e in self.library.files(call.view.id)}
        return {"count": len(jobs[start:]), "jobs": [history_job(job, names) for job in jobs[start:]]}

    async def websocket_id(self, call: Call) -> dict[str, Any]:
        return {"websocket_id": call.connection.id if call.connection else 0}

    async def identify(self, call: Call) -> dict[str, Any]:
        return {"connection_id": call.connection.id if call.connection else 0}

    # ------------------------------------------------------------------------------------------ HTTP

    async def http(self, request: Request, method: Method, params: dict[str, Any]) -> Response:
        try:
            view = machine_of(self.agent, request)
            result = await method(self, Call(view, params, str(request.base_url)))
        except FabwireError as exc:
            return _error(_status_code(exc), str(exc))
        return JSONResponse({"result": result})

    async def upload(self, request: Request) -> Response:
        """POST /server/files/upload: multipart `file`, `root` (gcodes), `path`, `print` ("true"), `checksum`
        (SHA-256, 422 when it does not match). With print sent before the file (the slicers' Moonraker hosts),
        the machine is claimed before the file is read."""
        claims: list[JobClaim] = []
        sinks: list[Callable[[bytes], Awaitable[None]]] = []
        try:
            view = machine_of(self.agent, request)
            view.require_files()

            def before_file(fields: dict[str, str], filename: str) -> None:
                if fields.get("print", "").strip().lower() == "true" and fields.get("root", ROOT) == ROOT:
                    claim = self.library.claim_print(view.id, f"{fields.get('path', '')}/{filename}")
                    if claim is not None:
                        claims.append(claim)
                        sinks.append(claim.write)  # the job's copy is written as the file arrives

            form = await read_upload(request, self.agent.jobs.max_upload_bytes, before_file,
                                     self.library.staging(view.id), sinks)
            try:
                fields = form.fields
                if form.file is None:
                    raise InputError("send the file as the multipart field 'file'")
                root = fields.get("root") or ROOT
                if root != ROOT:
                    raise RpcError(400, f"uploads go to the root {ROOT!r} here, not {root!r}")
                checksum = fields.get("checksum", "").strip().lower()
                if checksum:
                    digest = await asyncio.to_thread(_sha256, form.file)
                    if digest != checksum:
                        raise RpcError(422, f"checksum mismatch: the upload's SHA-256 is {digest}")
                start = fields.get("print", "").strip().lower() == "true"
                name = f"{fields.get('path', '')}/{file_name_of(form.filename)}"
                result = await while_connected(request, self.library.add(  # dropped if the slicer hangs up
                    view.id, name, form.adopt(), start=start, select=start, claim=claims[0] if claims else None,
                    claim_fed=bool(claims)))
            finally:
                form.close()
        except FabwireError as exc:
            return _error(_status_code(exc), str(exc))
        finally:
            for claim in claims:
                claim.release()
        entry = result["file"]
        return JSONResponse({"result": {"item": {**self._file(entry), "root": ROOT},
                                        "print_started": result["job"] is not None, "print_queued": result["queued"],
                                        "action": "create_file"}}, status_code=201)

    async def serve_file(self, request: Request, path: str) -> Response:
        """GET /server/files/gcodes/PATH: a kept file, or a preview under `.thumbs/`."""
        try:
            view = machine_of(self.agent, request)
            parts = path.split("/")
            if THUMBS in parts[:-1]:
                stored = parts[-1]
                for entry in self.library.files(view.id):
                    for index, thumb in enumerate(sorted(entry["thumbnails"],
                                                         key=lambda t: t["width"] * t["height"])):
                        if thumb["stored"] == stored:
                            image, media = self.library.thumbnail(view.id, entry["name"], index)
                            return Response(image, media_type=media)
                raise RpcError(404, f"no preview {stored!r}")
            entry = self.library.get(view.id, path)
            return FileResponse(str(self.library.path_of(view.id, entry)), media_type="text/plain",
                                filename=entry["name"].rsplit("/", 1)[-1])
        except FabwireError as exc:
            return _error(_status_code(exc), str(exc))

    # ------------------------------------------------------------------------------------------ WebSocket

    async def websocket(self, websocket: WebSocket) -> None:
        """JSON-RPC 2.0: requests answered in order; `notify_status_update` [changes, eventtime] after a
        subscription whenever a subscribed value changes."""
        try:
            view = machine_of(self.agent, websocket)
        except FabwireError as exc:
            await websocket.close(code=4404, reason=str(exc)[:120])
            return
        await websocket.accept()
        connection = Connection()
        self.connections.add(connection)
        subscription = self.agent.subscribe(view.id)
        receiver: asyncio.Future[Any] = asyncio.ensure_future(_frame(websocket))
        events: asyncio.Future[Any] = asyncio.ensure_future(anext(subscription))
        try:
            while True:
                done, _ = await asyncio.wait({receiver, events}, return_when=asyncio.FIRST_COMPLETED)
                if events in done:
                    events.result()
                    await self._notify(websocket, connection, view.id)
                    events = asyncio.ensure_future(anext(subscription))
                if receiver in done:
                    reply = await self._message(receiver.result(), view.id, connection, str(websocket.base_url))
                    if reply is not None:
                        await websocket.send_text(json.dumps(reply, allow_nan=False))
                    receiver = asyncio.ensure_future(_frame(websocket))
        except (WebSocketDisconnect, ConnectionError, RuntimeError, StopAsyncIteration):
            pass
        finally:
            self.connections.discard(connection)
            subscription.close()
            for future in (receiver, events):
                future.cancel()
                with contextlib.suppress(BaseException):
                    await future

    async def _notify(self, websocket: WebSocket, connection: Connection, device_id: str) -> None:
        if not connection.subscribed:
            return
        current = json.loads(json.dumps(self._pick(self.objects(self.library.machines.view(device_id)),
                                                   connection.subscribed)))
        changes: dict[str, Any] = {}
        for name, values in current.items():
            before = connection.sent.get(name, {})
            diff = {k: v for k, v in values.items() if before.get(k, object()) != v}
            if diff:
                changes[name] = diff
        if changes:
            connection.sent = current
            await websocket.send_text(json.dumps({"jsonrpc": "2.0", "method": "notify_status_update",
                                                  "params": [changes, time.monotonic()]}))

    async def _message(self, frame: str | bytes, device_id: str, connection: Connection,
                       base: str) -> dict[str, Any] | list[dict[str, Any]] | None:
        """The reply to one WebSocket frame: a request's response, a batch's responses (JSON-RPC 2.0 §6), an
        error response for anything else, None when only notifications came."""
        if isinstance(frame, bytes):
            return _rpc_error(INVALID_REQUEST, "send JSON-RPC requests as text frames, not binary")
        try:
            message = parse_message(frame.encode("utf-8", "surrogatepass"), what="the message", max_bytes=MAX_MESSAGE)
        except InputError as exc:  # NaN and Infinity too (`fabwire.jsontext`)
            return _rpc_error(PARSE_ERROR, f"Parse error: {exc}")
        if isinstance(message, list) and message:
            replies = [await self._rpc(item, device_id, connection, base) for item in message]
            return [r for r in replies if r is not None] or None
        return await self._rpc(message, device_id, connection, base)

    async def _rpc(self, message: Any, device_id: str, connection: Connection, base: str) -> dict[str, Any] | None:
        for refusal in REFUSALS:
            if refusal.check(message):
                rpc_id = message.get("id") if isinstance(message, dict) and _is_id(message.get("id")) else None
                return _rpc_error(refusal.code, f"Invalid Request: {refusal.what}", rpc_id)
        rpc_id = message.get("id")
        method = METHODS.get(message["method"])
        params = message.get("params") or {}
        if method is None:
            error: dict[str, Any] = {"code": ERROR_CODES["method"], "message": f"Method not found: "
                                     f"{message['method'][:80]}"}
        elif not isinstance(params, dict):
            error = {"code": ERROR_CODES["params"], "message": "params must be an object"}
        else:
            try:
                view = self.library.machines.view(device_id)
                result = await method(self, Call(view, params, base, connection))
            except FabwireError as exc:
                error = {"code": _status_code(exc), "message": str(exc)}
            else:
                return {"jsonrpc": "2.0", "result": result, "id": rpc_id} if "id" in message else None
        return {"jsonrpc": "2.0", "error": error, "id": rpc_id} if "id" in message else None


async def _frame(websocket: WebSocket) -> str | bytes:
    """The next message's text (a text frame) or bytes (a binary frame); WebSocketDisconnect once it closes."""
    message = await websocket.receive()
    if message["type"] == "websocket.disconnect":
        raise WebSocketDisconnect(message.get("code", 1000), message.get("reason"))
    text: str | None = message.get("text")
    return text if text is not None else bytes(message.get("bytes") or b"")


def _rpc_error(code: int, message: str, rpc_id: Any = None) -> dict[str, Any]:
    return {"jsonrpc": "2.0", "error": {"code": code, "message": message}, "id": rpc_id}


def _error(status: int, message: str) -> JSONResponse:
    return JSONResponse({"error": {"code": status, "message": message, "traceback": None}}, status_code=status,
                        headers=connection_headers(status))


def _sha256(file: BinaryIO) -> str:
    digest = hashlib.sha256()
    file.seek(0)
    while chunk := file.read(1 << 20):
        digest.update(chunk)
    file.seek(0)
    return digest.hexdigest()


METHODS: dict[str, Method] = {
    "server.info": MoonrakerDoor.server_info,
    "printer.info": MoonrakerDoor.printer_info,
    "printer.objects.list": MoonrakerDoor.objects_list,
    "printer.objects.query": MoonrakerDoor.objects_query,
    "printer.objects.subscribe": MoonrakerDoor.objects_subscribe,
    "printer.print.start": MoonrakerDoor.print_start,
    "printer.print.pause": MoonrakerDoor.print_pause,
    "printer.print.resume": MoonrakerDoor.print_resume,
    "printer.print.cancel": MoonrakerDoor.print_cancel,
    "printer.gcode.script": MoonrakerDoor.gcode_script,
    "server.files.list": MoonrakerDoor.files_list,
    "server.files.metadata": MoonrakerDoor.files_metadata,
    "server.files.delete_file": MoonrakerDoor.files_delete,
    "server.history.list": MoonrakerDoor.history_list,
    "server.websocket.id": MoonrakerDoor.websocket_id,
    "server.connection.identify": MoonrakerDoor.identify,
}
"""JSON-RPC method → its implementation (the HTTP routes below call the same ones)."""

HTTP_ROUTES: tuple[tuple[str, str, str], ...] = (
    ("GET", "/server/info", "server.info"),
    ("GET", "/printer/info", "printer.info"),
    ("GET", "/printer/objects/list", "printer.objects.list"),
    ("GET", "/printer/objects/query", "printer.objects.query"),
    ("POST", "/printer/objects/query", "printer.objects.query"),
    ("POST", "/printer/objects/subscribe", "printer.objects.subscribe"),
    ("POST", "/printer/print/start", "printer.print.start"),
    ("POST", "/printer/print/pause", "printer.print.pause"),
    ("POST", "/printer/print/resume", "printer.print.resume"),
    ("POST", "/printer/print/cancel", "printer.print.cancel"),
    ("POST", "/printer/gcode/script", "printer.gcode.script"),
    ("GET", "/server/files/list", "server.files.list"),
    ("GET", "/server/files/metadata", "server.files.metadata"),
    ("GET", "/server/history/list", "server.history.list"),
)
"""(HTTP method, path, the JSON-RPC method it is): moonraker.readthedocs.io, external API."""


async def _params(request: Request) -> dict[str, Any]:
    """Query arguments (`?print_stats&extruder=temperature,target` → objects for the object routes), then a
    JSON body's members."""
    params: dict[str, Any] = {}
    if request.url.path.endswith("/objects/query") or request.url.path.endswith("/objects/subscribe"):
        objects = {k: (v.split(",") if v else None) for k, v in request.query_params.multi_items()}
        if objects:
            params["objects"] = objects
    else:
        params.update(request.query_params)
    if request.method == "POST" and request_media_type(request.scope) == "application/json":
        raw = await request.body()
        try:
            body = parse_json(raw) if raw.strip() else {}
        except InputError as exc:
            raise RpcError(400, str(exc)) from None
        if not isinstance(body, dict):
            raise RpcError(400, "the body must be a JSON object")
        params.update(body)
    return params


def mount(app: FastAPI, agent: Agent) -> None:
    """Add the Moonraker-compatible routes, for the default machine and under `/printers/NAME`."""
    door = MoonrakerDoor(agent)

    def route(rpc: str) -> Callable[[Request], Awaitable[Response]]:
        async def endpoint(request: Request) -> Response:
            try:
                params = await _params(request)
            except FabwireError as exc:
                return _error(_status_code(exc), str(exc))
            return await door.http(request, METHODS[rpc], params)

        return endpoint

    async def delete_file(request: Request, path: str) -> Response:
        return await door.http(request, METHODS["server.files.delete_file"], {"path": path})

    for prefix in PREFIXES:
        router = door_router(agent, prefix)
        for verb, path, rpc in HTTP_ROUTES:
            router.add_api_route(path, route(rpc), methods=[verb], openapi_extra=JSON_BODY if verb == "POST" else None)
        router.add_api_route("/server/files/upload", door.upload, methods=["POST"], openapi_extra=MULTIPART_BODY)
        router.add_api_route(f"/server/files/{ROOT}/{{path:path}}", door.serve_file, methods=["GET"])
        router.add_api_route(f"/server/files/{ROOT}/{{path:path}}", delete_file, methods=["DELETE"])
        router.add_api_websocket_route("/websocket", door.websocket)
        app.include_router(router)
