"""Doors: the REST dialects other tools already speak (OctoPrint, Moonraker), as thin translations of one model
(`fabwire.agent.model` machines, `fabwire.agent.library` files and queues, the agent's jobs).

Every machine is served under its own prefix, `/printers/NAME/…`, and the default machine (the first da Vinci,
else the first Line-us) at the root as well.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import tempfile
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

from fastapi import APIRouter, Depends, FastAPI, Request
from starlette.requests import HTTPConnection

from fabwire.agent.core import Agent
from fabwire.agent.library import STAGED
from fabwire.agent.model import MachineView, TakesNoJobs
from fabwire.errors import InputError

JSON_BODY: dict[str, object] = {"requestBody": {"required": False, "content": {"application/json": {}}}}
"""The body a door's command route declares (`fabwire.agent.boundary` refuses undeclared bodies)."""
MULTIPART_BODY: dict[str, object] = {"requestBody": {"required": True, "content": {"multipart/form-data": {}}}}
"""The body an upload route declares: the form slicers send, its file part streamed by the door."""

PREFIXES = ("", "/printers/{machine}")
"""Where each door's routes are mounted: the default machine at the root, every machine by name."""


def door_router(agent: Agent, prefix: str) -> APIRouter:
    """A door's router at one of `PREFIXES`: under `/printers/NAME` every route, whatever it answers (even
    `/api/version`, which a slicer's "Test" button checks), is 404 for a name no machine has."""
    async def known_machine(connection: HTTPConnection) -> None:
        machine_of(agent, connection)

    dependencies = [Depends(known_machine)] if "{machine}" in prefix else []
    return APIRouter(prefix=prefix, include_in_schema=False, dependencies=dependencies)


def machine_of(agent: Agent, request: HTTPConnection) -> MachineView:
    """The machine a request addresses (by its prefix), or the default one at the root."""
    name = request.path_params.get("machine")
    if name is not None:
        return agent.library.machines.view(name)
    view = agent.library.machines.default()
    if view is None:
        raise TakesNoJobs("this agent monitors no printer or drawing machine: address one as /printers/NAME/")
    return view


def file_name_of(filename: str | None) -> str:
    """The name of an uploaded file part without any folders a client put in it (Windows' too): the folder
    is the form's `path` field."""
    return (filename or "").replace("\\", "/").rsplit("/", 1)[-1]


def base_url(request: HTTPConnection) -> str:
    """The URL the request's door lives at (with its machine prefix), without a trailing slash."""
    name = request.path_params.get("machine")
    root = str(request.base_url).rstrip("/")
    return f"{root}/printers/{name}" if name is not None else root


def mount_doors(app: FastAPI, agent: Agent) -> None:
    """Add the library routes, the OctoPrint- and the Moonraker-compatible doors to the agent's app."""
    from fabwire.agent.appkeys import AppKeys
    from fabwire.agent.doors import library_api, moonraker, octoprint

    appkeys = AppKeys(agent.state_dir)
    library_api.mount(app, agent, appkeys)
    octoprint.mount(app, agent, appkeys)
    moonraker.mount(app, agent)


FIELD_MAX = 64 * 1024
"""Bytes a plain form field may hold (a folder, "true"); more is an error."""
FIELDS_MAX = 32
"""Plain fields a form may hold; a slicer sends two or three (PrusaSlicer: print, path; Cura: select, print)."""
PARTS_MAX = FIELDS_MAX + 1
"""Parts a form may hold, named or not, empty or not: the fields and the file. Each part costs parser callbacks
on the agent's event loop, so a body of millions of empty parts is refused at the first one past this."""
PART_HEADERS_MAX = 8 * 1024
"""Bytes of one part's header lines (names, values, ':' and CRLF): a Content-Disposition with a long file name
and a Content-Type fit many times over (python-multipart's own limits, where it has them, are per line and count)."""


@dataclass
class Upload:
    """A slicer's multipart upload: its plain fields, and the file part's name and bytes (in a temporary file)."""

    fields: dict[str, str] = field(default_factory=dict)
    filename: str | None = None
    file: BinaryIO | None = None
    path: Path | None = None
    """Where the file part was written (in the directory given to `read_upload`); the library adopts it."""
    size: int = 0

    def adopt(self) -> Path:
        """The written file, closed, for the library to move into place (`close` still removes it if not)."""
        if self.file is None or self.path is None:
            raise InputError("send the file as the multipart field 'file'")
        self.file.close()
        return self.path

    def close(self) -> None:
        """Close the file and remove it unless it was adopted (moved away)."""
        if self.file is not None:
            self.file.close()
        if self.path is not None:
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()


