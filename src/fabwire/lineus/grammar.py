"""Reading one Line-us command line (device side): whitespace-separated words, a code, then one letter per
parameter with its value; values may be double-quoted. `parse_command` turns a line into a typed command or says
why it cannot.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from fabwire.errors import LocalProtocolError, RemoteProtocolError, excerpt
from fabwire.lineus.commands import (
    COORD_LIMIT,
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
    parse_number,
)


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
        raise RemoteProtocolError(f"not a command: {excerpt(word, 40)}")
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
            raise LocalProtocolError(f"{self.code} {letter}: {excerpt(raw, 40)} is not a whole number")
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
_RUN_TOGETHER = re.compile(r"(?:[XYZSPKxyzspk][+-]?(?:\d+(?:\.\d*)?|\.\d+))+")
"""G parameters (the letters G codes take) written without spaces; `X1e3` is not two of them."""
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
            raise RemoteProtocolError(f"{code}: bad parameter {excerpt(token, 40)}")
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
