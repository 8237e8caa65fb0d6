"""The device's side of XYZv3, sans-IO: the command parser and the splitter of what a printer reads into commands
and upload blocks, and the reply lines a printer writes. Total: any input gives events, never an exception."""

from __future__ import annotations

import json
import re
import struct
import zlib
from dataclasses import dataclass

from fabwire.errors import InputError, LocalProtocolError
from fabwire.xyz.commands import (
    CONTROL_VERB,
    FINISH,
    FLOW_OPS,
    MAX_BLOCK,
    MAX_COMMAND,
    PREFIX,
    Command,
    FirmwareUpload,
    Flow,
    GetZOffset,
    Home,
    Jog,
    JoinWifi,
    LeaveWifi,
    NudgeZOffset,
    PlaceObject,
    PrintControl,
    Query,
    RestoreDefaults,
    SetAutoLevel,
    SetBuzzer,
    SetEnergy,
    SetLanguage,
    SetLife,
    SetName,
    SetZOffset,
    Signature,
    SimControl,
    TagInfo,
    Uid,
    UnknownCommand,
    UnlockFilament,
    Upload,
    UploadDidFinish,
)


def parse_command(text: str) -> Command:
    """Parse the text after `XYZv3/` (terminator removed); anything unrecognised is an UnknownCommand.

    Total: whatever a client sends (deep JSON, huge numbers, odd types) ends as a command or an UnknownCommand."""
    if len(text) > MAX_COMMAND:
        return UnknownCommand(text[:MAX_COMMAND])
    try:
        return _parse(text)
    except (LocalProtocolError, InputError, ValueError, KeyError, TypeError, RecursionError, OverflowError):
        return UnknownCommand(text)


def _parse(text: str) -> Command:
    verb, _, arg = text.partition("=")
    if text == "uploadDidFinish":
        return UploadDidFinish()
    if verb == "query" and arg:
        return Query(arg)
    if verb in ("upload", "firmware"):
        m = re.fullmatch(r"([^,]+),(\d{1,12})(?:,(SaveToSD|Downgrade))?", arg)
        if m:
            if verb == "upload":
                return Upload(m[1], int(m[2]), m[3] == "SaveToSD")
            return FirmwareUpload(m[1], int(m[2]), m[3] == "Downgrade")
    if verb == "config":
        return _parse_config(arg) or UnknownCommand(text)
    if verb == "action":
        return _parse_action(arg) or UnknownCommand(text)
    if verb == CONTROL_VERB:
        return SimControl(arg)
    return UnknownCommand(text)


def _parse_config(arg: str) -> Command | None:
    simple: dict[str, Command] = {
        "autolevel:on": SetAutoLevel(True), "autolevel:off": SetAutoLevel(False),
        "buzzer:on": SetBuzzer(True), "buzzer:off": SetBuzzer(False),
        "zoffset:get": GetZOffset(), "restoredefault:on": RestoreDefaults(), "disconnectap": LeaveWifi(),
        "engrave:placeobject": PlaceObject(), "taginfo": TagInfo(), "signature:[get]": Signature(), "uid": Uid(),
    }
    if arg in simple:
        return simple[arg]
    if m := re.fullmatch(r"zoffset:set\[(-?\d{1,6})\]", arg):
        return SetZOffset(int(m[1]))
    if m := re.fullmatch(r"print\[(\w+)\]", arg):
        return PrintControl(m[1])
    if m := re.fullmatch(r"lang:\[(\w+)\]", arg):
        return SetLanguage(m[1])
    if m := re.fullmatch(r"energy:\[(\d{1,6})\]", arg):
        return SetEnergy(int(m[1]))
    if m := re.fullmatch(r"name:\[(.*)\]", arg):
        return SetName(m[1])
    if m := re.fullmatch(r"life:\[(\d{1,12})\]", arg):
        return SetLife(int(m[1]))
    if m := re.fullmatch(r"ssid:\[([^,]*),([^,]*),(\d{1,6})\]", arg):
        return JoinWifi(m[1], m[2], int(m[3]))
    if m := re.fullmatch(r"pd([a-e]):\[(\d{1,12})\]", arg):
        return UnlockFilament(m[1], int(m[2]))
    return None


