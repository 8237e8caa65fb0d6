"""The file library and the print queue of each machine, shared by every door.

Uploads are kept per machine under `STATE/library/<machine id>/` (stored under generated names; the name a
slicer gave is only shown), with the figures the machine's intake reads (`META_FIGURES`; see
`Driver.describe_upload`) and the slicer's embedded previews (see `fabwire.thumbnails`), or else the machine's own
picture of the job (a drawing's plan). The index of a machine is `index.json` there: `{"files": {NAME: entry},
"queue": [NAME …], "queue_enabled": bool, "selected": NAME | None}`. An entry is `{"name", "size", "uploaded"
(epoch s), "stored", "sha256", "meta": {figure: value | None, for those of META_FIGURES the machine's kind tells},
"thumbnails": [{"width", "height", "format", "stored"}], "prints": {"success", "failure", "last": {"date" (epoch s),
"success"} | None}}`.

The library keeps at most `keep` files per machine: the oldest that is neither queued nor printing goes first.
With the queue turned on, a print asked for while the machine is busy waits in the queue and starts once the
machine is idle again (a da Vinci's finished print acknowledged); turned off (the default), such a request is
refused with the reason (`MachineNotReady`, HTTP 409), never accepted and then failed.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import json
import logging
import os
import re
import secrets
import shutil
import tempfile
import time
import unicodedata
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

from fabwire.agent.model import Machines, MachineView, TakesNoJobs
from fabwire.agent.offload import in_thread
from fabwire.checks import ASCII_BLANKS, FILE_HIDDEN, FILE_NAME_MAX, FILE_RESERVED, refuse
from fabwire.errors import InputError, excerpt
from fabwire.thumbnails import read_thumbnails

if TYPE_CHECKING:
    from fabwire.agent.core import Agent
    from fabwire.agent.session import JobClaim

log = logging.getLogger("fabwire.agent")
KEEP = 100
META_FIGURES = ("print_time_s", "filament_mm", "layers", "slicer", "pen_down_mm", "strokes")
"""What a file says of its job, where the machine's intake can tell (None where a file of that kind does not say):
a 3D print's time (s), filament (mm), layer count and slicer; a drawing's time (s), pen-down length (mm) and stroke
count."""
CHUNK = 1 << 20
"""Files kept per machine by default."""
QUEUE_MAX = 100
NAME_MAX = FILE_NAME_MAX
INDEX = "index.json"
STAGED = ".upload-"
"""The name prefix of an upload a door is still writing into a machine's files (see `staging`)."""


@dataclass(frozen=True, slots=True)
class SlicerOutput:
    suffix: str
    advice: str
    """What the file is and what to change in the slicer so it sends plain G-code."""
    source: str


SLICER_OUTPUTS: tuple[SlicerOutput, ...] = (
    SlicerOutput(".bgcode", "that is binary G-code; in PrusaSlicer untick Printer Settings → General → Firmware → "
                 "Supports binary G-code, and send again", "PrusaSlicer 2.7 release notes (binary G-code, .bgcode)"),
    SlicerOutput(".3mf", "that is a 3MF project (OrcaSlicer can send a plate as .gcode.3mf); export or send "
                 "plain G-code", "OrcaSlicer src/slic3r/Utils/OctoPrint.cpp (plateindex of a .gcode.3mf)"),
    SlicerOutput(".ufp", "that is an Ultimaker Format Package; turn off the UFP transfer of Cura's OctoPrint plugin",
                 "fieldOfView/Cura-OctoPrintPlugin OctoPrintOutputDevice.py (_transfer_as_ufp)"),
    SlicerOutput(".stl", "that is a model, not a print: slice it first and send the G-code", "STL (3D Systems)"),
)
"""Files slicers can be set to send that no da Vinci prints, with what to change in the slicer."""


class FileNotInLibrary(InputError):
    """No file of that name in the machine's library (HTTP 404)."""

    http_status = 404


