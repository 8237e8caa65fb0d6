"""The XYZv3 wire grammar for both roles, sans-IO: typed commands, the host's reply reader, upload block
framing, and the device's command splitter. Time is always an argument; nothing here sleeps or reads a clock.

Serial and Wi-Fi links answer differently (Wi-Fi omits `$` after most replies and every config/action ack),
so the reader is told the link kind and never waits for a terminator that will not come.
"""

from __future__ import annotations

import enum
import json
import re
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import ClassVar

from fabwire.errors import InputError, LocalProtocolError

PREFIX = b"XYZv3/"
MAX_COMMAND = 4096
"""Longest command text parsed (the longest real one, a Wi-Fi join, is under 120 characters)."""
FINISH = b"XYZv3/uploadDidFinish"
DEFAULT_BLOCK_SIZE = 8192
MAX_BLOCK = 1 << 16
"""Largest upload block a device accepts (printers announce `o:p8`, 8 KiB; `p<k>` allows up to k KiB)."""
NO_CARTRIDGE_SERIAL = "-" * 14
REMAINING_UNKNOWN = 71582788
"""`d:` remaining-minutes sentinel (0x04444444) meaning the printer has no estimate."""


class Link(enum.Enum):
    """How the printer frames replies: decided by the transport, not the model."""

    SERIAL = "serial"
    WIFI = "wifi"


class Expect(enum.Enum):
    """What reply a command draws."""

    STATUS = "status"  # letter lines; `$` on serial, on Wi-Fi only for query=a
    ACK = "ack"  # serial `ok` + `$`; nothing on Wi-Fi
    NUMBER = "number"  # `<int>` + `$` on both links
    ACTION = "action"  # serial `name:{"stat":…}` + `$`; nothing on Wi-Fi
    DATA = "data"  # one line + `$` on both links
    LINE = "line"  # one line, no `$`
    UPLOAD = "upload"  # one `ok` line (Wi-Fi: `ok `), no `$`
    FINISH = "finish"  # `ok` (+ a late extra `ok` on Wi-Fi)
    NOTHING = "nothing"


# --------------------------------------------------------------------------------------------------- commands


@dataclass(frozen=True, slots=True)
class Command:
    """A host → printer message; `body` is the text after `XYZv3/`."""

    expect: ClassVar[Expect] = Expect.NOTHING

    @property
    def body(self) -> str:
        raise NotImplementedError

    def expects(self, link: Link) -> Expect:
        """The reply this command draws on `link`."""
        if link is Link.WIFI and self.expect in (Expect.ACK, Expect.ACTION):
            return Expect.NOTHING
        return self.expect


_LETTERS = re.compile(r"^[A-Za-z0-9]+$")


@dataclass(frozen=True, slots=True)
class Query(Command):
    """`query=<letters>`; `a` asks for everything."""

    letters: str = "a"
    expect: ClassVar[Expect] = Expect.STATUS

    def __post_init__(self) -> None:
        if not _LETTERS.match(self.letters):
            raise LocalProtocolError(f"query letters must be letters or digits, not {self.letters!r}")

    @property
    def body(self) -> str:
        return f"query={self.letters}"

    @property
    def wanted(self) -> frozenset[str]:
        return frozenset() if "a" in self.letters else frozenset(self.letters)


def _on_off(value: bool) -> str:
    return "on" if value else "off"


@dataclass(frozen=True, slots=True)
class SetAutoLevel(Command):
    on: bool
    expect: ClassVar[Expect] = Expect.ACK

    @property
    def body(self) -> str:
        return f"config=autolevel:{_on_off(self.on)}"


@dataclass(frozen=True, slots=True)
class SetBuzzer(Command):
    on: bool
    expect: ClassVar[Expect] = Expect.ACK

    @property
    def body(self) -> str:
        return f"config=buzzer:{_on_off(self.on)}"


@dataclass(frozen=True, slots=True)
class GetZOffset(Command):
    expect: ClassVar[Expect] = Expect.NUMBER

    @property
    def body(self) -> str:
        return "config=zoffset:get"


