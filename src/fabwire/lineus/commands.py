"""Line-us G-code commands (host → device) as typed values, and the number and text rules they follow.

Each command validates its parameters when built, so the client cannot send what the device would refuse; `text()`
is the line as sent. Sources: the GCodeSpec (1.0.4a, 3.2.0) and the Line-us-Programming README.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import ClassVar, Literal

from fabwire.errors import LocalProtocolError, excerpt

REPLY_TERMINATOR = b"\r\n\x00"
COMMAND_TERMINATOR = b"\x00"
TERMINATOR_BYTES = b"\r\n\x00"
MAX_LINE = 1024
"""Longest command line the device side accepts (the real controller has a small fixed buffer)."""
MAX_REPLY = 65536
"""Longest reply the host side buffers before deciding the peer is not a Line-us."""
COORD_LIMIT = 100_000.0
NAME_RE = re.compile(r"[A-Za-z0-9-]{1,32}")
FILE_SLOTS = range(1, 33)

Number = float


# ---------------------------------------------------------------------------------------------------------------
# numbers and values


def format_number(value: float) -> str:
    """Fixed-point text without exponent: the firmware misreads `1e-05`."""
    if not math.isfinite(value):
        raise LocalProtocolError(f"cannot send a non-finite number ({value})")
    if value == int(value) and abs(value) < 1e15:
        return str(int(value))
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def encode_position(x: float, y: float, z: float, decimals: bool) -> bytes:
    """`ok X:… Y:… Z:…` with its terminator: the reply to every move, so it is built without the general
    reply machinery (its three values can never need quoting)."""
    return (f"ok X:{format_coordinate(x, decimals)} Y:{format_coordinate(y, decimals)} "
            f"Z:{format_coordinate(z, decimals)}").encode("ascii") + REPLY_TERMINATOR


def format_coordinate(value: float, decimals: bool) -> str:
    """Reply style: firmware 3 prints two decimals (`1000.00`), firmware 1 integers (`1000`)."""
    if decimals:
        text = f"{value:.2f}"
        return "0.00" if text == "-0.00" else text
    return str(round(value))


_NUMBER_RE = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)")


def parse_number(text: str, what: str) -> float:
    """A decimal number as the device reads it; exponents, NaN and infinities are refused."""
    if not _NUMBER_RE.fullmatch(text):
        raise LocalProtocolError(f"{what}: {excerpt(text, 40)} is not a number")
    value = float(text)
    if abs(value) > COORD_LIMIT:
        raise LocalProtocolError(f"{what}: {excerpt(text, 40)[1:-1]} is out of range")
    return value + 0.0


def _check_number(value: float | None, what: str, low: float = -COORD_LIMIT, high: float = COORD_LIMIT) -> None:
    if value is None:
        return
    if type(value) is float and low <= value <= high:  # the common case; NaN fails the comparison
        return
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise LocalProtocolError(f"{what} must be a number, not {type(value).__name__}")
    if not math.isfinite(value) or not low <= value <= high:
        raise LocalProtocolError(f"{what} must be between {format_number(low)} and {format_number(high)}, got {value}")


ALWAYS_QUOTED = frozenset({"FS", "INFO", "ZMap"})
"""Reply keys the firmware quotes whatever the value (file lists, messages)."""


_NEEDS_QUOTES = re.compile(r'[ \t"]')


def quote_value(value: str, always: bool = False) -> str:
    """A reply or parameter value, double-quoted when it holds blanks or is empty (or `always`)."""
    if always or value == "" or _NEEDS_QUOTES.search(value):
        if '"' in value:
            raise LocalProtocolError(f"a value cannot contain a double quote: {excerpt(value, 40)}")
        return f'"{value}"'
    return value


def _check_text(value: str, what: str, max_len: int, *, allow_space: bool = True) -> None:
    if not isinstance(value, str) or not value:
        raise LocalProtocolError(f"{what} must not be empty")
    if len(value) > max_len:
        raise LocalProtocolError(f"{what} is longer than {max_len} characters")
    if '"' in value or any(ord(ch) < 32 or ord(ch) > 126 for ch in value):
        raise LocalProtocolError(f"{what} may hold printable ASCII only and no double quote: {value!r}")
    if not allow_space and " " in value:
        raise LocalProtocolError(f"{what} may not contain spaces: {value!r}")


# ---------------------------------------------------------------------------------------------------------------
# commands (host → device)


@dataclass(frozen=True, slots=True)
class Command:
    """Base of every command; `text()` is the line without terminator."""

    code: ClassVar[str] = ""
    moves: ClassVar[bool] = False
    """Movement commands' replies wait for the motion queue."""

    def params(self) -> list[str]:
        return []

    def text(self) -> str:
        return " ".join([self.code, *self.params()])

    def encode(self) -> bytes:
        return self.text().encode("ascii") + COMMAND_TERMINATOR


