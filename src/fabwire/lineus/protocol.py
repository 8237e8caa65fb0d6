"""Line-us TCP protocol, both roles, without I/O.

Host → device: one G-code line ended by any run of `\\r`, `\\n`, `\\0`. Device → host: `hello …`, `ok …` or
`error …` followed by ` KEY:value` pairs and ended by exactly `\\r\\n\\0`. The commands (`commands`) and the
line grammar (`grammar`) are re-exported here, so the client and the simulator speak one protocol module: the
simulator parses with the same grammar it answers with.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from fabwire.errors import LocalProtocolError, RemoteProtocolError, excerpt
from fabwire.lineus.commands import (
    ALWAYS_QUOTED,
    COMMAND_TERMINATOR,
    COORD_LIMIT,
    FILE_SLOTS,
    MAX_LINE,
    MAX_REPLY,
    NAME_RE,
    REPLY_TERMINATOR,
    STEP_MAX,
    STEP_MIN,
    TERMINATOR_BYTES,
    Capabilities,
    Command,
    DeleteFile,
    Diagnostics,
    EndSave,
    FactoryReset,
    FirmwareUpdate,
    ForgetWifi,
    Gestures,
    GetPosition,
    Home,
    ListFiles,
    MachineName,
    MemoryDrawing,
    Move,
    RawMove,
    Reserved,
    ReverseServos,
    SaveCalibration,
    SetOrigin,
    SetSpeed,
    StartSave,
    StartupMode,
    StorageUsage,
    TimedDemo,
    Wifi,
    ZMap,
    encode_position,
    format_coordinate,
    format_number,
    parse_number,
    quote_value,
)
from fabwire.lineus.grammar import command_code, parse_command, split_fields

__all__ = [
    "ALWAYS_QUOTED",
    "COMMAND_TERMINATOR",
    "COORD_LIMIT",
    "FILE_SLOTS",
    "MAX_LINE",
    "MAX_REPLY",
    "NAME_RE",
    "REPLY_TERMINATOR",
    "STEP_MAX",
    "STEP_MIN",
    "TERMINATOR_BYTES",
    "BadLine",
    "Capabilities",
    "Command",
    "CommandReader",
    "DeleteFile",
    "Diagnostics",
    "EndSave",
    "FactoryReset",
    "FirmwareUpdate",
    "ForgetWifi",
    "Gestures",
    "GetPosition",
    "Hello",
    "Home",
    "Line",
    "ListFiles",
    "MachineName",
    "MemoryDrawing",
    "Message",
    "Move",
    "RawMove",
    "Reply",
    "ReplyReader",
    "Reserved",
    "ReverseServos",
    "SaveCalibration",
    "SetOrigin",
    "SetSpeed",
    "StartSave",
    "StartupMode",
    "StorageUsage",
    "TimedDemo",
    "Wifi",
    "ZMap",
    "command_code",
    "encode_position",
    "format_coordinate",
    "format_number",
    "parse_command",
    "parse_message",
    "parse_number",
    "quote_value",
    "split_fields",
]


# ---------------------------------------------------------------------------------------------------------------
# device side: the command reader


@dataclass(frozen=True, slots=True)
class Line:
    """One command line as received (terminators and surrounding spaces removed)."""

    text: str


@dataclass(frozen=True, slots=True)
class BadLine:
    """Input that cannot be a command (too long, not ASCII); the device answers `error`."""

    reason: str


_TERMINATOR_RUN = re.compile(rb"[\r\n\x00]")
_CONTROL = re.compile(r"[\x00-\x08\x0a-\x1f\x7f]")


class CommandReader:
    """Splits the host's byte stream into command lines: any run of `\\r`, `\\n`, `\\0` ends one line,
    and blank lines vanish, so every client's terminator habit gets exactly one reply per command."""

    def __init__(self, max_line: int = MAX_LINE) -> None:
        self._buffer = bytearray()
        self._max = max_line
        self._discarding = False

    def feed(self, data: bytes) -> list[Line | BadLine]:
        out: list[Line | BadLine] = []
        start = 0
        for match in _TERMINATOR_RUN.finditer(data):
            self._take(data[start : match.start()], out)
            self._end_line(out)
            start = match.end()
        self._take(data[start:], out)
        return out

    def _take(self, chunk: bytes, out: list[Line | BadLine]) -> None:
        if self._discarding or not chunk:
            return
        self._buffer += chunk
        if len(self._buffer) > self._max:
            self._buffer.clear()
            self._discarding = True
            out.append(BadLine(f"line longer than {self._max} bytes"))

    def _end_line(self, out: list[Line | BadLine]) -> None:
        if self._discarding:
            self._discarding = False
            return
        raw = bytes(self._buffer)
        self._buffer.clear()
        try:
            text = raw.decode("ascii").strip(" \t")
        except UnicodeDecodeError:
            out.append(BadLine("command is not ASCII text"))
            return
        if not text:
            return
        if _CONTROL.search(text):
            out.append(BadLine("command holds control characters"))
            return
        out.append(Line(text))


# ---------------------------------------------------------------------------------------------------------------
# replies (device → host)


_BAD_KEY = re.compile(r'[:"\r\n\x00]')
_BAD_VALUE = re.compile(r'["\r\n\x00]')