ZOFFSET_RANGE = range(-2000, 2001)
"""Z offset in 1/100 mm; ±20 mm is far beyond any real machine's travel."""


@dataclass(frozen=True, slots=True)
class SetZOffset(Command):
    value: int
    expect: ClassVar[Expect] = Expect.ACK

    def __post_init__(self) -> None:
        if self.value not in ZOFFSET_RANGE:
            low, high = ZOFFSET_RANGE.start, ZOFFSET_RANGE.stop - 1
            raise LocalProtocolError(f"z offset {self.value} is outside {low}..{high}")

    @property
    def body(self) -> str:
        return f"config=zoffset:set[{self.value}]"


@dataclass(frozen=True, slots=True)
class NudgeZOffset(Command):
    """`action=zoffset:up|down`: one 1/100 mm step; the firmware sends no reply."""

    up: bool

    @property
    def body(self) -> str:
        return f"action=zoffset:{'up' if self.up else 'down'}"


@dataclass(frozen=True, slots=True)
class RestoreDefaults(Command):
    expect: ClassVar[Expect] = Expect.ACK

    @property
    def body(self) -> str:
        return "config=restoredefault:on"


LANGUAGES = ("en", "fr", "it", "de", "es", "jp")


@dataclass(frozen=True, slots=True)
class SetLanguage(Command):
    code: str
    expect: ClassVar[Expect] = Expect.ACK

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[a-z]{2}", self.code):
            raise LocalProtocolError(f"language must be a two-letter code such as {', '.join(LANGUAGES)}")

    @property
    def body(self) -> str:
        return f"config=lang:[{self.code}]"


@dataclass(frozen=True, slots=True)
class SetEnergy(Command):
    minutes: int
    expect: ClassVar[Expect] = Expect.ACK

    def __post_init__(self) -> None:
        if not 0 <= self.minutes <= 9:
            raise LocalProtocolError(f"energy saving takes 0-9 minutes, not {self.minutes}")

    @property
    def body(self) -> str:
        return f"config=energy:[{self.minutes}]"


def _bracket_safe(what: str, text: str, limit: int) -> None:
    if not text or len(text) > limit or any(c in text for c in "[]\r\n") or not text.isprintable():
        raise LocalProtocolError(f"{what} must be 1-{limit} printable characters without brackets")


@dataclass(frozen=True, slots=True)
class SetName(Command):
    name: str
    expect: ClassVar[Expect] = Expect.ACK

    def __post_init__(self) -> None:
        _bracket_safe("printer name", self.name, 16)
        if not self.name.isascii():
            raise LocalProtocolError("printer name must be ASCII")

    @property
    def body(self) -> str:
        return f"config=name:[{self.name}]"


@dataclass(frozen=True, slots=True)
class SetLife(Command):
    value: int
    expect: ClassVar[Expect] = Expect.ACK

    @property
    def body(self) -> str:
        return f"config=life:[{self.value}]"


@dataclass(frozen=True, slots=True)
class JoinWifi(Command):
    ssid: str
    password: str
    channel: int = 0
    expect: ClassVar[Expect] = Expect.ACK

    def __post_init__(self) -> None:
        _bracket_safe("SSID", self.ssid, 32)
        if "," in self.ssid or "," in self.password or any(c in self.password for c in "[]\r\n"):
            raise LocalProtocolError("SSID and password cannot contain ',', brackets or line breaks")
        if not 0 <= self.channel <= 165:
            raise LocalProtocolError(f"Wi-Fi channel {self.channel} is out of range")

    @property
    def body(self) -> str:
        return f"config=ssid:[{self.ssid},{self.password},{self.channel}]"


@dataclass(frozen=True, slots=True)
class LeaveWifi(Command):
    expect: ClassVar[Expect] = Expect.ACK

    @property
    def body(self) -> str:
        return "config=disconnectap"


@dataclass(frozen=True, slots=True)
class PlaceObject(Command):
    expect: ClassVar[Expect] = Expect.ACK

    @property
    def body(self) -> str:
        return "config=engrave:placeobject"


