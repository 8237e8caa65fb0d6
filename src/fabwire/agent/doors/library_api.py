"""fabwire's own routes for the file library, the queues and application-key requests (under `/api/v1`, with
the rest of the native API): what the dashboard's library view and key approvals call."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, FastAPI, Request
from fastapi.responses import FileResponse, Response
from pydantic import BaseModel, Field, StrictBool

from fabwire.agent.appkeys import AppKeys
from fabwire.agent.core import Agent


class QueueChange(BaseModel):
    enabled: StrictBool | None = None
    order: list[str] | None = Field(default=None, max_length=1000, description="The queued names, in order.")


class Enqueue(BaseModel):
    name: str = Field(min_length=1, max_length=300)


def mount(app: FastAPI, agent: Agent, appkeys: AppKeys) -> None:
    library = agent.library
    api = APIRouter(prefix="/api/v1")

    def listing(device_id: str) -> dict[str, Any]:
        view = library.machines.view(device_id)
        return {"device": view.id, "files": library.files(view.id) if view.takes_jobs else [],
                "queue": library.queue(view.id), "queue_enabled": library.queue_enabled(view.id),
                "selected": library.selected(view.id), "ready": view.refusal() is None, "refusal": view.refusal()}

    @api.get("/devices/{device_id}/library", summary="Kept files (newest first), the queue and the selection")
    async def files(device_id: str) -> dict[str, Any]:
        return listing(device_id)

    @api.post("/devices/{device_id}/library/{name:path}/print", status_code=201,
              summary="Print a kept file now (409 with the reason when the machine cannot start it)")
    async def reprint(device_id: str, name: str) -> dict[str, Any]:
        return await library.start_print(device_id, name)

    @api.delete("/devices/{device_id}/library/{name:path}", status_code=204, summary="Delete a kept file")
    async def delete(device_id: str, name: str) -> Response:
        await library.delete(device_id, name)
        return Response(status_code=204)

    @api.get("/devices/{device_id}/library/{name:path}/thumbnail", summary="A kept file's largest preview")
    async def thumbnail(device_id: str, name: str) -> Response:
        view = library.machines.view(device_id)
        image, media = library.thumbnail(view.id, name)
        return Response(image, media_type=media)

    @api.get("/devices/{device_id}/library/{name:path}/download", summary="A kept file as uploaded")
    async def download(device_id: str, name: str) -> FileResponse:
        view = library.machines.view(device_id)
        entry = library.get(view.id, name)
        return FileResponse(str(library.path_of(view.id, entry)), filename=entry["name"].rsplit("/", 1)[-1])

    @api.post("/devices/{device_id}/queue", summary="Add a kept file to the end of the queue")
    async def enqueue(device_id: str, body: Enqueue) -> dict[str, Any]:
        view = library.machines.view(device_id)
        entry = library.get(view.id, body.name)
        return await library.set_queue(view.id, order=[*library.queue(view.id), entry["name"]])

    @api.put("/devices/{device_id}/queue", summary="Turn the queue on or off, and/or reorder or trim it")
    async def change_queue(device_id: str, body: QueueChange) -> dict[str, Any]:
        return await library.set_queue(device_id, enabled=body.enabled, order=body.order)

    @api.post("/devices/{device_id}/queue/next", status_code=201, summary="Start the first queued file now")
    async def start_next(device_id: str) -> dict[str, Any]:
        return await library.start_next(device_id)

    @api.get("/appkeys", summary="Application-key requests waiting for the owner's decision")
    async def key_requests() -> list[dict[str, object]]:
        return appkeys.pending()

    @api.post("/appkeys/{request_id}/approve", summary="Give the requesting application the access token")
    async def approve(request_id: str) -> dict[str, object]:
        return appkeys.decide(request_id, True)

    @api.post("/appkeys/{request_id}/deny", summary="Refuse the requesting application")
    async def deny(request_id: str, request: Request) -> dict[str, object]:
        return appkeys.decide(request_id, False)

    app.include_router(api)
