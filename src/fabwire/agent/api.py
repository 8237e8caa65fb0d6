"""The HTTP API (`/api/v1`, OpenAPI at `/api/v1/openapi.json`), the live WebSocket and the dashboard's files.

Every error is `{"message": words, "exit_code": the CLI's exit code for that kind of error, "error": class}`.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
from collections.abc import AsyncIterator, Callable
from datetime import UTC, datetime, timedelta
from importlib import resources
from typing import Any

from fastapi import APIRouter, FastAPI, Query, Request, WebSocket, WebSocketDisconnect
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, Field, StrictBool
from starlette.exceptions import HTTPException as StarletteHTTPException

from fabwire import __version__
from fabwire.agent.boundary import SUBPROTOCOL, Boundary, Policy, connection_headers, parse_json
from fabwire.agent.core import Agent, DeviceSpec, UnknownDevice, exit_code_of
from fabwire.agent.doors import mount_doors
from fabwire.agent.jobs import JobNotFound
from fabwire.agent.offload import while_connected
from fabwire.errors import (
    DeviceBusy,
    DeviceError,
    FabwireError,
    InputError,
    LinkError,
    LinkTimeout,
    RemoteProtocolError,
    excerpt,
)

STATIC = resources.files("fabwire.agent") / "static"
UPLOAD_QUERY = Query(..., min_length=1, max_length=200, description="The file's name; only its extension is used "
                     "(it is stored under a generated name).")


class ErrorBody(BaseModel):
    message: str
    exit_code: int = Field(description="The exit code `fabwire` gives for this kind of error.")
    error: str = Field(description="The error's class, e.g. DeviceError.")


class NewDevice(BaseModel):
    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
    kind: str = Field(pattern="^(xyz|lineus|mmu)$")
    address: str = Field(min_length=1, max_length=300, description="As for -d: host[:port], tcp://…, /dev/…")
    options: dict[str, str | int | float | bool | list[str]] = Field(
        default_factory=dict, description="The kind's settings, as in devices.toml (timeout, speed, auto_retries …)")


class Confirm(BaseModel):
    confirm: StrictBool = False  # "yes" or 1 is no confirmation: the actions' params take true only, too


SERIAL_PORT = re.compile(r"^/dev/(tty[A-Za-z0-9_.-]+|cu\.[A-Za-z0-9_.-]+|serial/by-(id|path)/[A-Za-z0-9_.:+-]+)$")
"""The only paths a device added over the API may name: serial ports (a request must not open any file)."""


def checked_address(body: NewDevice) -> str:
    """The address as the agent will open it, the name and address checked as every door checks them
    (`fabwire.checks.RULES`); over the API, a path must be a serial port's."""
    from fabwire.config import check_device_name
    from fabwire.devices import KINDS as DEVICE_KINDS
    from fabwire.transport.urls import parse_url

    check_device_name(body.name)
    endpoint = parse_url(body.address, DEVICE_KINDS[body.kind])
    if endpoint.scheme == "serial" and (not SERIAL_PORT.match(endpoint.path) or ".." in endpoint.path):
        raise InputError(f"{excerpt(endpoint.path, 60)} is not a serial port: over the API a device path must "
                         "look like /dev/ttyACM0 or /dev/serial/by-id/…")
    from fabwire.transport.simaddress import PATH_OPTIONS  # only the agent's owner says where it reads or writes

    paths = sorted(set(endpoint.options) & PATH_OPTIONS) if endpoint.scheme == "sim" else []
    if paths:
        raise InputError(f"over the API a simulator takes no file or folder ({', '.join(paths)}): a request must not "
                         "choose where the agent reads or writes; give them on the agent's command line")
    return endpoint.url



ERRORS: dict[int | str, dict[str, Any]] = {code: {"model": ErrorBody}
                                           for code in (400, 401, 403, 404, 408, 409, 413, 415, 503, 504, 507)}


def _status_for(exc: BaseException) -> int:
    status = getattr(exc, "http_status", None)
    if isinstance(status, int):
        return status
    if isinstance(exc, UnknownDevice | JobNotFound):
        return 404
    if isinstance(exc, DeviceError | DeviceBusy):
        return 409
    if isinstance(exc, LinkTimeout):
        return 504
    if isinstance(exc, LinkError | ConnectionError):
        return 503
    if isinstance(exc, RemoteProtocolError):
        return 502
    if isinstance(exc, InputError | FabwireError):
        return 400
    return 500


def error_response(status: int, message: str, exit_code: int, error: str) -> JSONResponse:
    return JSONResponse({"message": message, "exit_code": exit_code, "error": error}, status_code=status,
                        headers=connection_headers(status))