PRINT_OPS = ("pause", "resume", "cancel", "complete")


@dataclass(frozen=True, slots=True)
class PrintControl(Command):
    op: str
    expect: ClassVar[Expect] = Expect.ACK

    def __post_init__(self) -> None:
        if self.op not in PRINT_OPS:
            raise LocalProtocolError(f"print control is one of {', '.join(PRINT_OPS)}, not {self.op!r}")

    @property
    def body(self) -> str:
        return f"config=print[{self.op}]"


UNLOCK_SEQUENCE = (("a", 1591), ("b", 4387), ("c", 7264), ("e", 8046))


@dataclass(frozen=True, slots=True)
class UnlockFilament(Command):
    """One of `config=pda:[1591]` … `pde:[8046]`, sent in that order."""

    slot: str
    code: int
    expect: ClassVar[Expect] = Expect.ACK

    def __post_init__(self) -> None:
        if self.slot not in "abcde" or len(self.slot) != 1:
            raise LocalProtocolError(f"unlock slot must be a-e, not {self.slot!r}")

    @property
    def body(self) -> str:
        return f"config=pd{self.slot}:[{self.code}]"


@dataclass(frozen=True, slots=True)
class TagInfo(Command):
    expect: ClassVar[Expect] = Expect.DATA

    @property
    def body(self) -> str:
        return "config=taginfo"


@dataclass(frozen=True, slots=True)
class Signature(Command):
    """Firmware 3.x: `signature:"<32 raw bytes>"` (no `$`); the bytes may contain `\n`, so they are read by count."""

    expect: ClassVar[Expect] = Expect.LINE

    @property
    def body(self) -> str:
        return "config=signature:[get]"


@dataclass(frozen=True, slots=True)
class Uid(Command):
    """Firmware 3.x: `uid:"<4 raw bytes>"` then `$`."""

    expect: ClassVar[Expect] = Expect.DATA

    @property
    def body(self) -> str:
        return "config=uid"


RAW_REPLIES: dict[type[Command], tuple[str, int]] = {Signature: ("signature", 32), Uid: ("uid", 4)}
"""Replies carrying a fixed number of raw bytes between quotes: `<name>:"<bytes>"`."""


def raw_reply_line(command: Signature | Uid, value: bytes) -> str:
    """The device's reply line (latin-1 text, one char per byte) for `signature` or `uid`."""
    name, size = RAW_REPLIES[type(command)]
    if len(value) != size:
        raise LocalProtocolError(f"{name} carries exactly {size} bytes, not {len(value)}")
    return f'{name}:"{value.decode("latin-1")}"'


def raw_reply_value(command: Command, line: str) -> bytes | None:
    """The raw bytes in a `signature`/`uid` reply line, or None if the line is not one."""
    spec = RAW_REPLIES.get(type(command))
    if spec is None:
        return None
    head = f'{spec[0]}:"'
    if not (line.startswith(head) and line.endswith('"') and len(line) == len(head) + spec[1] + 1):
        return None
    return line[len(head) : -1].encode("latin-1")


CONTROL_VERB = "simctl"
"""`XYZv3/simctl=…` is the simulator's in-band control plane (fault triggers, OctoPrint-style). No real client
sends it; a real printer rejects it like any unknown command, so it cannot change what real clients see."""


@dataclass(frozen=True, slots=True)
class SimControl(Command):
    """`simctl=fault:<name>:on|off`, `simctl=clear` or `simctl=faults`; answered `simctl:<faults>` + `$`."""

    op: str
    expect: ClassVar[Expect] = Expect.DATA

    def __post_init__(self) -> None:
        if not re.fullmatch(r"fault:[a-z-]+:(?:on|off)|clear|faults", self.op):
            raise LocalProtocolError(f"simulator control is fault:<name>:on|off, clear or faults, not {self.op!r}")

    @property
    def body(self) -> str:
        return f"{CONTROL_VERB}={self.op}"


@dataclass(frozen=True, slots=True)
class Home(Command):
    expect: ClassVar[Expect] = Expect.ACTION

    @property
    def body(self) -> str:
        return "action=home"


