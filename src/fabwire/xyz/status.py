"""Status letters (`x:value` lines) to typed fields and back to the exact wire text.

One table maps each letter to a field, a parser and a renderer, so the client reads what the simulator
writes with the same code. A line that does not parse is kept raw in `unparsed`; an unknown letter in
`extra`: neither is ever fatal, and both render back unchanged.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable
from typing import Any

import msgspec

from fabwire.errors import InputError, visible
from fabwire.xyz.codes import (
    CANCELLING,
    CARTRIDGE_LENGTHS,
    COLOURS,
    DOOR_OPEN,
    FILE_CHECK,
    FILE_REJECTED,
    HEATER_TIMEOUT,
    IDLE,
    IDLE_NOISE,
    MATERIALS,
    NO_CARTRIDGE,
    NOZZLES,
    PAUSED,
    PRINT_DONE,
    PRINTING,
    STATE_NAMES,
    SUBSTATE_NAMES,
    ErrorWord,
    translate_state,
)
from fabwire.xyz.models import PrinterModel, find_model
from fabwire.xyz.protocol import DEFAULT_BLOCK_SIZE, NO_CARTRIDGE_SERIAL, REMAINING_UNKNOWN, block_size_from_packet

# ------------------------------------------------------------------------------------------- value types


class Progress(msgspec.Struct, frozen=True):
    percent: int
    elapsed_min: int
    remaining_min: int | None
    """None when the printer has no estimate (wire sentinel 71582788)."""


class Temperatures(msgspec.Struct, frozen=True):
    """`t:<n>,a[,b]`: n=1 → extruder and its target; otherwise two extruders. None = `--`."""

    count: int
    values: tuple[int | None, ...]

    @property
    def extruder(self) -> int | None:
        return self.values[0] if self.values else None

    @property
    def target(self) -> int | None:
        return self.values[1] if self.count == 1 and len(self.values) > 1 else None

    @property
    def extruder2(self) -> int | None:
        return self.values[1] if self.count != 1 and len(self.values) > 1 else None


class Cartridge(msgspec.Struct, frozen=True):
    """`w:<n>,<serial>[,x]`: n=1 → x is a default filament temperature; n=2 → x is the second spool."""

    count: int
    fields: tuple[str, ...]

    @property
    def serials(self) -> tuple[str, ...]:
        return self.fields[: max(1, self.count)] if self.count == 2 else self.fields[:1]

    @property
    def present(self) -> bool:
        return bool(self.fields) and self.fields[0] != NO_CARTRIDGE_SERIAL and not set(self.fields[0]) <= {"-"}

    @property
    def colour(self) -> str | None:
        return self.spool_colour(0)

    @property
    def material_code(self) -> str | None:
        return self.spool_material_code(0)

    @property
    def length_mm(self) -> int | None:
        return self.spool_length_mm(0)

    def spool_present(self, index: int) -> bool:
        """Whether spool `index` (0 or 1; the second only on two-spool printers) has a tag read."""
        serials = self.serials
        serial = serials[index] if index < len(serials) else ""
        return bool(serial) and serial != NO_CARTRIDGE_SERIAL and not set(serial) <= {"-"}

    def _serial(self, index: int) -> str:
        return self.serials[index] if self.spool_present(index) else ""

    def spool_colour(self, index: int) -> str | None:
        serial = self._serial(index)
        return COLOURS.get(serial[4:5]) if len(serial) > 4 else None

    def spool_material_code(self, index: int) -> str | None:
        serial = self._serial(index)
        return serial[2] if len(serial) > 2 else None

    def spool_length_mm(self, index: int) -> int | None:
        serial = self._serial(index)
        return CARTRIDGE_LENGTHS.get(serial[3:4]) if serial else None


class Nozzle(msgspec.Struct, frozen=True):
    kind: str
    serials: tuple[str, ...]

    @property
    def diameter_mm(self) -> float | None:
        return NOZZLES.get(self.kind)

    @property
    def laser(self) -> bool:
        return self.kind in ("L", "N", "H", "Q")


class Packet(msgspec.Struct, frozen=True):
    """`o:p<k>,t<x>,c<y>[,a±]`."""

    k: int
    t: str = "1"
    c: str = "1"
    autolevel: bool | None = None

    @property
    def block_size(self) -> int:
        return block_size_from_packet(self.k)


class Lifetime(msgspec.Struct, frozen=True):
    unknown: int
    machine_min: int
    extruder_min: int
    last_min: int | None = None


class Network(msgspec.Struct, frozen=True):
    ip: str
    ssid: str | None = None
    channel: str | None = None
    rssi: int | None = None
    mac: str | None = None
    json_form: bool = True

    @property
    def connected(self) -> bool:
        return self.ip not in ("", "0.0.0.0")

    @property
    def signal_percent(self) -> int | None:
        if self.rssi is None:
            return None
        dbm = -self.rssi
        return 100 if dbm >= -50 else 0 if dbm <= -100 else 2 * (dbm + 100)

    def as_dict(self) -> dict[str, Any]:
        """For JSON: the firmware's `rssiValue` (a positive number) as dBm, and as the percentage XYZware shows."""
        return {"connected": self.connected, "ip": self.ip, "ssid": self.ssid, "mac": self.mac,
                "rssi_dbm": -self.rssi if self.rssi is not None else None, "signal_percent": self.signal_percent}