async def _json_object(request: Request) -> dict[str, Any]:
    """The request body as a JSON object (empty body: {}); InputError for anything else. The boundary has
    already bounded its size and checked its content type."""
    raw = await request.body()
    if not raw.strip():
        return {}
    body = parse_json(raw)
    if not isinstance(body, dict):
        raise InputError(f"the body must be a JSON object of parameters, not {type(body).__name__}")
    return body


def _iso(epoch: float) -> str:
    return datetime.fromtimestamp(epoch, UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def published(content: Any) -> JSONResponse:
    """What the agent already holds (a state, its health), written as JSON straight away: it is JSON already, so
    the framework's generic conversion, a copy of every nested value, is skipped; anything else goes through it."""
    try:
        return JSONResponse(content)
    except TypeError:
        return JSONResponse(jsonable_encoder(content))


def create_app(agent: Agent, *, max_upload_bytes: int, policy: Policy | None = None,
               on_dashboard: Callable[[], None] | None = None) -> FastAPI:
    """The agent's application, behind its boundary (`fabwire.agent.boundary`): `policy` says which names,
    token and sizes it accepts (default: loopback names only, no token, uploads up to `max_upload_bytes`).
    `on_dashboard` is called whenever the dashboard page is served."""
    app = FastAPI(title="fabwire agent", version=__version__, openapi_url="/api/v1/openapi.json", docs_url=None,
                  redoc_url=None, description="Machines, their states and history, jobs and actions; live events "
                  "on the WebSocket /api/v1/events.")

    @app.exception_handler(FabwireError)
    async def fabwire_error(request: Request, exc: FabwireError) -> JSONResponse:
        return error_response(_status_for(exc), str(exc), exc.exit_code, type(exc).__name__)

    @app.exception_handler(RequestValidationError)
    async def invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        problems = "; ".join(f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors())
        return error_response(422, f"bad request: {problems}", InputError.exit_code, "InputError")

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        return error_response(exc.status_code, str(exc.detail), InputError.exit_code, "HTTPError")

    api = APIRouter(prefix="/api/v1", responses=ERRORS)

    def device_dict(device_id: str) -> dict[str, Any]:
        session = agent.session(device_id)
        return {**session.info.to_dict(), "state": session.state}

    @api.get("/agent", summary="The agent itself: version, devices, and how punctual its polls are",
             response_model=dict[str, Any])
    async def about() -> Response:
        return published(agent.health())

    @api.get("/devices", summary="Every monitored device with its latest state",
             response_model=list[dict[str, Any]])
    async def devices() -> Response:
        return published([device_dict(d.id) for d in agent.devices()])

    @api.post("/devices", status_code=201, summary="Start monitoring a device")
    async def add_device(body: NewDevice) -> dict[str, Any]:
        spec = DeviceSpec(body.name, body.kind, checked_address(body), body.options)  # type: ignore[arg-type]
        info = await agent.add_device(spec)
        return device_dict(info.id)

    @api.get("/devices/{device_id}", summary="One device and its latest state", response_model=dict[str, Any])
    async def device(device_id: str) -> Response:
        return published(device_dict(device_id))

    @api.delete("/devices/{device_id}", status_code=204, summary="Stop monitoring a device")
    async def remove_device(device_id: str) -> Response:
        await agent.remove_device(device_id)
        return Response(status_code=204)

    @api.get("/devices/{device_id}/state", summary="The latest state (the `--json` status, a summary, ts, online)",
             response_model=dict[str, Any])
    async def state(device_id: str) -> Response:
        return published(agent.state(device_id))

    @api.get("/devices/{device_id}/history", summary="Samples (temperatures, progress, state) and events in a range")
    async def history(device_id: str, since: datetime | None = None, until: datetime | None = None,
                      limit: int = Query(2000, ge=1, le=20000)) -> dict[str, Any]:
        device_id = agent.session(device_id).info.id
        end = until or datetime.now(UTC)
        start = since or end - timedelta(hours=1)
        samples = await agent.history.samples(device_id, start.timestamp(), end.timestamp(), limit)
        events = await agent.history.events(device_id, start.timestamp(), end.timestamp(), limit)
        return {"device": device_id, "since": start.isoformat(), "until": end.isoformat(),
                "samples": [{**s, "ts": _iso(s["ts"])} for s in samples], "events": events}

    @api.get("/devices/{device_id}/drawing", summary="A Line-us job's planned strokes and the ink drawn so far")
    async def drawing(device_id: str) -> dict[str, Any]:
        return agent.session(device_id).drawing

    @api.get("/devices/{device_id}/actions", summary="The actions of this kind of device, and those that apply now")
    async def actions(device_id: str) -> dict[str, Any]:
        session = agent.session(device_id)
        return {"actions": [a.to_dict() for a in session.driver.actions],
                "applicable": session.state["summary"]["actions"]}

    @api.post("/devices/{device_id}/actions/{action}", summary="Run an action; long ones answer {started} at once",
              openapi_extra={"requestBody": {"required": False, "content": {
                  "application/json": {"schema": {"type": "object", "additionalProperties": True}}}}})
    async def act(device_id: str, action: str, request: Request) -> dict[str, Any]:
        agent.session(device_id).driver.action(action)  # an unknown action is the news, whatever the body
        return await agent.act(device_id, action, await _json_object(request))

    @api.post("/devices/{device_id}/jobs", status_code=201, summary="Upload a file (request body) and start it",
              openapi_extra={"requestBody": {"required": True, "content": {
                  "application/octet-stream": {"schema": {"type": "string", "format": "binary"}}}}})
    async def upload(device_id: str, request: Request, filename: str = UPLOAD_QUERY) -> dict[str, Any]:
        read = asyncio.Event()

        async def body() -> AsyncIterator[bytes]:
            async for chunk in request.stream():
                yield chunk
            read.set()

        # claimed before a byte is read; checked after the last, unless the uploader has gone meanwhile
        return await while_connected(request, agent.upload_job(device_id, filename, body()), read)

    @api.get("/jobs", summary="Jobs, newest first (they survive a restart)")
    async def jobs(device: str | None = None, limit: int = Query(100, ge=1, le=1000)) -> list[dict[str, Any]]:
        return await agent.jobs.list(agent.resolve(device) if device else None, limit)

    @api.get("/jobs/{job_id}", summary="One job")
    async def job(job_id: str) -> dict[str, Any]:
        return await agent.jobs.get(job_id)

    @api.post("/jobs/{job_id}/cancel", summary="Cancel a running job (needs {\"confirm\": true})")
    async def cancel(job_id: str, body: Confirm | None = None) -> dict[str, Any]:
        return await agent.cancel_job(job_id, confirm=bool(body and body.confirm))

    @api.websocket("/events")
    async def events(websocket: WebSocket, device: str | None = None) -> None:
        """Live events as JSON text messages (see `fabwire.agent.core`); the current state of each device first."""
        offered = websocket.scope.get("subprotocols", [])
        try:
            subscription = agent.subscribe(device)
        except UnknownDevice as exc:
            await websocket.send_denial_response(error_response(404, str(exc), exc.exit_code, "UnknownDevice"))
            return
        await websocket.accept(subprotocol=SUBPROTOCOL if SUBPROTOCOL in offered else None)
        receiver: asyncio.Future[Any] = asyncio.ensure_future(websocket.receive())
        try:
            for info in agent.devices():
                if device in (None, info.id):
                    current = agent.state(info.id)
                    await websocket.send_text(json.dumps({"ts": current["ts"], "device": info.id, "type": "state",
                                                          "state": current}))
            while True:
                getter = asyncio.ensure_future(anext(subscription))
                done, _ = await asyncio.wait({receiver, getter}, return_when=asyncio.FIRST_COMPLETED)
                if receiver in done:
                    getter.cancel()
                    if receiver.result().get("type") == "websocket.disconnect":
                        break
                    receiver = asyncio.ensure_future(websocket.receive())  # messages from clients are ignored
                    continue
                await websocket.send_text(json.dumps(getter.result()))
        except (WebSocketDisconnect, ConnectionError, RuntimeError, StopAsyncIteration):
            pass
        finally:
            subscription.close()
            receiver.cancel()
            with contextlib.suppress(BaseException):
                await receiver

    app.include_router(api)
    mount_doors(app, agent)
    app.mount("/static", StaticFiles(directory=str(STATIC)), name="static")

    @app.get("/", include_in_schema=False)
    async def index() -> FileResponse:
        if on_dashboard is not None:
            on_dashboard()
        return FileResponse(str(STATIC / "index.html"), headers={"cache-control": "no-cache"})

    @app.exception_handler(Exception)
    async def unexpected(request: Request, exc: Exception) -> JSONResponse:
        return error_response(500, f"internal error: {exc!r}", exit_code_of(exc), type(exc).__name__)

    app.add_middleware(Boundary, policy=policy or Policy(max_upload_bytes=max_upload_bytes),
                       router=app.router, requests_first=agent.requests)
    return app