JOG_LIMIT = 300


@dataclass(frozen=True, slots=True)
class Jog(Command):
    axis: str
    distance: float
    expect: ClassVar[Expect] = Expect.ACTION

    def __post_init__(self) -> None:
        if self.axis not in ("x", "y", "z"):
            raise LocalProtocolError(f"jog axis must be x, y or z, not {self.axis!r}")
        if not (0 < abs(self.distance) <= JOG_LIMIT):
            raise LocalProtocolError(f"jog distance must be non-zero and at most {JOG_LIMIT} mm")

    @property
    def body(self) -> str:
        sign = "-" if self.distance < 0 else "+"
        length = f"{abs(self.distance):g}"
        return f'action=jog:{{"axis":"{self.axis}","dir":"{sign}","len":"{length}"}}'


_FLOW_OPS: dict[str, tuple[str, ...]] = {
    "load": ("new", "cancel", "retry"),
    "unload": ("new", "cancel", "retry"),
    "cleannozzle": ("new", "cancel"),
    "calibratejr": ("new", "detectorok", "getdata", "release"),
}


@dataclass(frozen=True, slots=True)
class Flow(Command):
    """`action=<flow>:<op>` for load, unload, cleannozzle and calibratejr."""

    flow: str
    op: str
    expect: ClassVar[Expect] = Expect.ACTION

    def __post_init__(self) -> None:
        ops = _FLOW_OPS.get(self.flow)
        if ops is None or self.op not in ops:
            raise LocalProtocolError(f"unknown action {self.flow}:{self.op}")

    @property
    def body(self) -> str:
        return f"action={self.flow}:{self.op}"

    def expects(self, link: Link) -> Expect:
        if (self.flow, self.op) == ("calibratejr", "getdata"):
            return Expect.DATA
        if (self.flow, self.op) == ("unload", "cancel"):
            return Expect.NOTHING  # the firmware answers later with `complete`, not now
        return Command.expects(self, link)


_NAME = re.compile(r"^[^,\r\n\x00]{1,128}$")


@dataclass(frozen=True, slots=True)
class Upload(Command):
    """`upload=<name>,<size>[,SaveToSD]`: a print file follows in blocks."""

    name: str
    size: int
    save_to_sd: bool = False
    expect: ClassVar[Expect] = Expect.UPLOAD

    def __post_init__(self) -> None:
        if not _NAME.match(self.name) or not self.name.isprintable():
            raise LocalProtocolError(f"upload file name {self.name!r} must be printable, without commas")
        if not 0 < self.size < 2**32:
            raise LocalProtocolError(f"upload size {self.size} must be 1..4294967295 bytes")

    @property
    def body(self) -> str:
        return f"upload={self.name},{self.size}" + (",SaveToSD" if self.save_to_sd else "")


@dataclass(frozen=True, slots=True)
class FirmwareUpload(Command):
    """`firmware=<name>,<size>[,Downgrade]`: size excludes the image's 16-byte header."""

    name: str
    size: int
    downgrade: bool = False
    expect: ClassVar[Expect] = Expect.UPLOAD

    def __post_init__(self) -> None:
        if not _NAME.match(self.name) or not self.name.isprintable():
            raise LocalProtocolError(f"firmware file name {self.name!r} must be printable, without commas")
        if not 0 < self.size < 2**32:
            raise LocalProtocolError(f"firmware size {self.size} must be 1..4294967295 bytes")

    @property
    def body(self) -> str:
        return f"firmware={self.name},{self.size}" + (",Downgrade" if self.downgrade else "")


@dataclass(frozen=True, slots=True)
class UploadDidFinish(Command):
    expect: ClassVar[Expect] = Expect.FINISH

    @property
    def body(self) -> str:
        return "uploadDidFinish"


@dataclass(frozen=True, slots=True)
class UnknownCommand(Command):
    """Text the device could not make sense of (kept so the simulator can log or refuse it)."""

    text: str = ""

    @property
    def body(self) -> str:
        return self.text