@dataclass(frozen=True, slots=True)
class Reply:
    """`ok`/`error` and its KEY:value pairs, in order."""

    ok: bool
    fields: tuple[tuple[str, str], ...] = ()
    quoted: frozenset[str] = field(default=ALWAYS_QUOTED, compare=False)
    """Keys written in double quotes even without spaces (M122 writes ZMap bare, G31 quoted)."""

    def __post_init__(self) -> None:
        for key, value in self.fields:
            if not key or not key.isascii() or _BAD_KEY.search(key):
                raise LocalProtocolError(f"bad reply key {excerpt(key, 40)}")
            if not value.isascii() or _BAD_VALUE.search(value):
                raise LocalProtocolError(f"bad reply value {excerpt(value, 40)}")

    def get(self, key: str, default: str | None = None) -> str | None:
        for k, v in self.fields:
            if k == key:
                return v
        return default

    def as_dict(self) -> dict[str, str]:
        return dict(self.fields)

    @property
    def info(self) -> str:
        return self.get("INFO") or ""

    def text(self) -> str:
        pairs = (f"{quote_value(k) if ' ' in k else k}:{quote_value(v, k in self.quoted)}" for k, v in self.fields)
        return " ".join(["ok" if self.ok else "error", *pairs])

    def encode(self) -> bytes:
        return self.text().encode("ascii") + REPLY_TERMINATOR


@dataclass(frozen=True, slots=True)
class Hello:
    """The greeting every connection starts with."""

    version: str
    name: str
    serial: str
    extra: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        Reply(True, (("VERSION", self.version), ("NAME", self.name), ("SERIAL", self.serial), *self.extra))

    @property
    def firmware(self) -> tuple[int, ...]:
        """Numeric version parts, `(3, 2, 0)` for `3.2.0 Nov 17 2019 …`; `()` if unreadable."""
        match = re.match(r"(\d+(?:\.\d+)*)", self.version)
        return tuple(int(part) for part in match.group(1).split(".")) if match else ()

    @property
    def firmware_major(self) -> int:
        """The major version, 0 when the hello gives none (a bare `hello`, clones, test rigs)."""
        return self.firmware[0] if self.firmware else 0

    @property
    def firmware_label(self) -> str:
        """The version's first word for messages (`3.2.0`), or "(version not given)" when the hello has none."""
        words = self.version.split()
        return words[0] if words else "(version not given)"

    def text(self) -> str:
        pairs = (("VERSION", self.version), ("NAME", self.name), ("SERIAL", self.serial), *self.extra)
        return " ".join(["hello", *(f"{k}:{quote_value(v)}" for k, v in pairs)])

    def encode(self) -> bytes:
        return self.text().encode("ascii") + REPLY_TERMINATOR


Message = Reply | Hello


def parse_message(text: str) -> Message:
    """One device message (terminator removed) → Reply or Hello; RemoteProtocolError if it is neither."""
    if not text.isascii():
        raise RemoteProtocolError("reply is not ASCII text")
    tokens = split_fields(text)
    if not tokens:
        raise RemoteProtocolError("empty reply")
    status = tokens[0]
    if status not in ("ok", "error", "hello"):
        raise RemoteProtocolError(f"reply starts with {excerpt(status, 40)}, not ok/error/hello")
    pairs: list[tuple[str, str]] = []
    # Unquoted text splits at whitespace (CR and LF included), so only a NUL could reach a token: one look at the
    # whole text answers for every token.
    checked = '"' not in text and "\x00" not in text
    for token in tokens[1:]:
        key, sep, value = token.partition(":")
        if not sep or not key:
            raise RemoteProtocolError(f"reply field {excerpt(token, 40)} is not KEY:value")
        if not checked and _FORBIDDEN.search(token):
            raise RemoteProtocolError(f"reply field {excerpt(token, 40)} holds a forbidden character")
        pairs.append((key, value))
    if status != "hello":
        # Every field was checked above (ASCII text, no quote or terminator byte), which is all Reply checks.
        reply = object.__new__(Reply)
        object.__setattr__(reply, "ok", status == "ok")
        object.__setattr__(reply, "fields", tuple(pairs))
        object.__setattr__(reply, "quoted", ALWAYS_QUOTED)
        return reply
    try:
        found = dict(pairs)
        rest = tuple((k, v) for k, v in pairs if k not in ("VERSION", "NAME", "SERIAL"))
        return Hello(found.get("VERSION", ""), found.get("NAME", ""), found.get("SERIAL", ""), rest)
    except LocalProtocolError as exc:
        raise RemoteProtocolError(str(exc)) from None


_FORBIDDEN = re.compile('["\r\n\x00]')


class ReplyReader:
    """The host's reader: messages end at exactly `\\r\\n\\0`; anything else stays buffered."""

    def __init__(self, max_size: int = MAX_REPLY) -> None:
        self._buffer = bytearray()
        self._max = max_size

    @property
    def pending(self) -> bytes:
        return bytes(self._buffer)

    def feed(self, data: bytes) -> None:
        self._buffer += data

    def next_message(self) -> Message | None:
        """The next complete message, or None until more bytes arrive; RemoteProtocolError for a bad one
        (which is consumed, so reading can go on) or for a buffer that grew past any reply's size."""
        end = self._buffer.find(REPLY_TERMINATOR)
        if end < 0:
            if len(self._buffer) > self._max:
                size = len(self._buffer)
                self._buffer.clear()
                raise RemoteProtocolError(f"{size} bytes without a reply terminator: the peer is not a Line-us")
            return None
        raw = self._buffer[:end]
        del self._buffer[: end + len(REPLY_TERMINATOR)]
        try:
            text = raw.decode("ascii")
        except UnicodeDecodeError:
            raise RemoteProtocolError(f"reply is not ASCII text: {excerpt(bytes(raw), 40)}") from None
        return parse_message(text)