async def read_upload(request: Request, limit: int, before_file: Callable[[dict[str, str], str], None],
                      directory: Path, sinks: list[Callable[[bytes], Awaitable[None]]] | None = None) -> Upload:
    """Stream a multipart/form-data body: plain fields into `fields`, the part named `file` to a new file in
    `directory` (`Upload.path`, removed by `Upload.close` unless moved away).

    `before_file(fields, filename)` runs when the file part begins, with the fields sent before it (PrusaSlicer,
    OrcaSlicer and the Moonraker hosts send `print` first), before a byte of the file is read: a print that
    cannot start is refused there. InputError for a body that is no such form or ends before its closing
    boundary (a cut-off upload: nothing of it is kept), UploadTooLarge over `limit`;
    `file` is None when the form has no file part. Each of `sinks` (which `before_file` may fill: a job claim's
    `write`) gets the file's bytes too, as they arrive."""
    from python_multipart import MultipartParser
    from python_multipart.exceptions import MultipartParseError
    from python_multipart.multipart import parse_options_header

    from fabwire.agent.jobs import UploadTooLarge

    kind, options = parse_options_header(request.headers.get("content-type", ""))
    boundary = options.get(b"boundary")
    if kind != b"multipart/form-data" or not boundary:
        raise InputError("send the file as multipart/form-data with the field 'file'")
    upload = Upload()
    part: dict[str, Any] = {}
    pending = bytearray()
    parts = 0
    ended: list[bool] = []

    def begin() -> None:
        nonlocal parts
        parts += 1
        if parts > PARTS_MAX:
            raise InputError(f"the form has over {PARTS_MAX} parts: a slicer's upload has its file and a few "
                             "fields")
        part.clear()
        part.update(headers={}, field=b"", value=b"", data=bytearray(), name=None, filename=None, header_bytes=0)

    def header_bytes(count: int) -> None:
        part["header_bytes"] += count
        if part["header_bytes"] > PART_HEADERS_MAX:
            raise InputError(f"a part of the form has over {PART_HEADERS_MAX:,} bytes of headers")

    def header_field(data: bytes, start: int, end: int) -> None:
        header_bytes(end - start)
        part["field"] += data[start:end]

    def header_value(data: bytes, start: int, end: int) -> None:
        header_bytes(end - start)
        part["value"] += data[start:end]

    def header_end() -> None:
        header_bytes(3)  # ':' and CRLF
        part["headers"][part["field"].lower()] = part["value"]
        part["field"], part["value"] = b"", b""

    def headers_finished() -> None:
        _, disposition = parse_options_header(part["headers"].get(b"content-disposition", b""))
        part["name"] = disposition.get(b"name", b"").decode("utf-8", "replace")
        filename = disposition.get(b"filename")
        if part["name"] == "file" and filename is not None and upload.file is None:
            part["filename"] = filename.decode("utf-8", "replace")
            before_file(dict(upload.fields), file_name_of(part["filename"]))
            upload.filename = part["filename"]
            directory.mkdir(parents=True, exist_ok=True)
            fd, name = tempfile.mkstemp(dir=directory, prefix=STAGED)
            upload.path = Path(name)
            upload.file = os.fdopen(fd, "w+b")

    def data(chunk: bytes, start: int, end: int) -> None:
        if part["filename"] is not None:
            upload.size += end - start
            if upload.size > limit:
                raise UploadTooLarge(f"the upload is over the limit of {limit:,} bytes")
            pending.extend(chunk[start:end])
        elif part["name"]:
            part["data"] += chunk[start:end]
            if len(part["data"]) > FIELD_MAX:
                raise InputError(f"the form field {part['name']!r} is over {FIELD_MAX:,} bytes")

    def part_end() -> None:
        if part["filename"] is None and part["name"]:
            if len(upload.fields) >= FIELDS_MAX:
                raise InputError(f"the form has over {FIELDS_MAX} fields")
            upload.fields[part["name"]] = bytes(part["data"]).decode("utf-8", "replace")

    parser = MultipartParser(boundary, {
        "on_part_begin": begin, "on_header_field": header_field, "on_header_value": header_value,
        "on_header_end": header_end, "on_headers_finished": headers_finished, "on_part_data": data,
        "on_part_end": part_end, "on_end": lambda: ended.append(True)})
    try:
        async for chunk in request.stream():
            parser.write(chunk)
            if pending and upload.file is not None:
                piece = bytes(pending)
                pending.clear()
                await asyncio.to_thread(upload.file.write, piece)
                for sink in sinks or ():
                    await sink(piece)
        parser.finalize()
        if not ended:  # RFC 7578 §4.1 / RFC 2046 §5.1.1: a form ends with its close-delimiter "--BOUNDARY--"
            raise InputError("the multipart form ends before its closing boundary: the upload was cut off, so "
                             "nothing was kept; send it again")
    except MultipartParseError as exc:
        upload.close()
        raise InputError(f"the multipart form is malformed: {exc}") from None
    except BaseException:
        upload.close()
        raise
    if upload.file is not None:
        upload.file.seek(0)
    return upload