# ------------------------------------------------------------------------------------ parsers / renderers


def _opt_int(text: str) -> int | None:
    text = text.strip()
    return None if text.startswith("--") else int(text)


def _fmt_opt(value: int | None) -> str:
    return "--" if value is None else str(value)


def _ints(text: str) -> tuple[int, ...]:
    return tuple(int(x) for x in text.split(","))


def _fmt_ints(values: Iterable[int]) -> str:
    return ",".join(str(v) for v in values)


def _progress(text: str) -> Progress:
    pct, elapsed, remaining = (int(x) for x in text.split(","))
    return Progress(pct, elapsed, None if remaining == REMAINING_UNKNOWN or remaining < 0 else remaining)


def _fmt_progress(p: Progress) -> str:
    return f"{p.percent},{p.elapsed_min},{REMAINING_UNKNOWN if p.remaining_min is None else p.remaining_min}"


def _temps(text: str) -> Temperatures:
    head, *rest = text.split(",")
    return Temperatures(int(head), tuple(_opt_int(x) for x in rest))


def _fmt_temps(t: Temperatures) -> str:
    return ",".join([str(t.count), *(_fmt_opt(v) for v in t.values)])


def _cal(text: str) -> tuple[str, ...]:
    if not (text.startswith("{") and text.endswith("}")):
        raise ValueError("calibration values are enclosed in braces")
    parts = tuple(x.strip() for x in text[1:-1].split(",") if x.strip())
    for part in parts[:9]:
        int(part)
    for part in parts[9:]:
        float(part)
    return parts


def _state(text: str) -> tuple[int, int | None]:
    head, _, sub = text.partition(",")
    return int(head), (int(sub) if sub else None)


def _fmt_state(value: tuple[int, int | None]) -> str:
    return str(value[0]) + ("" if value[1] is None else f",{value[1]}")


def _cartridge(text: str) -> Cartridge:
    head, *rest = text.split(",")
    return Cartridge(int(head), tuple(rest))


def _nozzle(text: str) -> Nozzle:
    head, *rest = text.split(",")
    return Nozzle(head, tuple(rest))


def _packet(text: str) -> Packet:
    k, t, c, auto = 0, "1", "1", None
    for part in text.split(","):
        if part.startswith("p"):
            k = int(part[1:])
        elif part.startswith("t"):
            t = part[1:]
        elif part.startswith("c"):
            c = part[1:]
        elif part in ("a+", "a-"):
            auto = part == "a+"
    return Packet(k, t, c, auto)


def _fmt_packet(p: Packet) -> str:
    auto = "" if p.autolevel is None else (",a+" if p.autolevel else ",a-")
    return f"p{p.k},t{p.t},c{p.c}{auto}"


def _lifetime(text: str) -> Lifetime:
    values = _ints(text)
    return Lifetime(values[0], values[1], values[2], values[3] if len(values) > 3 else None)


