"""Jobs: uploads kept under generated names in the state directory, and their records in the history.

A job record is `{"id", "device", "type" ("print" | "draw" | "text"), "filename" (as uploaded, shown only),
"stored" (the generated file name or None), "size_bytes", "params", "state" ("queued" | "running" | "done" |
"failed" | "cancelled" | "interrupted"), "created", "started", "finished" (ISO-8601), "progress_percent",
"time_left_s", "message", "file_meta" (the library's figures of the file: `print_time_s`, `filament_mm`,
`layers`, `slicer`; None for a file sent otherwise), "paused_s" (seconds spent paused, closed pauses),
"paused_since" and "resumed_at" (epoch seconds, agent clock, or None), "printer_elapsed" ([seconds the printer
reported, epoch when it first said so] or None)}`. Jobs that were running when the agent stopped are marked
"interrupted" at start.

An upload is written as it arrives to `uploads/.ID.part` (0600), at most `max_upload_bytes`, and renamed to
`uploads/ID.EXT` once complete; a stored file goes when its job record does (the history's retention), and a
`.part` nobody is writing is removed at the next sweep. A full disk is `DiskFull` (HTTP 507) and leaves nothing.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import os
import re
import secrets
import sqlite3
import tempfile
from pathlib import Path
from typing import Any, ClassVar

from fabwire.agent.core import now_iso, private_dir
from fabwire.agent.history import History
from fabwire.errors import FabwireError, InputError

log = logging.getLogger("fabwire.agent")

SUFFIX = re.compile(r"\.(gcode|gco|g|3w|svg|svgz|gc|nc|ngc)$", re.IGNORECASE)
"""The only extensions a stored upload may carry: the stored name is ours, its extension tells the planners
what the file is."""
SHOWN_NAME = 200
WRITE_BATCH = 1024 * 1024
"""Bytes gathered before one write to disk (a write is a thread hop)."""
DISK_FULL = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})
"""The OS's ways of saying a file cannot grow: no space, over quota, over the file-size limit (RLIMIT_FSIZE)."""
PART = ".part"


class UploadTooLarge(InputError):
    """An upload over the agent's size limit."""

    http_status: ClassVar[int] = 413


class DiskFull(FabwireError):
    """The agent's disk (its state directory) has no room for an upload."""

    http_status: ClassVar[int] = 507


class JobStore:
    def __init__(self, history: History, uploads: Path | None, max_upload_bytes: int) -> None:
        self.history = history
        self.max_upload_bytes = max_upload_bytes
        self._temp: tempfile.TemporaryDirectory[str] | None = None
        if uploads is None:
            self._temp = tempfile.TemporaryDirectory(prefix="fabwire-uploads-")
            uploads = Path(self._temp.name)
        self.uploads = uploads
        self._live: set[str] = set()
        """Names in `uploads` being written or not yet on record: the sweep leaves them alone."""
        history.after_prune.append(self.sweep)

    def sweep(self, db: sqlite3.Connection) -> None:
        """Remove stored uploads whose job record is gone and `.part` files nobody writes (on the history's
        worker thread, after each prune)."""
        kept = {row[0] for row in db.execute("SELECT json_extract(data, '$.stored') FROM jobs") if row[0]}
        try:
            names = os.listdir(self.uploads)
        except OSError:
            return
        for name in names:
            if name not in kept and name not in self._live:
                with contextlib.suppress(OSError):
                    (self.uploads / name).unlink()

    def writer(self, job_id: str, filename: str) -> UploadWriter:
        """A writer for job `job_id`'s upload named `filename` (its extension must be one SUFFIX allows)."""
        match = SUFFIX.search(filename or "")
        if match is None:
            raise InputError(f"cannot tell what {filename!r} is from its name")
        return UploadWriter(self, job_id, f"{job_id}{match.group(0).lower()}")

    async def recover(self) -> None:
        for job in await self.history.jobs(None, 10_000):
            if job["state"] in ("queued", "running"):
                job.update(state="interrupted", message="the agent stopped while the job ran")
                await self.history.save_job(job)

    async def create(self, device: str, job_type: str, filename: str | None, upload: UploadWriter | None,
                     params: dict[str, Any], job_id: str | None = None,
                     file_meta: dict[str, Any] | None = None) -> dict[str, Any]:
        """Record a new job (state "queued"); `upload` is its complete file, if it has one; `file_meta` the
        library's figures of that file."""
        job_id = job_id or new_job_id()
        shown = (filename or "")[:SHOWN_NAME].replace("\x00", "") or None
        job = {"id": job_id, "device": device, "type": job_type, "filename": shown,
               "stored": upload.name if upload else None, "size_bytes": upload.size if upload else None,
               "params": params, "state": "queued", "created": now_iso(), "started": None, "finished": None,
               "progress_percent": 0.0, "time_left_s": None, "message": None,
               "file_meta": dict(file_meta) if file_meta else None, "paused_s": 0.0, "paused_since": None,
               "resumed_at": None, "printer_elapsed": None}
        await self.history.save_job(job)
        if upload is not None:
            self._live.discard(upload.name)  # on record now: it goes with the record
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