def terminator(command: Command, link: Link) -> bytes:
    """Serial: `\\n` (as py-threedub); Wi-Fi: `\\r\\n` (as XYZware). `uploadDidFinish` never has one (all clients)."""
    if isinstance(command, UploadDidFinish):
        return b""
    return b"\n" if link is Link.SERIAL else b"\r\n"


def encode(command: Command, link: Link) -> bytes:
    return PREFIX + command.body.encode("utf-8") + terminator(command, link)


# ---------------------------------------------------------------------------------------- command parsing


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
    if flow in _FLOW_OPS:
        return Flow(flow, op)
    return None


# ---------------------------------------------------------------------------------------- upload framing


def block_size_from_packet(k: int) -> int:
    """`o:p<k>` → bytes per block; k ≤ 0 falls back to 8192, as clients do."""
    return k * 1024 if k > 0 else DEFAULT_BLOCK_SIZE


def encode_block(index: int, data: bytes, *, crc: bool = True) -> bytes:
    """`[index u32be][len u32be][data][crc32(data) u32be or 0]`."""
    trailer = zlib.crc32(data) if crc else 0
    return struct.pack(">II", index, len(data)) + data + struct.pack(">I", trailer)


def iter_blocks(data: bytes, block_size: int, *, crc: bool = True) -> Iterator[bytes]:
    if block_size <= 0:
        raise LocalProtocolError("upload block size must be positive")
    view = memoryview(data)
    for index, start in enumerate(range(0, len(data), block_size)):
        yield encode_block(index, bytes(view[start : start + block_size]), crc=crc)