def _fmt_lifetime(v: Lifetime) -> str:
    return _fmt_ints([v.unknown, v.machine_min, v.extruder_min, *([] if v.last_min is None else [v.last_min])])


def _json_obj(text: str) -> dict[str, Any]:
    value = _json_any(text)
    if not isinstance(value, dict):
        raise ValueError("expected a JSON object")
    return value


def _json_any(text: str) -> Any:
    """A JSON value whose strings are all text: a `\\ud800` escape (a lone surrogate, which no output can
    write) is a ValueError, so the line is kept raw like any other value that does not parse."""
    value = json.loads(text)
    if not text.isascii() or "\\u" in text:  # only an escape or a character of the text can be a surrogate
        json.dumps(value, ensure_ascii=False).encode("utf-8")  # UnicodeEncodeError (a ValueError) on a surrogate
    return value


def _fmt_json(value: Any) -> str:
    return json.dumps(value, separators=(",", ":"))


def _network(text: str) -> Network:
    if not text.startswith("{"):
        return Network(text.strip(), json_form=False)
    wlan = _json_obj(text).get("wlan", {})
    rssi = wlan.get("rssiValue")
    return Network(str(wlan.get("ip", "")), wlan.get("ssid"), wlan.get("channel"),
                   int(rssi) if rssi not in (None, "") else None, wlan.get("MAC"))


def _fmt_network(n: Network) -> str:
    if not n.json_form:
        return n.ip
    wlan = {"ip": n.ip, "ssid": n.ssid or "", "channel": n.channel or "0",
            "rssiValue": "" if n.rssi is None else str(n.rssi), "MAC": n.mac or ""}
    return _fmt_json({"wlan": wlan})


def _name(text: str) -> str:
    return text.rstrip(" ")


def _fmt_name(name: str) -> str:
    return name.ljust(16)


def _str(text: str) -> str:
    return text


def _versions(text: str) -> tuple[str, ...]:
    return tuple(text.split(","))


Parser = Callable[[str], Any]
Renderer = Callable[[Any], str]

LETTERS: dict[str, tuple[str, Parser, Renderer]] = {
    "b": ("bed", _opt_int, _fmt_opt),
    "c": ("calibration", _cal, lambda v: "{" + ",".join(v) + "}"),
    "d": ("progress", _progress, _fmt_progress),
    "e": ("errors", _ints, _fmt_ints),
    "f": ("filament", _ints, _fmt_ints),
    "h": ("pla", int, str),
    "i": ("serial", _str, _str),
    "j": ("state", _state, _fmt_state),
    "k": ("material", int, str),
    "l": ("language", _str, _str),
    "m": ("m", _ints, _fmt_ints),
    "n": ("name", _name, _fmt_name),
    "o": ("packet", _packet, _fmt_packet),
    "O": ("targets", _json_obj, _fmt_json),
    "p": ("model_number", _str, _str),
    "s": ("settings", _json_obj, _fmt_json),
    "t": ("temperatures", _temps, _fmt_temps),
    "v": ("firmware", _versions, ",".join),
    "w": ("cartridge", _cartridge, lambda c: ",".join([str(c.count), *c.fields])),
    "z": ("zoffset", int, str),
    "G": ("last_used", _json_obj, _fmt_json),
    "L": ("lifetime", _lifetime, _fmt_lifetime),
    "V": ("wifi_firmware", _str, _str),
    "W": ("networks", _json_any, _fmt_json),
    "X": ("nozzle", _nozzle, lambda n: ",".join([n.kind, *n.serials])),
    "4": ("network", _network, _fmt_network),
    "Z": ("print_file", _json_obj, _fmt_json),
}


SHARED_LETTERS = frozenset(letter for letter, spec in LETTERS.items() if spec[1] not in (_json_obj, _json_any))
"""Letters whose parsed value is immutable (numbers, strings, tuples, frozen structs): statuses parsed from the
same line may share it. A JSON object or list is parsed afresh for each status."""