def note_course(job: dict[str, Any], summary: dict[str, Any], now: float) -> None:
    """Follow a running job from one of its machine's states (`fabwire.agent.drivers.base` summary): its pauses
    ("paused_s", "paused_since", "resumed_at") and the printer's own elapsed time ("printer_elapsed", with when it
    first said that value: a da Vinci counts whole minutes). `now` is epoch seconds."""
    if job.get("state") != "running":
        return
    paused = summary.get("state") == "paused"
    since = job.get("paused_since")
    if paused and since is None:
        job["paused_since"] = now
    elif not paused and since is not None:
        job["paused_s"] = float(job.get("paused_s") or 0.0) + max(0.0, now - since)
        job["paused_since"] = None
        job["resumed_at"] = now
    elapsed = summary.get("elapsed_s")
    seen = job.get("printer_elapsed")
    if isinstance(elapsed, int | float) and not isinstance(elapsed, bool) and (seen is None or seen[0] != elapsed):
        job["printer_elapsed"] = [float(elapsed), now]


class JobNotFound(InputError):
    """No job with that id."""


def new_job_id() -> str:
    return secrets.token_hex(8)


class UploadWriter:
    """One upload on its way to disk: `write` chunks as they arrive, then `finish` (or `discard`).

    Raises UploadTooLarge past the store's limit, DiskFull when the disk refuses; either way the partial file
    is gone before the error leaves."""

    def __init__(self, store: JobStore, job_id: str, name: str) -> None:
        self.store = store
        self.job_id = job_id
        self.name = name
        self.part = f".{job_id}{PART}"
        self.size = 0
        self.path = store.uploads / name
        self._pending: list[bytes] = []
        self._pending_size = 0
        self._fd: int | None = None
        self._done = False
        store._live.update((self.name, self.part))

    async def write(self, chunk: bytes) -> None:
        if self._done:
            raise RuntimeError("the upload is already finished")
        self.size += len(chunk)
        if self.size > self.store.max_upload_bytes:
            self.discard()
            raise UploadTooLarge(f"the upload is over the limit of {self.store.max_upload_bytes:,} bytes "
                                 "(--max-upload)")
        self._pending.append(chunk)
        self._pending_size += len(chunk)
        if self._pending_size >= WRITE_BATCH:
            await self._flush()

    async def _flush(self) -> None:
        data = b"".join(self._pending)
        self._pending.clear()
        self._pending_size = 0
        try:
            await asyncio.to_thread(self._write, data)
        except OSError as exc:
            self.discard()
            raise self._refusal(exc) from None

    def _write(self, data: bytes) -> None:
        if self._fd is None:
            private_dir(self.store.uploads)
            self._fd = os.open(self.store.uploads / self.part, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        view = memoryview(data)
        while view:
            view = view[os.write(self._fd, view):]

    def _refusal(self, exc: OSError) -> DiskFull:
        if exc.errno in DISK_FULL:
            return DiskFull(f"no space left on the agent's disk for the upload ({os.strerror(exc.errno or 0)} in "
                            f"{self.store.uploads}): nothing was kept")
        return DiskFull(f"the agent cannot store the upload in {self.store.uploads}: {exc.strerror or exc}")

    async def finish(self) -> Path:
        """Write what is left, sync it, and give it its stored name."""
        if not self.size:
            self.discard()
            raise InputError("the upload is empty")
        await self._flush()

        def close() -> None:
            assert self._fd is not None
            try:
                os.fsync(self._fd)
            finally:
                os.close(self._fd)
                self._fd = None
            os.replace(self.store.uploads / self.part, self.path)

        try:
            await asyncio.to_thread(close)
        except OSError as exc:
            self.discard()
            raise self._refusal(exc) from None
        self._done = True
        self.store._live.discard(self.part)
        return self.path

    def discard(self) -> None:
        """Remove whatever was written (partial or complete but never on record); safe to call twice."""
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None
        for name in (self.part, self.name):
            with contextlib.suppress(OSError):
                (self.store.uploads / name).unlink()
            self.store._live.discard(name)
        self._pending.clear()
        self._done = True