def block_count(size: int, block_size: int) -> int:
    return -(-size // block_size)


# ---------------------------------------------------------------------------------- host: the reply reader


@dataclass(frozen=True, slots=True)
class Reply:
    """A complete reply to `command`: its lines with `$`, `ok` and stray noise removed."""

    command: Command
    lines: tuple[str, ...] = ()
    acked: bool = False


@dataclass(frozen=True, slots=True)
class ErrorReply:
    """`E<n>$` in reply to `command`."""

    command: Command
    code: int


@dataclass(frozen=True, slots=True)
class NoReply:
    """The reply did not finish before the deadline; `lines` holds what did arrive."""

    command: Command
    lines: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class ActionStat:
    """`<name>:{"stat":"<word>",…}`: progress of an action flow, solicited or not (serial only)."""

    name: str
    stat: str
    values: tuple[int, ...] = ()
    extra: dict[str, str] = field(default_factory=dict, hash=False)


ReaderEvent = Reply | ErrorReply | NoReply | ActionStat

_ERROR = re.compile(r"^E(\d{1,10})\$?$")
_STAT = re.compile(r"^([A-Za-z][A-Za-z0-9_]+):(\{.*\})$")
_NUMBER = re.compile(r"^-?\d+$")


def parse_stat_line(line: str) -> ActionStat | None:
    """`load:{"stat":"heat","extemp":"24"}` or `calibratejr:{"stat":"ok",438,…}`; None if not such a line."""
    m = _STAT.match(line)
    if not m:
        return None
    inner = m[2][1:-1]
    stat = ""
    values: list[int] = []
    extra: dict[str, str] = {}
    for part in inner.split(","):
        key, sep, value = part.partition(":")
        if sep:
            key, value = key.strip().strip('"'), value.strip().strip('"')
            if key == "stat":
                stat = value
            else:
                extra[key] = value
        elif _NUMBER.match(part.strip()):
            values.append(int(part.strip()))
        elif part.strip():
            return None
    if not stat and not values:
        return None
    return ActionStat(m[1], stat, tuple(values), extra)


@dataclass
class _Pending:
    command: Command
    expect: Expect
    deadline: float
    lines: list[str] = field(default_factory=list)
    acked: bool = False
    seen: set[str] = field(default_factory=set)
    last_rx: float | None = None


class ReplyReader:
    """Matches printer output to the command in flight, one at a time, for one link kind.

    Lines that belong to nothing (late `$`, the extra `ok` after an upload, an `ok` inside a status reply)
    are dropped and counted in `noise`; action progress lines become ActionStat events whenever they come.
    """

    settle = 0.4
    """Wi-Fi partial queries: once some lines came, this much silence ends the reply."""

    def __init__(self, link: Link) -> None:
        self.link = link
        self._buffer = bytearray()
        self._events: list[ReaderEvent] = []
        self._pending: _Pending | None = None
        self._swallow_dollar = 0
        self.noise = 0
        self.noise_sample: str | None = None
        """The first line that fitted nothing: evidence when the peer is not an XYZv3 printer at all."""

    @property
    def busy(self) -> bool:
        return self._pending is not None

    def send(self, command: Command, now: float, timeout: float = 5.0) -> bytes:
        """Arm the reader for `command` and return its bytes to write."""
        if self._pending is not None:
            raise LocalProtocolError(f"a reply to {self._pending.command.body!r} is still outstanding")
        expect = command.expects(self.link)
        if expect is Expect.NOTHING:
            self._events.append(Reply(command))
        else:
            self._pending = _Pending(command, expect, now + timeout)
        return encode(command, self.link)

    def arm(self, command: Command, now: float, timeout: float = 5.0) -> None:
        """Expect a reply for bytes already sent by other means (upload blocks)."""
        self._pending = _Pending(command, command.expects(self.link), now + timeout)

    def abandon(self) -> None:
        """Stop waiting for the reply in flight (its command failed or was given up)."""
        self._pending = None

    def discard(self) -> None:
        """Forget buffered input (the stale replies a client drains before each command)."""
        self._buffer.clear()
        self._events = [e for e in self._events if isinstance(e, ActionStat)]

    def receive(self, data: bytes, now: float) -> None:
        self._buffer += data
        if self._pending is not None:
            self._pending.last_rx = now
        while True:
            raw_line = self._raw_reply()
            if raw_line is not None:
                if raw_line:
                    self._note(raw_line)
                    continue
                break
            end = self._buffer.find(b"\n")
            if end < 0:
                break
            raw = bytes(self._buffer[:end])
            del self._buffer[: end + 1]
            self._note(raw.decode("latin-1").rstrip("\r "))
        if len(self._buffer) > 65536:  # a line this long is not XYZv3; keep the reader bounded
            self._buffer.clear()
            self.noise += 1

    def _note(self, line: str) -> None:
        before = self.noise
        self._line(line)
        if self.noise > before and self.noise_sample is None:
            self.noise_sample = line[:60]

    def _raw_reply(self) -> str | None:
        """A `signature`/`uid` reply is read by byte count (its raw bytes may hold `\n`): the line, "" while
        it is still arriving, or None when the buffer does not start with one."""
        p = self._pending
        spec = RAW_REPLIES.get(type(p.command)) if p is not None else None
        if spec is None:
            return None
        head = f'{spec[0]}:"'.encode()
        buf = self._buffer
        if not (buf.startswith(head) or (len(buf) < len(head) and head.startswith(bytes(buf)) and buf)):
            return None
        size = len(head) + spec[1] + 1
        if len(buf) < size + 1:
            return ""
        if buf[size - 1 : size + 1] != b'"\n':
            return None  # not the framing we know: fall back to reading a line
        line = bytes(buf[:size]).decode("latin-1")
        del buf[: size + 1]
        return line

    def next_event(self, now: float) -> ReaderEvent | None:
        self._check_time(now)
        return self._events.pop(0) if self._events else None

    def deadline(self) -> float | None:
        p = self._pending
        if p is None:
            return None
        if self.link is Link.WIFI and p.expect is Expect.STATUS and p.lines and p.last_rx is not None:
            return min(p.deadline, p.last_rx + self.settle)
        return p.deadline

    def _check_time(self, now: float) -> None:
        p = self._pending
        if p is None:
            return
        quiet = self.link is Link.WIFI and p.expect is Expect.STATUS and bool(p.lines)
        if quiet and p.last_rx is not None and now >= p.last_rx + self.settle:
            self._finish()
        elif now >= p.deadline:
            if quiet or (p.expect is Expect.ACK and p.acked):
                self._finish()
            else:
                self._pending = None
                self._events.append(NoReply(p.command, tuple(p.lines)))

    def _finish(self) -> None:
        p = self._pending
        assert p is not None
        self._pending = None
        self._events.append(Reply(p.command, tuple(p.lines), p.acked))

    def _line(self, line: str) -> None:
        if not line:
            return
        p = self._pending
        if (m := _ERROR.match(line)) and (line.endswith("$") or p is not None):
            if p is not None:
                self._pending = None
                self._events.append(ErrorReply(p.command, int(m[1])))
            else:
                self.noise += 1
            return
        stat = parse_stat_line(line)
        if stat is not None and not (p is not None and p.expect in (Expect.DATA, Expect.LINE, Expect.ACTION)
                                     and _stat_matches(p.command, stat)):
            self._events.append(stat)
            if self.link is Link.SERIAL:
                self._swallow_dollar += 1
            return
        if line == "$":
            if p is not None and self._swallow_dollar == 0 and self._dollar_ends(p):
                self._finish()
            elif self._swallow_dollar:
                self._swallow_dollar -= 1
            else:
                self.noise += 1
            return
        if p is None:
            self.noise += 1
            return
        if line == "ok" or line.startswith("ok "):
            if p.expect in (Expect.UPLOAD, Expect.FINISH):
                p.acked = True
                self._finish()
            elif p.expect is Expect.ACK:
                p.acked = True
            else:
                self.noise += 1
            return
        if p.expect is Expect.STATUS:
            if len(line) >= 2 and line[1] == ":":
                p.lines.append(line)
                p.seen.add(line[0])
                wanted = p.command.wanted if isinstance(p.command, Query) else frozenset()
                if self.link is Link.WIFI and wanted and wanted <= p.seen:
                    self._finish()
            else:
                self.noise += 1
        elif p.expect is Expect.NUMBER:
            if _NUMBER.match(line) and not p.lines:
                p.lines.append(line)
            else:
                self.noise += 1
        elif p.expect in (Expect.DATA, Expect.ACTION, Expect.LINE):
            if not p.lines:
                p.lines.append(line)
                if p.expect is Expect.LINE:
                    self._finish()
            else:
                self.noise += 1
        else:
            self.noise += 1

    def _dollar_ends(self, p: _Pending) -> bool:
        if p.expect is Expect.STATUS:
            # A stale `$` can precede a full status reply; a real `a` reply always has lines.
            return bool(p.lines) or not (isinstance(p.command, Query) and not p.command.wanted)
        if p.expect is Expect.ACK:
            return p.acked
        if p.expect in (Expect.NUMBER, Expect.DATA, Expect.ACTION):
            return bool(p.lines)
        return False


def _stat_matches(command: Command, stat: ActionStat) -> bool:
    if isinstance(command, Flow):
        return stat.name == command.flow
    if isinstance(command, Home):
        return stat.name == "home"
    if isinstance(command, Jog):
        return stat.name == "jog"
    return isinstance(command, TagInfo | Signature | Uid)


class AckCounter:
    """Counts upload-block acks (`ok`, `ok `) in a byte stream, so several blocks may be in flight.

    `E<n>$` is an error; a stray `$` or blank line is ignored; anything else is counted as noise.
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self.noise = 0

    def feed(self, data: bytes) -> tuple[int, int | None]:
        """Return (acks in `data`, the first error code or None)."""
        self._buffer += data
        acks = 0
        while (end := self._buffer.find(b"\n")) >= 0:
            line = bytes(self._buffer[:end]).rstrip(b"\r ")
            del self._buffer[: end + 1]
            if line == b"ok" or line.startswith(b"ok "):
                acks += 1
            elif m := _ERROR.match(line.decode("latin-1")):
                return acks, int(m[1])
            elif line not in (b"", b"$"):
                self.noise += 1
        if len(self._buffer) > 4096:
            self._buffer.clear()
            self.noise += 1
        return acks, None


# ------------------------------------------------------------------------------- device: command splitter


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