_EXTRA, _DASHED, _PARSED, _UNPARSED = range(4)
_Read = tuple[str, str, int, Any]
"""A line read: its letter, its field (or "" for an unknown letter), what it was (_EXTRA … _UNPARSED), and the
parsed value (or the raw text for _EXTRA and _UNPARSED)."""
LINE_MEMORY = 4096
"""Lines read recently, remembered (a bench of printers answers mostly the same lines each poll): between one
and two generations of this many distinct lines."""
_recent: dict[str, _Read] = {}
_older: dict[str, _Read] = {}


def _read(line: str) -> _Read | None:
    """One `x:value` line, read as `Status.update` takes it; None when it is no such line."""
    global _recent, _older
    known = _recent.get(line)
    if known is not None:
        return known
    known = _older.get(line)
    if known is None:
        text = visible(line)
        if text[1:2] != ":":  # a control character first: shown as `\\xNN`, it is no letter
            return None
        letter, value = text[0], text[2:]
        spec = LETTERS.get(letter)
        if spec is None:
            known = (letter, "", _EXTRA, value)
        elif value.strip() == "--":
            known = (letter, spec[0], _DASHED, None)
        else:
            try:
                known = (letter, spec[0], _PARSED, spec[1](value))
            except (ValueError, IndexError, TypeError, AttributeError, RecursionError, OverflowError):
                known = (letter, spec[0], _UNPARSED, value)  # a value from the wire that does not parse is kept raw
        if letter not in SHARED_LETTERS and known[2] == _PARSED:
            return known
    if len(_recent) >= LINE_MEMORY:
        _older, _recent = _recent, {}
    _recent[line] = known
    return known


# ----------------------------------------------------------------------------------------------- status


