"""History in SQLite (the state directory's `history.sqlite3`): samples, events, jobs and device ids.

Writes are buffered and flushed twice a second in one transaction on a single worker thread, so a bench of a
thousand machines costs one commit per flush, not one per poll. A sample equal to the device's previous one is
kept only every `SAME_SAMPLE_EVERY_S`, and rows older than the retention are deleted each minute.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import json
import os
import sqlite3
import time
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any, TypeVar

from fabwire.agent.core import private_dir
from fabwire.errors import ConfigError

T = TypeVar("T")
FLUSH_EVERY_S = 0.5
PRUNE_EVERY_S = 60.0
SAME_SAMPLE_EVERY_S = 30.0
SAMPLE_FIELDS = ("state", "extruder_temp_c", "extruder_target_c", "bed_temp_c", "bed_target_c", "progress_percent",
                 "time_left_s")
KEPT_EVENTS = frozenset({"online", "offline", "event", "error", "job"})
"""State events are not stored as events: their numbers are the samples."""

SCHEMA = """
CREATE TABLE IF NOT EXISTS samples (device TEXT NOT NULL, ts REAL NOT NULL, state TEXT, extruder_temp_c REAL,
    extruder_target_c REAL, bed_temp_c REAL, bed_target_c REAL, progress_percent REAL, time_left_s REAL);
CREATE INDEX IF NOT EXISTS samples_device_ts ON samples (device, ts);
CREATE TABLE IF NOT EXISTS events (device TEXT NOT NULL, ts REAL NOT NULL, type TEXT NOT NULL, data TEXT NOT NULL);
CREATE INDEX IF NOT EXISTS events_device_ts ON events (device, ts);
CREATE TABLE IF NOT EXISTS jobs (id TEXT PRIMARY KEY, device TEXT NOT NULL, created REAL NOT NULL,
    data TEXT NOT NULL);
CREATE INDEX IF NOT EXISTS jobs_device ON jobs (device, created);
CREATE TABLE IF NOT EXISTS devices (kind TEXT NOT NULL, address TEXT NOT NULL, id TEXT NOT NULL,
    info TEXT NOT NULL, PRIMARY KEY (kind, address));