def _axes(x: float | None, y: float | None, z: float | None) -> list[str]:
    out = []
    for letter, value in (("X", x), ("Y", y), ("Z", z)):
        if value is not None:
            out.append(letter + format_number(value))
    return out


@dataclass(frozen=True, slots=True)
class Move(Command):
    """G01 (straight line at the G94 step) or G00 (rapid, joint space); omitted axes keep their value."""

    x: float | None = None
    y: float | None = None
    z: float | None = None
    rapid: bool = False
    moves: ClassVar[bool] = True

    def __post_init__(self) -> None:
        for letter, value in (("X", self.x), ("Y", self.y), ("Z", self.z)):
            _check_number(value, letter)
        if self.x is None and self.y is None and self.z is None:
            raise LocalProtocolError("a move needs at least one of X, Y, Z")

    def text(self) -> str:
        return " ".join(["G00" if self.rapid else "G01", *_axes(self.x, self.y, self.z)])


@dataclass(frozen=True, slots=True)
class Home(Command):
    code: ClassVar[str] = "G28"
    moves: ClassVar[bool] = True


@dataclass(frozen=True, slots=True)
class ZMap(Command):
    """G31: four corner offsets (TL, TR, BR, BL), `clear`, or None to query."""

    corners: tuple[float, float, float, float] | None = None
    clear: bool = False
    code: ClassVar[str] = "G31"

    def __post_init__(self) -> None:
        if self.clear and self.corners is not None:
            raise LocalProtocolError("G31 takes corners or clear, not both")
        if self.corners is not None:
            if len(self.corners) != 4:
                raise LocalProtocolError("G31 needs exactly four corner values")
            for value in self.corners:
                _check_number(value, "G31 corner", -1000, 1000)

    def params(self) -> list[str]:
        if self.clear:
            return ["Sclear"]
        if self.corners is not None:
            return ["S" + ";".join(format_number(v) for v in self.corners)]
        return []


@dataclass(frozen=True, slots=True)
class RawMove(Command):
    """G40: a move that ignores G54 and calibration; `keep` re-applies `xy` or `z` calibration."""

    x: float | None = None
    y: float | None = None
    z: float | None = None
    keep: Literal["xy", "z"] | None = None
    code: ClassVar[str] = "G40"
    moves: ClassVar[bool] = True

    def __post_init__(self) -> None:
        for letter, value in (("X", self.x), ("Y", self.y), ("Z", self.z)):
            _check_number(value, letter)
        if self.keep not in (None, "xy", "z"):
            raise LocalProtocolError("G40 K must be xy or z")

    def params(self) -> list[str]:
        return _axes(self.x, self.y, self.z) + ([f"K{self.keep}"] if self.keep else [])


@dataclass(frozen=True, slots=True)
class SetOrigin(Command):
    """G54: machine = drawing × S + (X, Y), kept per connection."""

    x: float = 0.0
    y: float = 0.0
    scale: float = 1.0
    code: ClassVar[str] = "G54"

    def __post_init__(self) -> None:
        _check_number(self.x, "G54 X")
        _check_number(self.y, "G54 Y")
        _check_number(self.scale, "G54 S", -1000, 1000)

    def params(self) -> list[str]:
        return [f"X{format_number(self.x)}", f"Y{format_number(self.y)}", f"S{format_number(self.scale)}"]