class Status(msgspec.Struct, frozen=True):
    """Everything the printer reported; a letter it did not send stays None."""

    bed: int | None = None
    calibration: tuple[str, ...] | None = None
    progress: Progress | None = None
    errors: tuple[int, ...] | None = None
    filament: tuple[int, ...] | None = None
    pla: int | None = None
    serial: str | None = None
    state: tuple[int, int | None] | None = None
    material: int | None = None
    language: str | None = None
    m: tuple[int, ...] | None = None
    name: str | None = None
    packet: Packet | None = None
    targets: dict[str, Any] | None = None
    model_number: str | None = None
    settings: dict[str, Any] | None = None
    temperatures: Temperatures | None = None
    firmware: tuple[str, ...] | None = None
    cartridge: Cartridge | None = None
    zoffset: int | None = None
    last_used: dict[str, Any] | None = None
    lifetime: Lifetime | None = None
    wifi_firmware: str | None = None
    networks: Any = None
    nozzle: Nozzle | None = None
    network: Network | None = None
    print_file: dict[str, Any] | None = None
    order: tuple[str, ...] = ()
    """Letters in the order the printer sent them (rendering keeps it)."""
    extra: dict[str, str] = msgspec.field(default_factory=dict)
    """Letters this table does not know, raw."""
    unparsed: dict[str, str] = msgspec.field(default_factory=dict)
    """Known letters whose value did not parse, raw."""
    dashed: frozenset[str] = frozenset()
    """Letters reported as `--` (no such sensor, e.g. `b:--` on a printer without a heated bed)."""

    # -- parsing

    @classmethod
    def parse(cls, lines: Iterable[str]) -> Status:
        return cls().update(lines)

    def update(self, lines: Iterable[str]) -> Status:
        """This status with the letters in `lines` replaced (a partial query merges into the last full one)."""
        changes: dict[str, Any] = {}
        order = dict.fromkeys(self.order)
        extra = dict(self.extra)
        unparsed = dict(self.unparsed)
        dashed = set(self.dashed)
        recent = _recent
        for line in lines:
            read = recent.get(line) or (_read(line) if line[1:2] == ":" else None)
            if read is None:
                continue
            letter, attr, what, value = read
            order[letter] = None
            if what == _PARSED:
                changes[attr] = value
                if dashed:
                    dashed.discard(letter)
                if unparsed:
                    unparsed.pop(letter, None)
            elif what == _EXTRA:
                extra[letter] = value
            elif what == _DASHED:
                dashed.add(letter)
                if unparsed:
                    unparsed.pop(letter, None)
                changes[attr] = None
            else:
                dashed.discard(letter)
                unparsed[letter] = value
                changes[attr] = None
        return msgspec.structs.replace(self, order=tuple(order), extra=extra, unparsed=unparsed,
                                       dashed=frozenset(dashed), **changes)

    # -- rendering

    def line(self, letter: str) -> str | None:
        if letter in self.unparsed:
            return f"{letter}:{self.unparsed[letter]}"
        if letter in self.extra:
            return f"{letter}:{self.extra[letter]}"
        if letter in self.dashed:
            return f"{letter}:--"
        spec = LETTERS.get(letter)
        if spec is None:
            return None
        value = getattr(self, spec[0])
        return None if value is None else f"{letter}:{spec[2](value)}"

    def lines(self, letters: str | None = None) -> list[str]:
        """The wire lines (without `\\n`) for `letters` (all when None), in the printer's order."""
        present = [*self.order, *(letter for letter in self._set_letters() if letter not in self.order)]
        chosen = present if letters is None else [letter for letter in present if letter in letters]
        return [text for letter in chosen if (text := self.line(letter)) is not None]

    def _set_letters(self) -> list[str]:
        return [letter for letter, spec in LETTERS.items() if getattr(self, spec[0]) is not None]

    # -- decoded views

    @property
    def state_code(self) -> int | None:
        return translate_state(self.state[0]) if self.state else None

    @property
    def substate(self) -> int | None:
        return self.state[1] if self.state else None

    @property
    def state_name(self) -> str:
        code = self.state_code
        if code is None:
            return "unknown"
        name = STATE_NAMES.get(code, f"state {code}")
        sub = SUBSTATE_NAMES.get((code, self.substate or 0))
        return f"{name}: {sub}" if sub and sub != name else name

    @property
    def idle(self) -> bool:
        return self.state_code == IDLE

    @property
    def error_words(self) -> tuple[ErrorWord, ...]:
        noise = IDLE_NOISE.get(self.model_number or "", frozenset())
        return tuple(ErrorWord.decode(e) for e in (self.errors or ()) if e and e not in noise)

    @property
    def material_name(self) -> str | None:
        """`k:` is decimal on the wire; XYZware reads its hex spelling as the id (65 → "41" → ABS)."""
        if self.material is None:
            return None
        hex_text = f"{self.material:x}"
        return MATERIALS.get(self.material) or (MATERIALS.get(int(hex_text)) if hex_text.isdigit() else None)

    @property
    def wifi_networks(self) -> list[dict[str, Any]]:
        """`W:` (a scan) as a list: XYZware sends an array of objects, older notes show one object."""
        value = self.networks
        if isinstance(value, dict):
            return [value]
        if isinstance(value, list):
            return [v for v in value if isinstance(v, dict)]
        return []

    @property
    def extruder(self) -> int | None:
        return self.temperatures.extruder if self.temperatures else None

    @property
    def extruder_target(self) -> int | None:
        if self.temperatures and self.temperatures.target is not None:
            return self.temperatures.target
        if self.targets and str(self.targets.get("nozzle", "")).isdigit():
            return int(self.targets["nozzle"])
        return None

    @property
    def block_size(self) -> int:
        return self.packet.block_size if self.packet else DEFAULT_BLOCK_SIZE

    @property
    def autolevel(self) -> bool | None:
        return self.packet.autolevel if self.packet else None

    @property
    def buzzer(self) -> bool | None:
        value = (self.settings or {}).get("buzzer")
        return None if value is None else value == "on"

    @property
    def doors_open(self) -> tuple[str, ...]:
        doors = (self.settings or {}).get("dr") or {}
        return tuple(k for k, v in doors.items() if v == "on") if isinstance(doors, dict) else ()

    @property
    def filament_mm(self) -> int | None:
        return self.spool_filament_mm(0)

    @property
    def filament2_mm(self) -> int | None:
        """The second spool's filament left (`f:2,len1,len2`, Jr. 2.0 Mix and 2.0 Duo); None on one-spool models."""
        return self.spool_filament_mm(1)

    def spool_filament_mm(self, index: int) -> int | None:
        """Filament left on spool `index` in mm (`f:<count>,len1[,len2]`); None when unknown or not there."""
        if not self.filament or len(self.filament) < index + 2 or self.filament[index + 1] < 0:
            return None
        if index and self.filament[0] < index + 1:
            return None
        return self.filament[index + 1]

    @property
    def spools(self) -> list[dict[str, Any]]:
        """Each spool the printer reports (two on the Jr. 2.0 Mix and 2.0 Duo): its tag serial, colour, material
        and filament left."""
        cart = self.cartridge
        count = max(1, cart.count if cart and cart.count == 2 else 1, self.filament[0] if self.filament else 1)
        out = []
        for index in range(min(count, 2)):
            present = cart.spool_present(index) if cart else None
            out.append({"serial": cart.serials[index] if cart and present else None, "present": present,
                        "colour": cart.spool_colour(index) if cart else None,
                        "material_code": cart.spool_material_code(index) if cart else None,
                        "filament_left_mm": self.spool_filament_mm(index)})
        return out

    @property
    def model(self) -> PrinterModel | None:
        if not self.model_number:
            return None
        try:
            return find_model(self.model_number)
        except InputError:
            return None

    @property
    def firmware_version(self) -> str | None:
        return ",".join(self.firmware) if self.firmware else None

    def to_dict(self, since: tuple[Status, dict[str, Any]] | None = None, *,
                changed: frozenset[str] | None = None) -> dict[str, Any]:
        """A typed, JSON-ready view with units in the key names (°C, mm, s); absent values are null. The wire
        lines, letter by letter, are under `raw`.

        `since`, an earlier status and its view, spares the work for what did not change (a printer polled each
        second answers mostly the same): only the parts whose fields differ are made again (`changed`, when the
        caller has it already, is `changed_fields(since[0], self)`). The result is equal to a view made from
        scratch, key order included; it is a new dict either way."""
        if since is None:
            out: dict[str, Any] = {}
            for _, section in VIEW_SECTIONS:
                out.update(section(self))
            out["raw"] = self._raw()
            return out
        before, view = since
        if changed is None:
            changed = changed_fields(before, self)
        out = dict(view)
        for fields, section in VIEW_SECTIONS:
            if not changed.isdisjoint(fields):
                out.update(section(self))
        out["raw"] = view["raw"] if not changed else self._raw_since(view["raw"], changed)
        return out

    def _raw(self) -> dict[str, str]:
        """The wire value of each letter, in the printer's order."""
        out: dict[str, str] = {}
        for letter in self.order:
            if (line := self.line(letter)) is not None:
                out[letter] = line[2:]
        return out

    def _raw_since(self, before: dict[str, str], changed: frozenset[str]) -> dict[str, str]:
        """`_raw` from an earlier status's (`before`), where the letters and their order are the same and only
        parsed values changed (the fields `changed`): those letters are written again, the rest kept."""
        if not changed.isdisjoint(_LAYOUT_FIELDS):
            return self._raw()
        out = dict(before)
        for field in changed:
            letter = FIELD_LETTERS[field]
            line = self.line(letter)
            if line is None or letter not in out:
                return self._raw()
            out[letter] = line[2:]
        return out