"""


def epoch(iso: str) -> float:
    """Epoch seconds of an ISO-8601 time (`fabwire.agent.core.now_iso`'s form, "Z" or an offset)."""
    return datetime.fromisoformat(iso.replace("Z", "+00:00")).timestamp()


class History:
    def __init__(self, path: Path | None, *, retention_s: float) -> None:
        self.path = path
        self.retention_s = retention_s
        self._pool = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="fabwire-history")
        self._db: sqlite3.Connection | None = None
        self._samples: list[tuple[Any, ...]] = []
        self._events: list[tuple[Any, ...]] = []
        self._last: dict[str, tuple[float, tuple[Any, ...]]] = {}
        self._task: asyncio.Task[None] | None = None
        self.after_prune: list[Callable[[sqlite3.Connection], None]] = []
        """Run on the worker thread after each prune (the job store removes the uploads of pruned jobs)."""

    async def _call(self, func: Callable[[sqlite3.Connection], T]) -> T:
        def run() -> T:
            assert self._db is not None
            return func(self._db)

        return await asyncio.get_running_loop().run_in_executor(self._pool, run)

    async def open(self) -> None:
        def connect() -> sqlite3.Connection:
            if self.path is not None:
                private_dir(self.path.parent)
                os.close(os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600))  # SQLite gives -wal and -shm its mode
            db = sqlite3.connect(str(self.path) if self.path else ":memory:", check_same_thread=False)
            db.executescript("PRAGMA journal_mode=WAL; PRAGMA synchronous=NORMAL;" + SCHEMA)
            return db

        try:
            self._db = await asyncio.get_running_loop().run_in_executor(self._pool, connect)
        except (sqlite3.Error, OSError) as exc:
            raise ConfigError(f"cannot open the history database {self.path}: {exc}") from None
        await self._call(self._prune)
        self._task = asyncio.create_task(self._flusher(), name="history-flush")

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        if self._db is not None:
            await self._call(self._flush)
            await self._call(lambda db: db.close())
            self._db = None

    # ------------------------------------------------------------------------------------------ writing

    def record_sample(self, device: str, ts: float, summary: dict[str, Any]) -> None:
        values = tuple(summary.get(k) for k in SAMPLE_FIELDS)
        last = self._last.get(device)
        if last is not None and last[1] == values and ts - last[0] < SAME_SAMPLE_EVERY_S:
            return
        self._last[device] = (ts, values)
        self._samples.append((device, ts, *values))

    def record_event(self, event: dict[str, Any]) -> None:
        if event["type"] in KEPT_EVENTS and not event.get("stroke") and not event.get("preview"):
            self._events.append((event["device"], epoch(event["ts"]), event["type"], json.dumps(event)))

    async def _flusher(self) -> None:
        last_prune = time.monotonic()
        while True:
            await asyncio.sleep(FLUSH_EVERY_S)
            await self._call(self._flush)
            if time.monotonic() - last_prune > PRUNE_EVERY_S:
                last_prune = time.monotonic()
                await self._call(self._prune)

    def _flush(self, db: sqlite3.Connection) -> None:
        samples, self._samples = self._samples, []
        events, self._events = self._events, []
        if not samples and not events:
            return
        with db:
            db.executemany(f"INSERT INTO samples VALUES (?, ?, {', '.join('?' * len(SAMPLE_FIELDS))})", samples)
            db.executemany("INSERT INTO events VALUES (?, ?, ?, ?)", events)

    def _prune(self, db: sqlite3.Connection) -> None:
        cutoff = time.time() - self.retention_s
        with db:
            db.execute("DELETE FROM samples WHERE ts < ?", (cutoff,))
            db.execute("DELETE FROM events WHERE ts < ?", (cutoff,))
            db.execute("DELETE FROM jobs WHERE created < ? AND json_extract(data, '$.state') != 'running'",
                       (cutoff,))
        for hook in self.after_prune:
            hook(db)

    # ------------------------------------------------------------------------------------------ reading

    async def samples(self, device: str, since: float, until: float, limit: int) -> list[dict[str, Any]]:
        """Samples of `device` with since <= ts <= until (epoch seconds), the newest `limit`, oldest first."""
        await self._call(self._flush)
        rows = await self._call(lambda db: db.execute(
            "SELECT * FROM (SELECT ts, " + ", ".join(SAMPLE_FIELDS) + " FROM samples WHERE device = ? AND ts >= ? "
            "AND ts <= ? ORDER BY ts DESC LIMIT ?) ORDER BY ts", (device, since, until, limit)).fetchall())
        return [dict(zip(("ts", *SAMPLE_FIELDS), row, strict=True)) for row in rows]

    async def events(self, device: str, since: float, until: float, limit: int) -> list[dict[str, Any]]:
        await self._call(self._flush)
        rows = await self._call(lambda db: db.execute(
            "SELECT data FROM (SELECT ts, data FROM events WHERE device = ? AND ts >= ? AND ts <= ? "
            "ORDER BY ts DESC LIMIT ?) ORDER BY ts", (device, since, until, limit)).fetchall())
        return [json.loads(row[0]) for row in rows]

    # ------------------------------------------------------------------------------------------ devices and jobs

    async def known_id(self, kind: str, address: str) -> str | None:
        row = await self._call(lambda db: db.execute("SELECT id FROM devices WHERE kind = ? AND address = ?",
                                                     (kind, address)).fetchone())
        return str(row[0]) if row else None

    async def remember_device(self, info: Any) -> None:
        data = json.dumps(info.to_dict())

        def write(db: sqlite3.Connection) -> None:
            with db:
                db.execute("INSERT OR REPLACE INTO devices VALUES (?, ?, ?, ?)", (info.kind, info.address, info.id,
                                                                                  data))

        await self._call(write)

    async def save_job(self, job: dict[str, Any]) -> None:
        data = json.dumps(job)

        def write(db: sqlite3.Connection) -> None:
            with db:
                db.execute("INSERT OR REPLACE INTO jobs VALUES (?, ?, ?, ?)",
                           (job["id"], job["device"], epoch(job["created"]), data))

        await self._call(write)

    async def jobs(self, device: str | None, limit: int) -> list[dict[str, Any]]:
        """Newest first."""
        args: tuple[Any, ...]
        if device is None:
            query, args = "SELECT data FROM jobs ORDER BY created DESC LIMIT ?", (limit,)
        else:
            query, args = "SELECT data FROM jobs WHERE device = ? ORDER BY created DESC LIMIT ?", (device, limit)
        rows = await self._call(lambda db: db.execute(query, args).fetchall())
        return [json.loads(row[0]) for row in rows]

    async def job(self, job_id: str) -> dict[str, Any] | None:
        row = await self._call(lambda db: db.execute("SELECT data FROM jobs WHERE id = ?", (job_id,)).fetchone())
        return json.loads(row[0]) if row else None