STEP_MIN, STEP_MAX = 1.0, 30.0


@dataclass(frozen=True, slots=True)
class SetSpeed(Command):
    """G94: largest interpolation step in units, S for pen-down moves and P for pen-up moves (1–30)."""

    draw: float | None = None
    travel: float | None = None
    code: ClassVar[str] = "G94"

    def __post_init__(self) -> None:
        if self.draw is None and self.travel is None:
            raise LocalProtocolError("G94 needs S (pen-down step) or P (pen-up step)")
        _check_number(self.draw, "G94 S", STEP_MIN, STEP_MAX)
        _check_number(self.travel, "G94 P", STEP_MIN, STEP_MAX)

    def params(self) -> list[str]:
        out = []
        if self.draw is not None:
            out.append("S" + format_number(self.draw))
        if self.travel is not None:
            out.append("P" + format_number(self.travel))
        return out


@dataclass(frozen=True, slots=True)
class ListFiles(Command):
    code: ClassVar[str] = "M20"


@dataclass(frozen=True, slots=True)
class MemoryDrawing(Command):
    """M23: 0 default, 1 memory drawing, 2 follow (K = channel), 3 unfollow."""

    mode: int = 0
    channel: str | None = None
    code: ClassVar[str] = "M23"

    def __post_init__(self) -> None:
        if self.mode not in (0, 1, 2, 3):
            raise LocalProtocolError("M23 S must be 0, 1, 2 or 3")
        if self.channel is not None:
            _check_text(self.channel, "M23 K", 32, allow_space=False)

    def params(self) -> list[str]:
        return [f"S{self.mode}"] + ([f"K{self.channel}"] if self.channel else [])


def _check_slot(slot: int, code: str) -> None:
    if isinstance(slot, bool) or not isinstance(slot, int) or slot not in FILE_SLOTS:
        raise LocalProtocolError(f"{code} S must be a drawing number from 1 to 32, got {slot!r}")


@dataclass(frozen=True, slots=True)
class StartSave(Command):
    """M28: later commands on this connection are stored in drawing `slot` until M29."""

    slot: int = 1
    code: ClassVar[str] = "M28"

    def __post_init__(self) -> None:
        _check_slot(self.slot, "M28")

    def params(self) -> list[str]:
        return [f"S{self.slot}"]


@dataclass(frozen=True, slots=True)
class EndSave(Command):
    code: ClassVar[str] = "M29"


@dataclass(frozen=True, slots=True)
class DeleteFile(Command):
    slot: int = 1
    code: ClassVar[str] = "M30"

    def __post_init__(self) -> None:
        _check_slot(self.slot, "M30")

    def params(self) -> list[str]:
        return [f"S{self.slot}"]


@dataclass(frozen=True, slots=True)
class StorageUsage(Command):
    code: ClassVar[str] = "M39"


@dataclass(frozen=True, slots=True)
class TimedDemo(Command):
    """M85: every `period` s draw the first `seconds` s of the last memory drawing (K locks to one)."""

    seconds: float = 0
    period: float = 0
    drawing: int | None = None
    code: ClassVar[str] = "M85"

    def __post_init__(self) -> None:
        _check_number(self.seconds, "M85 S", 0, 86400)
        _check_number(self.period, "M85 P", 0, 86400)
        if self.drawing is not None:
            _check_slot(self.drawing, "M85 K")

    def params(self) -> list[str]:
        out = [f"S{format_number(self.seconds)}", f"P{format_number(self.period)}"]
        return out + ([f"K{self.drawing}"] if self.drawing is not None else [])


@dataclass(frozen=True, slots=True)
class GetPosition(Command):
    """M114; with `servos` (M114 S) the servo angles instead."""

    servos: bool = False
    code: ClassVar[str] = "M114"

    def params(self) -> list[str]:
        return ["S"] if self.servos else []


@dataclass(frozen=True, slots=True)
class Capabilities(Command):
    code: ClassVar[str] = "M115"


@dataclass(frozen=True, slots=True)
class Diagnostics(Command):
    code: ClassVar[str] = "M122"