def _parse_action(arg: str) -> Command | None:
    if arg == "home":
        return Home()
    if arg in ("zoffset:up", "zoffset:down"):
        return NudgeZOffset(arg.endswith("up"))
    if arg.startswith("jog:"):
        if len(arg) > 200:  # a jog spec is about 40 characters; never hand a parser a deep structure
            return None
        try:
            spec = json.loads(arg[4:])
            distance = float(spec["len"]) * (-1 if spec["dir"] == "-" else 1)
            return Jog(str(spec["axis"]), distance)
        except (ValueError, KeyError, TypeError):
            return None
    flow, _, op = arg.partition(":")
    if flow in FLOW_OPS:
        return Flow(flow, op)
    return None


@dataclass(frozen=True, slots=True)
class Received:
    """A complete command as the device read it."""

    command: Command
    raw: bytes


@dataclass(frozen=True, slots=True)
class Block:
    """One upload block as framed on the wire; `data` may be shorter than `length` (see DeviceDecoder)."""

    index: int
    length: int
    data: bytes
    trailer: int

    @property
    def crc_ok(self) -> bool:
        """Zero means "no check" (miniMover, py-threedub); anything else must be the CRC-32 of the data."""
        return self.trailer == 0 or self.trailer == zlib.crc32(self.data)


@dataclass(frozen=True, slots=True)
class UploadStalled:
    """No upload bytes arrived for `idle` seconds; the decoder is back in text mode."""

    received: int
    expected: int


@dataclass(frozen=True, slots=True)
class Garbage:
    """Bytes that are not a command (no `XYZv3/` prefix)."""

    raw: bytes


DeviceEvent = Received | Block | UploadStalled | Garbage

_UPLOAD_HEAD = re.compile(rb"^XYZv3/(?:upload|firmware)=[^,\r\n]*,\d{1,12}(?:,(?:SaveToSD|Downgrade))?")


