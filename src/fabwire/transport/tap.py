"""The trace tap: every chunk both ways, timestamped, as replayable JSONL.

File format, one JSON object per line:
  {"trace": "fabwire", "version": 1, "url": ..., "peer": ..., "started": ISO-8601, "device": kind}   (first line;
   "device", the protocol spoken — xyz, lineus or mmu — is absent from older captures)
  {"t": seconds since start, "dir": ">" (to the device) or "<" (from it), "data": bytes as latin-1 text}
  {"t": ..., "event": "eof" | "close" | "error", "detail": ...}
Latin-1 maps every byte to one code point, so JSON string escapes keep captures lossless and text stays readable.
"""

from __future__ import annotations

import contextlib
import json
import logging
import time
from collections.abc import Callable, Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import IO, Literal

import msgspec

from fabwire.errors import InputError, LinkClosed
from fabwire.transport.base import DEFAULT_READ_SIZE, Transport

Direction = Literal[">", "<"]
TO_DEVICE: Direction = ">"
FROM_DEVICE: Direction = "<"

wire_log = logging.getLogger("fabwire.wire")


class TraceRecord(msgspec.Struct, frozen=True):
    t: float
    direction: Direction | None
    data: bytes = b""
    event: str = ""
    detail: str = ""


class TraceWriter:
    """Appends records to a JSONL file; flushes each line so a crash keeps everything before it.

    A writer made by `to_file` reopens its file for appending when a record comes after `close`, so a client
    that reconnects (a new link, a new tap) keeps one capture.
    """

    def __init__(self, stream: IO[str], *, url: str, peer: str, path: Path | None = None,
                 device: str | None = None) -> None:
        self._stream = stream
        self._path = path
        self._start = time.monotonic()
        header = {
            "trace": "fabwire",
            "version": 1,
            "url": url,
            "peer": peer,
            "started": datetime.now(UTC).isoformat(timespec="milliseconds"),
        }
        if device is not None:
            header["device"] = device
        self._emit(header)

    @classmethod
    def to_file(cls, path: str | Path, *, url: str, peer: str, device: str | None = None) -> TraceWriter:
        """A writer to `path`, replacing an earlier capture there. Raises InputError for a file that cannot be
        written, and for an existing non-empty file that is no capture (`--trace part.gcode` must not destroy the
        G-code it was meant to go beside)."""
        if not _replaceable(Path(path)):
            raise InputError(f"{path} exists and is not a fabwire trace: not overwriting it (name another file)")
        try:
            stream = open(path, "w", encoding="utf-8")  # noqa: SIM115 - closed by close()
        except OSError as exc:
            raise InputError(f"cannot write trace file {path}: {exc.strerror}") from exc
        return cls(stream, url=url, peer=peer, path=Path(path), device=device)

    def _emit(self, obj: dict[str, object]) -> None:
        if self._stream.closed and self._path is not None:
            try:
                self._stream = open(self._path, "a", encoding="utf-8")  # noqa: SIM115 - closed by close()
            except OSError as exc:
                raise InputError(f"cannot write trace file {self._path}: {exc.strerror}") from exc
        try:
            self._stream.write(json.dumps(obj, ensure_ascii=True) + "\n")
            self._stream.flush()
        except OSError as exc:  # a full disk, a vanished mount: the capture cannot go on, say where and why
            raise InputError(f"cannot write trace file {self._path or 'stream'}: {exc.strerror or exc}") from exc

    def _now(self) -> float:
        return round(time.monotonic() - self._start, 6)

    def chunk(self, direction: Direction, data: bytes) -> None:
        self._emit({"t": self._now(), "dir": direction, "data": data.decode("latin-1")})

    def event(self, event: str, detail: str = "") -> None:
        self._emit({"t": self._now(), "event": event, "detail": detail})

    def close(self) -> None:
        if not self._stream.closed:
            with contextlib.suppress(OSError):  # what is left after a failed write: that failure was reported
                self._stream.close()


MAX_TRACE_LINE = 16 << 20
"""A record holds one read or write (at most 64 KiB, a few times that as JSON); longer lines are not records."""