def _identity_view(status: Status) -> dict[str, Any]:
    model = status.model
    return {"model_number": status.model_number, "model": model.name if model else None, "name": status.name,
            "serial": status.serial, "firmware": status.firmware_version, "language": status.language}


def _state_view(status: Status) -> dict[str, Any]:
    return {"state": status.state_code, "substate": status.substate, "state_name": status.state_name,
            "errors": [{"raw": w.raw, "source": w.source, "code": w.code, "name": w.name, "meaning": w.meaning}
                       for w in status.error_words]}


def _heat_view(status: Status) -> dict[str, Any]:
    return {"extruder_c": status.extruder, "extruder_target_c": status.extruder_target,
            "extruder2_c": status.temperatures.extruder2 if status.temperatures else None, "bed_c": status.bed}


def _progress_view(status: Status) -> dict[str, Any]:
    progress = status.progress
    remaining = progress.remaining_min if progress else None
    return {"progress_percent": progress.percent if progress else None,
            "elapsed_s": progress.elapsed_min * 60 if progress else None,
            "time_left_s": remaining * 60 if remaining is not None else None}


def _settings_view(status: Status) -> dict[str, Any]:
    return {"autolevel": status.autolevel, "buzzer": status.buzzer, "block_size_bytes": status.block_size}