def require_plain_name(name: str) -> None:
    """InputError (rule `file-hidden`) when an upload's name holds a character that hides or changes what it
    shows; every door's uploads are named to the owner (jobs, history, the dashboard), whether kept or not."""
    hidden = FILE_HIDDEN.search(name)
    if hidden:
        char = hidden.group()
        raise refuse("file-hidden", char=f"U+{ord(char):04X} ({unicodedata.name(char, 'unnamed')})")


def clean_name(name: str, folder: str = "") -> str:
    """The library name of an upload: `folder/name` with `/` separators, no empty, `.` or `..` parts, no
    control, reserved or hidden characters (the `file-*` rows of `fabwire.checks.RULES`), in Unicode NFC (macOS
    and copies from PDFs spell accents decomposed); InputError otherwise."""
    require_plain_name(f"{folder}/{name}")  # first: a control character is named as such, not as a bad part
    blanks = ASCII_BLANKS  # only what a terminal's copy brings: other blanks are refused, not taken off
    parts = [p for p in f"{folder.strip(blanks).strip('/')}/{name.strip(blanks)}".split("/") if p.strip()]
    if not parts:
        raise refuse("file-empty")
    for part in parts:
        if part in (".", "..") or FILE_RESERVED.search(part) or part != part.strip():
            raise refuse("file-part", part=excerpt(part, 60))
    joined = unicodedata.normalize("NFC", "/".join(parts))  # `é` typed or composed from `e` + U+0301: one file
    if len(joined) > NAME_MAX:
        raise refuse("file-length", length=len(joined))
    return joined


