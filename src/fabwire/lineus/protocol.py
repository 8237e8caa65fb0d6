"""Line-us TCP protocol, both roles, without I/O.

Host → device: one G-code line ended by any run of `\\r`, `\\n`, `\\0`. Device → host: `hello …`, `ok …` or
`error …` followed by ` KEY:value` pairs and ended by exactly `\\r\\n\\0`. Commands are typed values that
validate their parameters, so the client cannot send what the device would refuse and the simulator
parses with the same grammar it answers with.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import ClassVar, Literal

from fabwire.errors import LocalProtocolError, RemoteProtocolError

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
        raise LocalProtocolError(f"{what}: {text!r} is not a number")
    value = float(text)
    if abs(value) > COORD_LIMIT:
        raise LocalProtocolError(f"{what}: {text} is out of range")
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


def _quote(value: str, always: bool = False) -> str:
    if always or value == "" or _NEEDS_QUOTES.search(value):
        if '"' in value:
            raise LocalProtocolError(f"a value cannot contain a double quote: {value!r}")
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
            raise LocalProtocolError(f"a machine name is 1-32 of A-Z a-z 0-9 -, got {self.name!r}")

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
        out = ["S" + _quote(self.ssid)]
        if self.password is not None:
            out.append("P" + _quote(self.password))
        return out


@dataclass(frozen=True, slots=True)
class ForgetWifi(Command):
    """M588: forget one network, or all with `*`."""

    ssid: str = "*"
    code: ClassVar[str] = "M588"

    def __post_init__(self) -> None:
        _check_text(self.ssid, "SSID", 32)

    def params(self) -> list[str]:
        return ["S" + _quote(self.ssid)]


@dataclass(frozen=True, slots=True)
class FirmwareUpdate(Command):
    code: ClassVar[str] = "M997"


# ---------------------------------------------------------------------------------------------------------------
# parsing a command line (device side)


def split_fields(text: str) -> list[str]:
    """Whitespace-separated tokens; a double-quoted run keeps its spaces (quotes removed)."""
    if '"' not in text:
        return text.split()
    tokens: list[str] = []
    current: list[str] = []
    in_token = False
    quoted = False
    for ch in text:
        if quoted:
            if ch == '"':
                quoted = False
            else:
                current.append(ch)
        elif ch == '"':
            quoted = True
            in_token = True
        elif ch in " \t":
            if in_token:
                tokens.append("".join(current))
                current, in_token = [], False
        else:
            current.append(ch)
            in_token = True
    if quoted:
        raise RemoteProtocolError("unbalanced double quote")
    if in_token:
        tokens.append("".join(current))
    return tokens


_CODE_RE = re.compile(r"([GM])(\d{1,3})")


def _normalise_code(word: str) -> str:
    match = _CODE_RE.fullmatch(word.upper())
    if match is None:
        raise RemoteProtocolError(f"not a command: {word!r}")
    letter, digits = match.groups()
    number = int(digits)
    return f"{letter}{number:02d}" if letter == "G" else f"M{number}"


@dataclass(frozen=True, slots=True)
class _Params:
    code: str
    values: dict[str, str] = field(default_factory=dict)

    def take(self, letter: str) -> str | None:
        return self.values.pop(letter, None)

    def number(self, letter: str) -> float | None:
        raw = self.take(letter)
        return None if raw is None else parse_number(raw, f"{self.code} {letter}")

    def integer(self, letter: str) -> int | None:
        raw = self.take(letter)
        if raw is None:
            return None
        if not re.fullmatch(r"[+-]?\d{1,6}", raw):
            raise LocalProtocolError(f"{self.code} {letter}: {raw!r} is not a whole number")
        return int(raw)

    def finish(self) -> None:
        if self.values:
            raise LocalProtocolError(f"{self.code} does not take {', '.join(sorted(self.values))}")


_PLAIN_MOVE = re.compile(r"[Gg]0{0,2}([01])((?:[ \t]+[XYZxyz][+-]?(?:\d+(?:\.\d*)?|\.\d+))+)")
"""A G00/G01 line of plain numbers: the bulk of any drawing, parsed without the general machinery."""


def parse_command(line: str) -> Command:
    """One received line (terminators removed) → a typed command, or RemoteProtocolError saying why not."""
    match = _PLAIN_MOVE.fullmatch(line)
    if match is not None:
        axes: dict[str, float] = {}
        for token in match.group(2).split():
            value = float(token[1:]) + 0.0
            letter = token[0].upper()
            if letter in axes or abs(value) > COORD_LIMIT:
                break  # duplicated or out of range: the general parser says which
            axes[letter] = value
        else:
            return Move(axes.get("X"), axes.get("Y"), axes.get("Z"), rapid=match.group(1) == "0")
    try:
        return _parse(line)
    except LocalProtocolError as exc:
        raise RemoteProtocolError(str(exc)) from None


_HEAD = re.compile(r"([GgMm]\d{1,3})(?=[A-Za-z]|$)")
_RUN_TOGETHER = re.compile(r"(?:[A-Za-z][+-]?(?:\d+(?:\.\d*)?|\.\d+))+")
_ONE_PARAM = re.compile(r"[A-Za-z][+-]?(?:\d+(?:\.\d*)?|\.\d+)")


def command_code(line: str) -> str | None:
    """The normalised code a line starts with (`G01`, `M114`), or None when it does not start with one."""
    tokens = line.split(maxsplit=1)
    match = _HEAD.match(tokens[0]) if tokens else None
    return _normalise_code(match.group(1)) if match else None


def _g_tokens(tokens: list[str]) -> list[str]:
    """`G01X1000Y0` and `X1400Y0`: G-code parameters written without spaces, as converters do, split apart.
    Only numeric G parameters are split; M-code values are text (`M550 Pmy-bot2`)."""
    head = _HEAD.match(tokens[0])
    if head is None or head.group(1)[0] not in "Gg":
        return tokens
    out = [head.group(1)]
    rest = tokens[0][head.end():]
    for token in ([rest] if rest else []) + tokens[1:]:
        out.extend(_ONE_PARAM.findall(token) if _RUN_TOGETHER.fullmatch(token) else [token])
    return out


def _parse(line: str) -> Command:
    tokens = split_fields(line)
    if not tokens:
        raise RemoteProtocolError("empty command")
    tokens = _g_tokens(tokens)
    code = _normalise_code(tokens[0])
    p = _Params(code)
    flags: set[str] = set()
    for token in tokens[1:]:
        letter, value = token[0].upper(), token[1:]
        if not letter.isalpha():
            raise RemoteProtocolError(f"{code}: bad parameter {token!r}")
        if letter in p.values or letter in flags:
            raise RemoteProtocolError(f"{code}: parameter {letter} given twice")
        if value:
            p.values[letter] = value
        elif code == "M114" and letter == "S":
            flags.add(letter)
        else:
            raise RemoteProtocolError(f"{code}: parameter {letter} has no value")
    command = _build(code, p, flags)
    p.finish()
    return command


def _lower_values(p: _Params, letter: str) -> str | None:
    raw = p.take(letter)
    return None if raw is None else raw.lower()


def _build(code: str, p: _Params, flags: set[str]) -> Command:
    if code in ("G00", "G01"):
        return Move(p.number("X"), p.number("Y"), p.number("Z"), rapid=code == "G00")
    if code == "G28":
        return Home()
    if code == "G31":
        raw = p.take("S")
        if raw is None:
            return ZMap()
        if raw.lower() == "clear":
            return ZMap(clear=True)
        parts = raw.split(";")
        if len(parts) != 4:
            raise RemoteProtocolError("G31 S needs four values separated by ';'")
        a, b, c, d = (parse_number(part, "G31 S") for part in parts)
        return ZMap((a, b, c, d))
    if code == "G40":
        x, y, z = p.number("X"), p.number("Y"), p.number("Z")
        keep = _lower_values(p, "K")
        if keep not in (None, "xy", "z"):
            raise RemoteProtocolError("G40 K must be xy or z")
        return RawMove(x, y, z, keep)  # type: ignore[arg-type]
    if code == "G54":
        x, y, s = p.number("X"), p.number("Y"), p.number("S")
        return SetOrigin(x if x is not None else 0.0, y if y is not None else 0.0, s if s is not None else 1.0)
    if code == "G94":
        return SetSpeed(p.number("S"), p.number("P"))
    if code == "M20":
        return ListFiles()
    if code == "M23":
        mode = p.integer("S")
        return MemoryDrawing(0 if mode is None else mode, p.take("K"))
    if code in ("M28", "M30"):
        slot = p.integer("S")
        if slot is None:
            raise RemoteProtocolError(f"{code} needs S<drawing number 1-32>")
        return StartSave(slot) if code == "M28" else DeleteFile(slot)
    if code == "M29":
        return EndSave()
    if code == "M39":
        return StorageUsage()
    if code == "M85":
        seconds, period = p.number("S"), p.number("P")
        return TimedDemo(seconds or 0.0, period or 0.0, p.integer("K"))
    if code == "M114":
        return GetPosition(servos="S" in flags)
    if code == "M115":
        return Capabilities()
    if code == "M122":
        return Diagnostics()
    if code in ("M170", "M172"):
        return Reserved(int(code[1:]))
    if code == "M171":
        reset = p.take("S")
        if reset not in ("CONFIRM", "SPIFFS"):
            raise RemoteProtocolError("M171 needs SCONFIRM or SSPIFFS")
        return FactoryReset(wipe_files=reset == "SPIFFS")
    if code == "M280":
        return ReverseServos()
    if code == "M291":
        mode = p.integer("S")
        if mode not in (1, 2):
            raise RemoteProtocolError("M291 needs S1 (gestures on) or S2 (off)")
        return Gestures(on=mode == 1)
    if code == "M374":
        raw = _lower_values(p, "S")
        if raw not in (None, "clear"):
            raise RemoteProtocolError("M374 takes no parameter or Sclear")
        return SaveCalibration(clear=raw == "clear")
    if code == "M550":
        return MachineName(p.take("P"))
    if code == "M552":
        return StartupMode(p.integer("S"), p.integer("P"))
    if code == "M587":
        return Wifi(p.take("S"), p.take("P"))
    if code == "M588":
        ssid = p.take("S")
        if ssid is None:
            raise RemoteProtocolError("M588 needs S<ssid> or S*")
        return ForgetWifi(ssid)
    if code == "M997":
        return FirmwareUpdate()
    raise RemoteProtocolError(f"unknown command {code}")


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
                raise LocalProtocolError(f"bad reply key {key!r}")
            if not value.isascii() or _BAD_VALUE.search(value):
                raise LocalProtocolError(f"bad reply value {value!r}")

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
        pairs = (f"{_quote(k) if ' ' in k else k}:{_quote(v, k in self.quoted)}" for k, v in self.fields)
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
        return self.firmware[0] if self.firmware else 0

    def text(self) -> str:
        pairs = (("VERSION", self.version), ("NAME", self.name), ("SERIAL", self.serial), *self.extra)
        return " ".join(["hello", *(f"{k}:{_quote(v)}" for k, v in pairs)])

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
        raise RemoteProtocolError(f"reply starts with {status!r}, not ok/error/hello")
    pairs: list[tuple[str, str]] = []
    for token in tokens[1:]:
        key, sep, value = token.partition(":")
        if not sep or not key:
            raise RemoteProtocolError(f"reply field {token!r} is not KEY:value")
        if _FORBIDDEN.search(token):
            raise RemoteProtocolError(f"reply field {token!r} holds a forbidden character")
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
        raw = bytes(self._buffer[:end])
        del self._buffer[: end + len(REPLY_TERMINATOR)]
        try:
            text = raw.decode("ascii")
        except UnicodeDecodeError:
            raise RemoteProtocolError(f"reply is not ASCII text: {raw[:40]!r}") from None
        return parse_message(text)
