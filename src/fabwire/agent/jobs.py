"""Jobs: uploads kept under generated names in the state directory, and their records in the history.

A job record is `{"id", "device", "type" ("print" | "draw" | "text"), "filename" (as uploaded, shown only),
"stored" (the generated file name or None), "size_bytes", "params", "state" ("queued" | "running" | "done" |
"failed" | "cancelled" | "interrupted"), "created", "started", "finished" (ISO-8601), "progress_percent",
"time_left_s", "message"}`. Jobs that were running when the agent stopped are marked "interrupted" at start.
"""

from __future__ import annotations

import re
import secrets
import tempfile
from pathlib import Path
from typing import Any

from fabwire.agent.core import now_iso
from fabwire.agent.history import History
from fabwire.errors import InputError

SUFFIX = re.compile(r"\.(gcode|gco|g|3w|svg|svgz|gc|nc|ngc)$", re.IGNORECASE)
"""The only extensions a stored upload may carry: the stored name is ours, its extension tells the planners
what the file is."""
SHOWN_NAME = 200


class UploadTooLarge(InputError):
    """An upload over the agent's size limit."""


class JobStore:
    def __init__(self, history: History, uploads: Path | None, max_upload_bytes: int) -> None:
        self.history = history
        self.max_upload_bytes = max_upload_bytes
        self._temp: tempfile.TemporaryDirectory[str] | None = None
        if uploads is None:
            self._temp = tempfile.TemporaryDirectory(prefix="fabwire-uploads-")
            uploads = Path(self._temp.name)
        self.uploads = uploads

    async def recover(self) -> None:
        for job in await self.history.jobs(None, 10_000):
            if job["state"] in ("queued", "running"):
                job.update(state="interrupted", message="the agent stopped while the job ran")
                await self.history.save_job(job)

    async def create(self, device: str, job_type: str, filename: str | None, data: bytes | None,
                     params: dict[str, Any]) -> dict[str, Any]:
        job_id = secrets.token_hex(8)
        stored = None
        if data is not None:
            if len(data) > self.max_upload_bytes:
                raise UploadTooLarge(f"the upload is {len(data):,} bytes; the limit is {self.max_upload_bytes:,}")
            if not data:
                raise InputError("the upload is empty")
            match = SUFFIX.search(filename or "")
            if match is None:
                raise InputError(f"cannot tell what {filename!r} is from its name")
            stored = f"{job_id}{match.group(0).lower()}"
            self.uploads.mkdir(parents=True, exist_ok=True)
            (self.uploads / stored).write_bytes(data)
        shown = (filename or "")[:SHOWN_NAME].replace("\x00", "") or None
        job = {"id": job_id, "device": device, "type": job_type, "filename": shown, "stored": stored,
               "size_bytes": len(data) if data is not None else None, "params": params, "state": "queued",
               "created": now_iso(), "started": None, "finished": None, "progress_percent": 0.0,
               "time_left_s": None, "message": None}
        await self.history.save_job(job)
        return job

    def path_of(self, job: dict[str, Any]) -> Path | None:
        stored = job.get("stored")
        return self.uploads / stored if stored else None

    async def save(self, job: dict[str, Any]) -> None:
        await self.history.save_job(job)

    async def get(self, job_id: str) -> dict[str, Any]:
        job = await self.history.job(job_id)
        if job is None:
            raise JobNotFound(f"no job {job_id!r}")
        return job

    async def list(self, device: str | None = None, limit: int = 100) -> list[dict[str, Any]]:
        return await self.history.jobs(device, limit)


class JobNotFound(InputError):
    """No job with that id."""
