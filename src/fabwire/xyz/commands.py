"""XYZv3 commands, host → printer: typed, validated in their constructors, encoded exactly as the official clients
send them, with the reply each one draws on a serial or a Wi-Fi link (reference §4)."""

from __future__ import annotations

import enum
import re
from typing import ClassVar

import msgspec

from fabwire.errors import LocalProtocolError

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


class Command(msgspec.Struct, frozen=True):
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


class Query(Command, frozen=True):
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


class SetAutoLevel(Command, frozen=True):
    on: bool
    expect: ClassVar[Expect] = Expect.ACK

    @property
    def body(self) -> str:
        return f"config=autolevel:{_on_off(self.on)}"


class SetBuzzer(Command, frozen=True):
    on: bool
    expect: ClassVar[Expect] = Expect.ACK

    @property
    def body(self) -> str:
        return f"config=buzzer:{_on_off(self.on)}"


class GetZOffset(Command, frozen=True):
    expect: ClassVar[Expect] = Expect.NUMBER

    @property
    def body(self) -> str:
        return "config=zoffset:get"


ZOFFSET_RANGE = range(-2000, 2001)
"""Z offset in 1/100 mm; ±20 mm is far beyond any real machine's travel."""


class SetZOffset(Command, frozen=True):
    value: int
    expect: ClassVar[Expect] = Expect.ACK

    def __post_init__(self) -> None:
        if self.value not in ZOFFSET_RANGE:
            low, high = ZOFFSET_RANGE.start, ZOFFSET_RANGE.stop - 1
            raise LocalProtocolError(f"z offset {self.value} is outside {low}..{high}")

    @property
    def body(self) -> str:
        return f"config=zoffset:set[{self.value}]"


class NudgeZOffset(Command, frozen=True):
    """`action=zoffset:up|down`: one 1/100 mm step; the firmware sends no reply."""

    up: bool

    @property
    def body(self) -> str:
        return f"action=zoffset:{'up' if self.up else 'down'}"


class RestoreDefaults(Command, frozen=True):
    expect: ClassVar[Expect] = Expect.ACK

    @property
    def body(self) -> str:
        return "config=restoredefault:on"


LANGUAGES = ("en", "fr", "it", "de", "es", "jp")


class SetLanguage(Command, frozen=True):
    code: str
    expect: ClassVar[Expect] = Expect.ACK

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[a-z]{2}", self.code):
            raise LocalProtocolError(f"language must be a two-letter code such as {', '.join(LANGUAGES)}")

    @property
    def body(self) -> str:
        return f"config=lang:[{self.code}]"


class SetEnergy(Command, frozen=True):
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


class SetName(Command, frozen=True):
    name: str
    expect: ClassVar[Expect] = Expect.ACK

    def __post_init__(self) -> None:
        _bracket_safe("printer name", self.name, 16)
        if not self.name.isascii():
            raise LocalProtocolError("printer name must be ASCII")

    @property
    def body(self) -> str:
        return f"config=name:[{self.name}]"


class SetLife(Command, frozen=True):
    value: int
    expect: ClassVar[Expect] = Expect.ACK

    @property
    def body(self) -> str:
        return f"config=life:[{self.value}]"


class JoinWifi(Command, frozen=True):
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


class LeaveWifi(Command, frozen=True):
    expect: ClassVar[Expect] = Expect.ACK

    @property
    def body(self) -> str:
        return "config=disconnectap"


class PlaceObject(Command, frozen=True):
    expect: ClassVar[Expect] = Expect.ACK

    @property
    def body(self) -> str:
        return "config=engrave:placeobject"


PRINT_OPS = ("pause", "resume", "cancel", "complete")


class PrintControl(Command, frozen=True):
    op: str
    expect: ClassVar[Expect] = Expect.ACK

    def __post_init__(self) -> None:
        if self.op not in PRINT_OPS:
            raise LocalProtocolError(f"print control is one of {', '.join(PRINT_OPS)}, not {self.op!r}")

    @property
    def body(self) -> str:
        return f"config=print[{self.op}]"


UNLOCK_SEQUENCE = (("a", 1591), ("b", 4387), ("c", 7264), ("e", 8046))


class UnlockFilament(Command, frozen=True):
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


class TagInfo(Command, frozen=True):
    expect: ClassVar[Expect] = Expect.DATA

    @property
    def body(self) -> str:
        return "config=taginfo"


class Signature(Command, frozen=True):
    """Firmware 3.x: `signature:"<32 raw bytes>"` (no `$`); the bytes may contain `\n`, so they are read by count."""

    expect: ClassVar[Expect] = Expect.LINE

    @property
    def body(self) -> str:
        return "config=signature:[get]"


class Uid(Command, frozen=True):
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


class SimControl(Command, frozen=True):
    """`simctl=fault:<name>:on|off`, `simctl=clear` or `simctl=faults`; answered `simctl:<faults>` + `$`."""

    op: str
    expect: ClassVar[Expect] = Expect.DATA

    def __post_init__(self) -> None:
        if not re.fullmatch(r"fault:[a-z-]+:(?:on|off)|clear|faults", self.op):
            raise LocalProtocolError(f"simulator control is fault:<name>:on|off, clear or faults, not {self.op!r}")

    @property
    def body(self) -> str:
        return f"{CONTROL_VERB}={self.op}"


class Home(Command, frozen=True):
    expect: ClassVar[Expect] = Expect.ACTION

    @property
    def body(self) -> str:
        return "action=home"


JOG_LIMIT = 300
JOG_STEP = 0.001
"""The finest jog written: `len` is a quoted plain decimal (reference, Jog), three places at most, never an
exponent (`1e-05`), which a firmware reading digits would take as 1 mm."""


class Jog(Command, frozen=True):
    axis: str
    distance: float
    expect: ClassVar[Expect] = Expect.ACTION

    def __post_init__(self) -> None:
        if self.axis not in ("x", "y", "z"):
            raise LocalProtocolError(f"jog axis must be x, y or z, not {self.axis!r}")
        if not (JOG_STEP <= abs(self.distance) <= JOG_LIMIT):  # nan too
            raise LocalProtocolError(f"jog distance must be {JOG_STEP:g} to {JOG_LIMIT} mm either way, "
                                     f"not {self.distance:g}")

    @property
    def body(self) -> str:
        sign = "-" if self.distance < 0 else "+"
        length = f"{abs(self.distance):.3f}".rstrip("0").rstrip(".")
        return f'action=jog:{{"axis":"{self.axis}","dir":"{sign}","len":"{length}"}}'


FLOW_OPS: dict[str, tuple[str, ...]] = {
    "load": ("new", "cancel", "retry"),
    "unload": ("new", "cancel", "retry"),
    "cleannozzle": ("new", "cancel"),
    "calibratejr": ("new", "detectorok", "getdata", "release"),
}


class Flow(Command, frozen=True):
    """`action=<flow>:<op>` for load, unload, cleannozzle and calibratejr."""

    flow: str
    op: str
    expect: ClassVar[Expect] = Expect.ACTION

    def __post_init__(self) -> None:
        ops = FLOW_OPS.get(self.flow)
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


class Upload(Command, frozen=True):
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


class FirmwareUpload(Command, frozen=True):
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


class UploadDidFinish(Command, frozen=True):
    expect: ClassVar[Expect] = Expect.FINISH

    @property
    def body(self) -> str:
        return "uploadDidFinish"


class UnknownCommand(Command, frozen=True):
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