class DeviceDecoder:
    """Splits what a printer reads into commands and upload blocks.

    A text command ends at `\\n` (a preceding `\\r` is dropped), at the start of the next `XYZv3/`, after an
    idle gap, or at EOF — every way real clients end them. After `upload=`/`firmware=` it switches to
    binary blocks until `XYZv3/uploadDidFinish`.
    """

    def __init__(self, *, gap: float = 0.03, upload_idle: float = 30.0, max_line: int = 4096,
                 max_block: int = MAX_BLOCK) -> None:
        self.gap = gap
        self.max_block = max_block
        self.upload_idle = upload_idle
        self.max_line = max_line
        self._buffer = bytearray()
        self._last_rx: float | None = None
        self._owed = 0  # upload bytes still expected; -1 when not uploading
        self._uploading = False
        self._expected = 0
        self._received = 0
        self._events: list[DeviceEvent] = []

    @property
    def uploading(self) -> bool:
        return self._uploading

    def cancel_upload(self) -> None:
        """The device refused the upload: what follows is text again (stray block bytes become garbage)."""
        self._uploading = False

    def feed(self, data: bytes, now: float) -> list[DeviceEvent]:
        self._buffer += data
        self._last_rx = now
        self._parse(now, flush=False)
        return self._take()

    def poll(self, now: float) -> list[DeviceEvent]:
        """Act on the idle gap (an unterminated command is complete) and on a stalled upload."""
        if self._last_rx is not None:
            idle = now - self._last_rx
            if self._uploading and idle >= self.upload_idle:
                self._events.append(UploadStalled(self._received, self._expected))
                self._uploading = False
                self._buffer.clear()
            elif not self._uploading and self._buffer and idle >= self.gap:
                self._parse(now, flush=True)
        return self._take()

    def eof(self, now: float) -> list[DeviceEvent]:
        """The peer closed: whatever text is pending is a command (miniMover closes right after writing)."""
        self._parse(now, flush=True)
        if not self._uploading and self._buffer:
            self._emit_text(bytes(self._buffer))
            self._buffer.clear()
        return self._take()

    def next_deadline(self) -> float | None:
        if self._last_rx is None:
            return None
        if self._uploading:
            return self._last_rx + self.upload_idle
        return self._last_rx + self.gap if self._buffer else None

    def _take(self) -> list[DeviceEvent]:
        events, self._events = self._events, []
        return events

    def _parse(self, now: float, *, flush: bool) -> None:
        while self._buffer:
            if self._uploading:
                if not self._parse_block():
                    return
                continue
            if not self._parse_text(flush):
                return

    def _parse_text(self, flush: bool) -> bool:
        buf = self._buffer
        while bytes(buf[:1]) in (b"\r", b"\n"):
            del buf[:1]
        if not buf:
            return False
        start = buf.find(PREFIX)
        if start != 0:
            nl = buf.find(b"\n")
            cut = min(x for x in (start, nl + 1 if nl >= 0 else -1, len(buf)) if x > 0)
            if cut == len(buf) and start < 0 and nl < 0 and not flush and len(buf) < self.max_line:
                return False  # maybe the start of a prefix, or garbage still arriving
            self._events.append(Garbage(bytes(buf[:cut]).rstrip(b"\r\n")))
            del buf[:cut]
            return True
        if m := _UPLOAD_HEAD.match(buf):
            after = buf[m.end() : m.end() + 1]
            if not after and not flush:
                return False
            if after != b",":  # binary may follow at once, with no terminator in between
                self._emit_text(bytes(buf[: m.end()]))
                del buf[: m.end()]
                if buf[:2] == b"\r\n":
                    del buf[:2]
                elif buf[:1] == b"\n":
                    del buf[:1]
                return True
        nl = buf.find(b"\n")
        nxt = buf.find(PREFIX, 1)
        if nl >= 0 and (nxt < 0 or nl < nxt):
            self._emit_text(bytes(buf[:nl]).rstrip(b"\r"))
            del buf[: nl + 1]
            return True
        if nxt > 0:
            self._emit_text(bytes(buf[:nxt]).rstrip(b"\r"))
            del buf[:nxt]
            return True
        if buf == FINISH:  # it never carries a terminator, so it is complete as soon as it is whole
            self._emit_text(bytes(buf))
            buf.clear()
            return True
        if flush or len(buf) >= self.max_line:
            self._emit_text(bytes(buf).rstrip(b"\r"))
            buf.clear()
            return True
        return False

    def _emit_text(self, raw: bytes) -> None:
        body = raw[len(PREFIX) :]
        try:
            text = body.decode("utf-8")
        except UnicodeDecodeError:
            text = body.decode("latin-1")
        command = parse_command(text)
        self._events.append(Received(command, raw))
        if isinstance(command, Upload | FirmwareUpload):
            self._uploading = True
            self._owed = command.size
            self._expected = command.size
            self._received = 0

    def _parse_block(self) -> bool:
        buf = self._buffer
        while bytes(buf[:1]) in (b"\r", b"\n"):
            del buf[:1]
        if buf[:1] == b"X":
            # The uploadDidFinish (or any command) ends the binary phase, even if blocks are missing.
            if len(buf) < len(FINISH) and FINISH.startswith(bytes(buf)):
                return False
            self._uploading = False
            return True
        if len(buf) < 8:
            return False
        index, length = struct.unpack_from(">II", buf, 0)
        if length > self.max_block:  # never buffer what no printer's block size allows
            self._events.append(Garbage(bytes(buf[:8])))
            self._uploading = False
            buf.clear()
            return False
        take = min(length, self._owed)
        if len(buf) < 8 + take + 4:
            return False
        data = bytes(buf[8 : 8 + take])
        (trailer,) = struct.unpack_from(">I", buf, 8 + take)
        del buf[: 8 + take + 4]
        self._owed -= take
        self._received += take
        self._events.append(Block(index, length, data, trailer))
        return True


def reply_lines(lines: list[str] | tuple[str, ...], *, dollar: bool) -> bytes:
    """Printer → host: lines end in a bare `\\n` (never `\\r\\n`), optionally closed by `$`."""
    text = "".join(f"{line}\n" for line in lines) + ("$\n" if dollar else "")
    return text.encode("latin-1")


def stat_line(name: str, stat: str, *values: int, **extra: str) -> str:
    parts = [f'"stat":"{stat}"', *(f'"{k}":"{v}"' for k, v in extra.items()), *(str(v) for v in values)]
    return f"{name}:{{{','.join(parts)}}}"


def error_line(code: int) -> str:
    return f"E{code}$"