class Library:
    def __init__(self, agent: Agent, root: Path | None, keep: int = KEEP) -> None:
        self.agent = agent
        self.machines = Machines(agent)
        self.keep = keep
        self._temp: tempfile.TemporaryDirectory[str] | None = None
        if root is None:
            self._temp = tempfile.TemporaryDirectory(prefix="fabwire-library-")
            root = Path(self._temp.name)
        self.root = root
        self._indexes: dict[str, dict[str, Any]] = {}
        self._locks: dict[str, asyncio.Lock] = {}
        self._watcher: asyncio.Task[None] | None = None
        self._job_files: dict[str, tuple[str, str]] = {}
        """job id → (machine id, library name): whose print statistics a job's end updates."""
        self._ended_files: dict[str, tuple[str, tuple[str, str]]] = {}
        """device → (its last ended job's id, (device, file name)): the doors still name a finished job's file."""

    # ------------------------------------------------------------------------------------------ lifecycle

    async def start(self) -> None:
        """Follow the agent's events; uploads a door staged when the agent last stopped are removed."""
        for leftover in self.root.glob(f"*/files/{STAGED}*"):
            with contextlib.suppress(OSError):
                leftover.unlink()
        self.machines.start()
        self._watcher = asyncio.create_task(self._watch(), name="library-watch")

    async def stop(self) -> None:
        if self._watcher is not None:
            self._watcher.cancel()
            with contextlib.suppress(BaseException):
                await self._watcher
            self._watcher = None

    # ------------------------------------------------------------------------------------------ reading

    def index(self, device_id: str) -> dict[str, Any]:
        if device_id not in self._indexes:
            path = self.root / _safe_dir(device_id) / INDEX
            try:
                loaded = json.loads(path.read_text(encoding="utf-8"))
                if not isinstance(loaded, dict) or not isinstance(loaded.get("files"), dict):
                    raise ValueError("not an index")
            except FileNotFoundError:
                loaded = {}
            except (OSError, ValueError) as exc:
                log.warning("library index %s unreadable (%s): starting it afresh", path, exc)
                loaded = {}
            loaded.setdefault("files", {})
            loaded.setdefault("queue", [])
            loaded.setdefault("queue_enabled", False)
            loaded.setdefault("selected", None)
            self._indexes[device_id] = loaded
        return self._indexes[device_id]

    def files(self, device_id: str) -> list[dict[str, Any]]:
        """Newest first."""
        return sorted(self.index(device_id)["files"].values(), key=lambda e: -e["uploaded"])

    def get(self, device_id: str, name: str) -> dict[str, Any]:
        entry = self.index(device_id)["files"].get(unicodedata.normalize("NFC", name.strip("/")))
        if entry is None:
            raise FileNotInLibrary(f"no file {excerpt(name, 80)} in the library of {device_id}")
        return dict(entry)

    def path_of(self, device_id: str, entry: dict[str, Any]) -> Path:
        return self.root / _safe_dir(device_id) / "files" / str(entry["stored"])

    def thumbnail(self, device_id: str, name: str, index: int = -1) -> tuple[bytes, str]:
        """(image bytes, media type) of a file's preview, the largest by default; PNG for QOI previews."""
        thumbs = self.get(device_id, name)["thumbnails"]
        if not thumbs or not -len(thumbs) <= index < len(thumbs):
            raise FileNotInLibrary(f"{excerpt(name, 80)} has no preview {index}")
        ordered = sorted(thumbs, key=lambda t: t["width"] * t["height"])
        thumb = ordered[index]
        path = self.root / _safe_dir(device_id) / "thumbs" / thumb["stored"]
        media = "image/jpeg" if thumb["stored"].endswith(".jpg") else "image/png"
        return path.read_bytes(), media

    def file_of_job(self, job: dict[str, Any] | None) -> dict[str, Any] | None:
        """The library entry a job prints (None for a job started otherwise, or a file since removed)."""
        owner = self._job_files.get(job["id"]) if job else None
        if owner is None and job is not None:
            ended = self._ended_files.get(str(job.get("device")))
            owner = ended[1] if ended is not None and ended[0] == job["id"] else None
        if owner is None:
            return None
        entry = self.index(owner[0])["files"].get(owner[1])
        return dict(entry) if entry is not None else None

    def queue(self, device_id: str) -> list[str]:
        return list(self.index(device_id)["queue"])

    def queue_enabled(self, device_id: str) -> bool:
        return bool(self.index(device_id)["queue_enabled"])

    def selected(self, device_id: str) -> str | None:
        name = self.index(device_id)["selected"]
        return name if name in self.index(device_id)["files"] else None

    def disk(self) -> tuple[int, int]:
        """(free bytes, total bytes) where the library lives."""
        self.root.mkdir(parents=True, exist_ok=True)
        usage = shutil.disk_usage(self.root)
        return usage.free, usage.total

    # ------------------------------------------------------------------------------------------ changing

    def _require_takes(self, view: MachineView, name: str) -> None:
        """InputError unless the machine takes files named so, saying what a slicer's other outputs are."""
        job_types = self.agent.session(view.id).driver.job_types
        suffix = Path(name).suffix.lower()
        if suffix not in job_types:
            accepted = ", ".join(sorted(job_types))
            advice = next((a.advice for a in SLICER_OUTPUTS if a.suffix == suffix), None)
            raise InputError(f"{view.name} takes {accepted} files, not {excerpt(Path(name).name, 80)}"
                             + (f": {advice}" if advice else ""))

    def claim_print(self, device: str, name: str) -> JobClaim | None:
        """Claim the machine for printing the upload `name` now (atomic; MachineNotReady/DeviceBusy, HTTP 409,
        with the reason), or None when its queue is on and it cannot start now (the upload is to wait)."""
        view = self.machines.view(device)
        self._require_takes(view, clean_name(name))
        if self.queue_enabled(view.id) and view.refusal() is not None:
            return None
        return self.agent.claim_job(view.id, Path(clean_name(name)).name)

    def staging(self, device: str) -> Path:
        """Where a door may write an upload for `add` to adopt (same file system: a rename, not a copy)."""
        return self.root / _safe_dir(self.machines.view(device).id) / "files"

    async def add(self, device: str, name: str, src: BinaryIO | Path, *, start: bool = False,
                  select: bool = False, claim: JobClaim | None = None, claim_fed: bool = False) -> dict[str, Any]:
        """Keep an upload (read from `src`, or a file written in `staging` and moved into place) in the machine's
        library, and select and/or start it.

        Returns `{"file": entry, "job": job | None, "queued": bool}`. With `start`, the machine is claimed first
        (or `claim` is the one `claim_print` made before the upload was read; `claim_fed`: the upload was
        written to it as it arrived)
        (`Agent.claim_job`: atomic; `MachineNotReady`/`DeviceBusy`, HTTP 409, with the reason when it cannot
        print now) and nothing is kept when it refuses, unless its queue is on (then the file waits). InputError
        for a name or a file the machine cannot take (the intake's own words); nothing is kept then either."""
        view = self.machines.view(device)
        view.require_files()
        device_id = view.id
        name = clean_name(name)
        session = self.agent.session(device_id)
        self._require_takes(view, name)
        queue = start and claim is None and self.queue_enabled(device_id) and view.refusal() is not None
        if start and not queue and claim is None:
            claim = self.agent.claim_job(device_id, Path(name).name)
        async with claim if claim is not None else contextlib.nullcontext():
            stored = await asyncio.to_thread(self._copy_in, device_id, name, src)
            try:
                meta = await session.link.describe_upload(Path(name).name, stored, check=claim is None)
                entry = await in_thread(self._describe, device_id, name, stored, meta)
                job = await self._feed(claim, device_id, entry, fed=claim_fed) if claim is not None else None
            except BaseException:
                with contextlib.suppress(OSError):
                    stored.unlink()
                raise
        async with self._lock(device_id):
            index = self.index(device_id)
            old = index["files"].get(name)
            index["files"][name] = entry
            if select or start:
                index["selected"] = name
            self._trim(device_id, index, old)
            if queue:
                if len(index["queue"]) >= QUEUE_MAX:
                    raise InputError(f"the queue of {view.name} holds {QUEUE_MAX} files already")
                index["queue"].append(name)
            await self._save(device_id)
        return {"file": dict(entry), "job": job, "queued": queue}

    async def start_print(self, device: str, name: str) -> dict[str, Any]:
        """Start a kept file now: the job record; MachineNotReady (409) with the reason when the machine cannot."""
        view = self.machines.view(device)
        entry = self.get(view.id, name)
        async with self.agent.claim_job(view.id, Path(entry["name"]).name) as claim:
            job = await self._feed(claim, view.id, entry)
        async with self._lock(view.id):
            self.index(view.id)["selected"] = entry["name"]
            await self._save(view.id)
        return job

    async def select(self, device: str, name: str | None) -> None:
        view = self.machines.view(device)
        if name is not None:
            name = self.get(view.id, name)["name"]
        async with self._lock(view.id):
            self.index(view.id)["selected"] = name
            await self._save(view.id)

    async def delete(self, device: str, name: str) -> None:
        view = self.machines.view(device)
        entry = self.get(view.id, name)
        if view.job is not None and self._job_files.get(view.job["id"]) == (view.id, entry["name"]):
            raise TakesNoJobs(f"{entry['name']} is printing on {view.name}: cancel the print first")
        async with self._lock(view.id):
            self._remove(view.id, self.index(view.id), entry["name"])
            await self._save(view.id)

    async def set_queue(self, device: str, *, enabled: bool | None = None, order: list[str] | None = None
                        ) -> dict[str, Any]:
        """Turn the queue on/off and/or set its order (`order` may only hold names already queued or kept)."""
        view = self.machines.view(device)
        async with self._lock(view.id):
            index = self.index(view.id)
            if order is not None:
                missing = [n for n in order if n not in index["files"]]
                if missing:
                    raise FileNotInLibrary(f"no file {excerpt(missing[0], 80)} in the library of {view.name}")
                if len(order) > QUEUE_MAX:
                    raise InputError(f"a queue holds at most {QUEUE_MAX} files")
                index["queue"] = list(order)
            if enabled is not None:
                index["queue_enabled"] = enabled
            await self._save(view.id)
        if enabled:
            await self._start_next(view.id)
        return {"enabled": self.queue_enabled(view.id), "queue": self.queue(view.id)}

    async def start_next(self, device: str) -> dict[str, Any]:
        """Start the first queued file now (whether or not the queue is on); MachineNotReady with the reason."""
        view = self.machines.require_ready(device)
        queue = self.queue(view.id)
        if not queue:
            raise InputError(f"the queue of {view.name} is empty")
        job = await self.start_print(view.id, queue[0])
        async with self._lock(view.id):
            with contextlib.suppress(ValueError):
                self.index(view.id)["queue"].remove(queue[0])
            await self._save(view.id)
        return job

    # ------------------------------------------------------------------------------------------ plumbing

    async def _feed(self, claim: JobClaim, device_id: str, entry: dict[str, Any], *, fed: bool = False
                    ) -> dict[str, Any]:
        """Stream a kept file into a claim (unless it was `fed` as it arrived) and start the job (the claim's
        own checks run on its copy)."""
        if not fed:
            with self.path_of(device_id, entry).open("rb") as handle:
                while chunk := await asyncio.to_thread(handle.read, CHUNK):
                    await claim.write(chunk)
        job = await claim.start(file_meta=entry.get("meta"))
        self._job_files[job["id"]] = (device_id, entry["name"])
        return job

    async def _start_next(self, device_id: str) -> None:
        """Start the head of the queue when the queue is on and the machine is ready; quietly wait otherwise."""
        if not self.queue_enabled(device_id) or not self.queue(device_id):
            return
        with contextlib.suppress(KeyError):
            if self.machines.view(device_id).refusal() is not None:
                return
        try:
            await self.start_next(device_id)
        except InputError as exc:
            log.info("queue of %s waits: %s", device_id, exc)

    async def _watch(self) -> None:
        """Print statistics when a library job ends; the next queued file when a machine becomes ready."""
        subscription = self.agent.subscribe()
        try:
            async for event in subscription:
                if event["type"] == "job":
                    job = event["job"]
                    owner = self._job_files.get(job["id"])
                    if owner is not None and job["state"] in ("done", "failed", "cancelled", "interrupted"):
                        del self._job_files[job["id"]]
                        self._ended_files[owner[0]] = (job["id"], owner)
                        await self._count(owner, job["state"] == "done")
                elif event["type"] == "state":
                    await self._start_next(event["device"])
        finally:
            subscription.close()

    async def _count(self, owner: tuple[str, str], success: bool) -> None:
        device_id, name = owner
        async with self._lock(device_id):
            entry = self.index(device_id)["files"].get(name)
            if entry is None:
                return
            prints = entry["prints"]
            prints["success" if success else "failure"] += 1
            prints["last"] = {"date": time.time(), "success": success}
            await self._save(device_id)

    def _copy_in(self, device_id: str, name: str, src: BinaryIO | Path) -> Path:
        """The upload copied (or, staged, moved) into the library under a generated name, at most the agent's
        upload limit."""
        from fabwire.agent.jobs import UploadTooLarge

        folder = self.root / _safe_dir(device_id) / "files"
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{secrets.token_hex(8)}{Path(name).suffix.lower()}"
        limit = self.agent.jobs.max_upload_bytes
        if isinstance(src, Path):
            size = src.stat().st_size
            if size > limit:
                raise UploadTooLarge(f"the upload is over the limit of {limit:,} bytes")
            if not size:
                raise InputError("the upload is empty")
            os.replace(src, path)
            return path
        size = 0
        try:
            with path.open("wb") as out:
                while chunk := src.read(CHUNK):
                    size += len(chunk)
                    if size > limit:
                        raise UploadTooLarge(f"the upload is over the limit of {limit:,} bytes")
                    out.write(chunk)
            if not size:
                raise InputError("the upload is empty")
        except BaseException:
            with contextlib.suppress(OSError):
                path.unlink()
            raise
        return path

    def _describe(self, device_id: str, name: str, path: Path, meta: dict[str, Any]) -> dict[str, Any]:
        """The entry of a copied upload, given what the driver's `describe_upload` said of it (`meta`): its figures,
        the previews, the checksum."""
        base = self.root / _safe_dir(device_id)
        digest = hashlib.sha256()
        with path.open("rb") as handle:
            while chunk := handle.read(CHUNK):
                digest.update(chunk)
            handle.seek(0)
            found = read_thumbnails(handle)
        thumbs = []
        picture = meta.get("picture")
        if picture is not None and not found:  # the machine's own picture of what it will do, e.g. a drawing's plan
            image, (width, height) = picture
            thumb_name = f"{path.stem}-{width}x{height}.png"
            (base / "thumbs").mkdir(parents=True, exist_ok=True)
            (base / "thumbs" / thumb_name).write_bytes(image)
            thumbs.append({"width": width, "height": height, "format": "PNG", "stored": thumb_name,
                           "size": len(image)})
        for thumb in found:
            try:
                image, _ = thumb.web_image()
            except (OSError, ValueError):
                continue
            thumb_name = f"{path.stem}-{thumb.width}x{thumb.height}{thumb.web_suffix}"
            (base / "thumbs").mkdir(parents=True, exist_ok=True)
            (base / "thumbs" / thumb_name).write_bytes(image)
            thumbs.append({"width": thumb.width, "height": thumb.height, "format": thumb.format,
                           "stored": thumb_name, "size": len(image)})
        return {"name": name, "size": path.stat().st_size, "uploaded": time.time(), "stored": path.name,
                "sha256": digest.hexdigest(),
                "meta": {k: meta[k] for k in META_FIGURES if k in meta},
                "thumbnails": thumbs, "prints": {"success": 0, "failure": 0, "last": None}}

    def _remove(self, device_id: str, index: dict[str, Any], name: str) -> None:
        entry = index["files"].pop(name, None)
        index["queue"] = [n for n in index["queue"] if n != name]
        if index["selected"] == name:
            index["selected"] = None
        if entry is not None:
            self._unlink(device_id, entry)

    def _unlink(self, device_id: str, entry: dict[str, Any]) -> None:
        base = self.root / _safe_dir(device_id)
        with contextlib.suppress(OSError):
            (base / "files" / entry["stored"]).unlink()
        for thumb in entry["thumbnails"]:
            with contextlib.suppress(OSError):
                (base / "thumbs" / thumb["stored"]).unlink()

    def _trim(self, device_id: str, index: dict[str, Any], replaced: dict[str, Any] | None) -> None:
        if replaced is not None:
            self._unlink(device_id, replaced)
        busy = {name for dev, name in self._job_files.values() if dev == device_id} | set(index["queue"])
        spare = sorted((e for e in index["files"].values() if e["name"] not in busy), key=lambda e: e["uploaded"])
        while len(index["files"]) > self.keep and spare:
            self._remove(device_id, index, spare.pop(0)["name"])

    async def _save(self, device_id: str) -> None:
        text = json.dumps(self.index(device_id), indent=1)
        await asyncio.to_thread(_write_atomic, self.root / _safe_dir(device_id) / INDEX, text)

    def _lock(self, device_id: str) -> asyncio.Lock:
        return self._locks.setdefault(device_id, asyncio.Lock())


def _safe_dir(device_id: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]", "_", device_id).lstrip(".") or "_"


def _write_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, temp = tempfile.mkstemp(dir=path.parent, prefix=".index-")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(temp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temp)
        raise