def _spools_view(status: Status) -> dict[str, Any]:
    cart = status.cartridge
    return {"filament_left_mm": status.filament_mm, "filament2_left_mm": status.filament2_mm,
            "spools": status.spools, "cartridge_present": cart.present if cart else None,
            "cartridge_colour": cart.colour if cart else None}


VIEW_SECTIONS: tuple[tuple[frozenset[str], Callable[[Status], dict[str, Any]]], ...] = (
    (frozenset({"model_number", "name", "serial", "firmware", "language"}), _identity_view),
    (frozenset({"state", "errors", "model_number"}), _state_view),  # a model's idle noise is no error
    (frozenset({"temperatures", "targets", "bed"}), _heat_view),
    (frozenset({"progress"}), _progress_view),
    (frozenset({"zoffset"}), lambda s: {"zoffset_mm": s.zoffset / 100 if s.zoffset is not None else None}),
    (frozenset({"calibration"}), lambda s: {"calibration": _calibration_ints(s.calibration)}),
    (frozenset({"packet", "settings"}), _settings_view),
    (frozenset({"filament", "cartridge"}), _spools_view),
    (frozenset({"material"}), lambda s: {"material": s.material_name}),
    (frozenset({"nozzle"}), lambda s: {"nozzle_mm": s.nozzle.diameter_mm if s.nozzle else None}),
    (frozenset({"network"}), lambda s: {"network": None if s.network is None else s.network.as_dict()}),
)
"""`Status.to_dict` but `raw`, part by part in its key order, each part with the fields it is made of."""

FIELD_LETTERS = {spec[0]: letter for letter, spec in LETTERS.items()}
_LAYOUT_FIELDS = frozenset({"order", "extra", "unparsed", "dashed"})
"""The fields that say which letters came, in what order and in which form: a change there rewrites `raw` whole."""
_FIELDS: tuple[str, ...] = Status.__struct_fields__
_SHARED_FIELDS = frozenset(LETTERS[letter][0] for letter in SHARED_LETTERS) | {"order", "extra", "unparsed",
                                                                                 "dashed"}


def changed_fields(before: Status, after: Status) -> frozenset[str]:
    """The fields of `after` that differ from `before`'s. A JSON value is the same only when it is written the
    same too: `1`, `1.0` and `true` are equal in Python but not on the wire."""
    return frozenset([name for name, a, b in zip(_FIELDS, msgspec.structs.astuple(before),
                                                 msgspec.structs.astuple(after), strict=True)
                      if a is not b and (a != b or (name not in _SHARED_FIELDS and not _same_json(a, b)))])


def _same_json(a: Any, b: Any) -> bool:
    """Whether two equal JSON values are written alike (numbers of one type, keys in one order)."""
    try:
        return msgspec.json.encode(a) == msgspec.json.encode(b)
    except (TypeError, ValueError, OverflowError):  # what msgspec does not write (a huge integer)
        return False


def _calibration_ints(values: tuple[str, ...] | None) -> list[int | None] | None:
    """Calibration readings as integers (None for a reading that is not a number)."""
    if values is None:
        return None
    out: list[int | None] = []
    for value in values:
        try:
            out.append(round(float(value)))
        except (ValueError, OverflowError):
            out.append(None)
    return out


__all__ = [  # the status types, and the codes a status is read with (their home is codes.py)
    "CANCELLING", "DOOR_OPEN", "FILE_CHECK", "FILE_REJECTED", "HEATER_TIMEOUT", "IDLE", "LETTERS", "NO_CARTRIDGE",
    "PAUSED", "PRINTING", "PRINT_DONE", "Cartridge", "ErrorWord", "Lifetime", "Network", "Nozzle", "Packet",
    "Progress", "Status", "Temperatures",
]