@dataclass(frozen=True, slots=True)
class Reserved(Command):
    """M170/M172: internal codes; sendable only as the device accepts them bare."""

    number: int = 170

    def __post_init__(self) -> None:
        if self.number not in (170, 172):
            raise LocalProtocolError("reserved codes are M170 and M172")

    def text(self) -> str:
        return f"M{self.number}"


@dataclass(frozen=True, slots=True)
class FactoryReset(Command):
    """M171 SCONFIRM (settings) or SSPIFFS (also wipes drawings and calibration)."""

    wipe_files: bool = False
    code: ClassVar[str] = "M171"

    def params(self) -> list[str]:
        return ["SSPIFFS" if self.wipe_files else "SCONFIRM"]


@dataclass(frozen=True, slots=True)
class ReverseServos(Command):
    code: ClassVar[str] = "M280"


@dataclass(frozen=True, slots=True)
class Gestures(Command):
    on: bool = True
    code: ClassVar[str] = "M291"

    def params(self) -> list[str]:
        return ["S1" if self.on else "S2"]


@dataclass(frozen=True, slots=True)
class SaveCalibration(Command):
    """M374: store the XY calibration with the arm at the calibration point, or clear it."""

    clear: bool = False
    code: ClassVar[str] = "M374"

    def params(self) -> list[str]:
        return ["Sclear"] if self.clear else []


@dataclass(frozen=True, slots=True)
class MachineName(Command):
    """M550: query (None) or set the name, `[A-Za-z0-9-]{1,32}`."""

    name: str | None = None
    code: ClassVar[str] = "M550"

    def __post_init__(self) -> None:
        if self.name is not None and (not isinstance(self.name, str) or not NAME_RE.fullmatch(self.name)):
            raise LocalProtocolError(f"a machine name is 1-32 of A-Z a-z 0-9 -, got {excerpt(self.name, 40)}")

    def params(self) -> list[str]:
        return [f"P{self.name}"] if self.name is not None else []


@dataclass(frozen=True, slots=True)
class StartupMode(Command):
    """M552: S1 Blue, S2 AP, S3 AP locked, S4 Blue + long press; P1/P2 choose the AP name."""

    mode: int | None = None
    ap_name: int | None = None
    code: ClassVar[str] = "M552"

    def __post_init__(self) -> None:
        if self.mode is None and self.ap_name is None:
            raise LocalProtocolError("M552 needs S (mode 1-4) or P (AP name 1-2)")
        if self.mode is not None and self.mode not in (1, 2, 3, 4):
            raise LocalProtocolError("M552 S must be 1, 2, 3 or 4")
        if self.ap_name is not None and self.ap_name not in (1, 2):
            raise LocalProtocolError("M552 P must be 1 or 2")

    def params(self) -> list[str]:
        out = []
        if self.mode is not None:
            out.append(f"S{self.mode}")
        if self.ap_name is not None:
            out.append(f"P{self.ap_name}")
        return out


@dataclass(frozen=True, slots=True)
class Wifi(Command):
    """M587: list networks (no SSID) or store an SSID with an optional password."""

    ssid: str | None = None
    password: str | None = None
    code: ClassVar[str] = "M587"

    def __post_init__(self) -> None:
        if self.ssid is None:
            if self.password is not None:
                raise LocalProtocolError("M587 P needs an SSID (S)")
            return
        _check_text(self.ssid, "SSID", 32)
        if self.password is not None:
            _check_text(self.password, "Wi-Fi password", 64)

    def params(self) -> list[str]:
        if self.ssid is None:
            return []
        out = ["S" + quote_value(self.ssid)]
        if self.password is not None:
            out.append("P" + quote_value(self.password))
        return out


@dataclass(frozen=True, slots=True)
class ForgetWifi(Command):
    """M588: forget one network, or all with `*`."""

    ssid: str = "*"
    code: ClassVar[str] = "M588"

    def __post_init__(self) -> None:
        _check_text(self.ssid, "SSID", 32)

    def params(self) -> list[str]:
        return ["S" + quote_value(self.ssid)]


@dataclass(frozen=True, slots=True)
class FirmwareUpdate(Command):
    code: ClassVar[str] = "M997"