def read_trace(path: str | Path, on_cut: Callable[[str], None] | None = None) -> Iterator[TraceRecord]:
    """Yield the records of a capture, reading one line at a time (memory stays that of one record).

    A last record cut off mid-line (the capturing process was killed while writing it) goes to `on_cut` as a
    sentence, when given, after the whole records. Raises InputError naming the line for a malformed record
    (the cut one too without `on_cut`), and for a file that cannot be read.
    """
    try:
        stream = open(path, encoding="utf-8", newline="\n")  # noqa: SIM115 - closed below
    except OSError as exc:
        raise InputError(f"cannot read trace file {path}: {exc.strerror}") from exc
    with stream:
        number = 0
        while True:
            try:
                line = stream.readline(MAX_TRACE_LINE + 1)
            except UnicodeDecodeError:
                raise InputError(f"{path} is not a fabwire trace (not UTF-8 text)") from None
            except OSError as exc:
                raise InputError(f"cannot read trace file {path}: {exc.strerror}") from exc
            if not line:
                return
            number += 1
            if len(line) > MAX_TRACE_LINE:
                raise InputError(f"{path}, line {number}: longer than any trace record")
            if on_cut is not None and not line.endswith("\n") and _cut_off(line):
                on_cut(f"{path}, line {number}: the last record is cut off (the capture stopped while writing it)")
                return
            if line.strip():
                record = _parse_record(path, number, line)
                if record is not None:
                    yield record


def _replaceable(path: Path) -> bool:
    """True for no file, an empty or special file (/dev/null, a pipe), or an earlier capture (its header line)."""
    try:
        if not path.is_file() or path.stat().st_size == 0:
            return True
        with open(path, "rb") as stream:
            first = stream.readline(4096)
    except OSError:
        return True  # opening it for writing says what is wrong
    return first.startswith((b'{"trace": "fabwire"', b'{"trace":"fabwire"'))


def trace_device(path: str | Path) -> str | None:
    """The device kind a capture's header names (`xyz`, `lineus`, `mmu`), or None when it names none. Reads the
    first line only; a file that is no capture is left for `read_trace` to refuse."""
    try:
        with open(path, encoding="utf-8", newline="\n") as stream:
            header = json.loads(stream.readline(MAX_TRACE_LINE + 1))
    except (OSError, ValueError, RecursionError):
        return None
    device = header.get("device") if isinstance(header, dict) else None
    return device if isinstance(device, str) else None


def _cut_off(line: str) -> bool:
    try:
        json.loads(line)
    except ValueError:
        return True
    return False


def _parse_record(path: str | Path, number: int, line: str) -> TraceRecord | None:
    try:
        obj = json.loads(line)
        if number == 1:
            if not isinstance(obj, dict) or obj.get("trace") != "fabwire":
                raise ValueError("missing the fabwire trace header")
            return None
        if "event" in obj:
            return TraceRecord(float(obj["t"]), None, event=str(obj["event"]), detail=str(obj.get("detail", "")))
        direction = obj["dir"]
        if direction not in (TO_DEVICE, FROM_DEVICE):
            raise ValueError(f"unknown direction {direction!r}")
        return TraceRecord(float(obj["t"]), direction, obj["data"].encode("latin-1"))
    except (ValueError, KeyError, TypeError, AttributeError, UnicodeEncodeError, RecursionError) as exc:
        raise InputError(f"{path}, line {number}: not a fabwire trace record ({exc})") from None


def replay_bytes(path: str | Path, direction: Direction) -> bytes:
    """All bytes that went one way, in order, exactly as they crossed the wire."""
    return b"".join(r.data for r in read_trace(path) if r.direction == direction)


class TapTransport(Transport):
    """Wraps a transport, recording every chunk to a `TraceWriter` and/or the `fabwire.wire` logger."""

    def __init__(self, inner: Transport, writer: TraceWriter | None = None, *, log: bool = True) -> None:
        self._inner = inner
        self._writer = writer
        self._log = log
        self.url = inner.url
        self.peer = inner.peer

    @property
    def closed(self) -> bool:
        return self._inner.closed

    def _record(self, direction: Direction, data: bytes) -> None:
        if self._writer is not None:
            self._writer.chunk(direction, data)
        if self._log and wire_log.isEnabledFor(logging.DEBUG):
            wire_log.debug("%s %s", direction, escape_text(data))

    async def read(self, max_bytes: int = DEFAULT_READ_SIZE) -> bytes:
        try:
            data = await self._inner.read(max_bytes)
        except LinkClosed as exc:
            if self._writer is not None:
                self._writer.event("eof", str(exc))
            raise
        self._record(FROM_DEVICE, data)
        return data

    async def write(self, data: bytes) -> None:
        self._record(TO_DEVICE, data)
        await self._inner.write(data)

    async def close(self) -> None:
        writer, self._writer = self._writer, None
        try:
            await self._inner.close()
        finally:
            if writer is not None:
                writer.event("close")
                writer.close()


_ESCAPES = {0x0D: "\\r", 0x0A: "\\n", 0x00: "\\0", 0x09: "\\t", 0x5C: "\\\\"}


def escape_text(data: bytes) -> str:
    """Printable ASCII as is, the usual control characters as \\r \\n \\0 \\t, everything else as \\xNN."""
    return "".join(
        _ESCAPES.get(b) or (chr(b) if 0x20 <= b < 0x7F else f"\\x{b:02x}") for b in data
    )
