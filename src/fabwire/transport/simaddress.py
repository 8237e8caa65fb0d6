"""`sim://NAME?OPTION=VALUE&…`: which simulators there are, the options each takes, and the one check of them.

`fabwire.transport.urls.parse_url` runs `check_simulator` on every sim:// address, whichever door it came in by
(`devices add`, `-d`, `serve --device`, devices.toml, the agent API), and each simulator builds itself from
`read_options`, the same table: an address that is accepted is one the simulator starts with. Nothing here imports
a simulator; an option's check imports what it looks values up in (the model table, the firmware list) only when
that option is given.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any
from urllib.parse import parse_qsl, urlsplit

import msgspec

from fabwire.checks import CONTROL, MAX_PATH, refuse
from fabwire.devices import KINDS, DeviceKind
from fabwire.errors import InputError, closest, excerpt


class SimOption(msgspec.Struct, frozen=True):
    """One option of a simulator: how its text is read (an InputError or ValueError saying what is wrong with a
    bad one), what it takes in words, and where that comes from."""

    read: Callable[[str], Any]
    takes: str
    source: str


def _number(low: float, high: float, *, infinite: bool = False) -> Callable[[str], float]:
    def read(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (low <= value <= high or (infinite and value == math.inf)) or math.isnan(value):
            raise InputError(f"expected a number from {low:g} to {high:g}{' or inf' if infinite else ''}, "
                             f"not {excerpt(text, 20)}")
        return value

    return read


def _speed(text: str) -> float:
    from fabwire.simspeed import FASTEST, SLOWEST

    return _number(SLOWEST, FASTEST)(text)


def _lineus_speed(text: str) -> float:
    from fabwire.simspeed import FASTEST

    value = _number(0, FASTEST, infinite=True)(text)
    return value or math.inf  # 0: no delay, as inf


def _choice(*words: str) -> Callable[[str], str]:
    def read(text: str) -> str:
        if text not in words:
            raise InputError(f"expected {' or '.join(words)}, not {excerpt(text, 20)}{closest(text, words)}")
        return text

    return read


_TRUE = ("1", "true", "yes", "on")
_FALSE = ("0", "false", "no", "off")


def _flag(text: str) -> bool:
    if text.lower() not in _TRUE + _FALSE:
        raise InputError(f"expected 1 or 0 (true/false, yes/no, on/off), not {excerpt(text, 20)}")
    return text.lower() in _TRUE


def _path(text: str) -> str:
    if not 0 < len(text) <= MAX_PATH:
        raise InputError(f"expected a file path of 1 to {MAX_PATH} characters, not {len(text)}")
    return text  # a control character is already refused with the address


def _xyz_model(text: str) -> str:
    from fabwire.xyz.models import simulated_model

    return simulated_model(text).model_number


def _xyz_faults(text: str) -> tuple[str, ...]:
    from fabwire.xyz.printer import FAULTS

    faults = tuple(f for f in text.replace(",", " ").replace("+", " ").split() if f)  # '+' arrives as a space
    for fault in faults:
        if fault not in FAULTS:
            raise InputError(f"unknown fault {excerpt(fault, 30)}{closest(fault, FAULTS)}; known: {', '.join(FAULTS)}")
    return faults


def _xyz_serial(text: str) -> str:
    if not (text.isascii() and text.isalnum() and len(text) <= 32):
        raise InputError(f"a serial number is 1-32 letters and digits (such as 3FM1XPUS5SIM000123), "
                         f"not {excerpt(text, 20)}")
    return text


def _lineus_version(text: str) -> str:
    from fabwire.lineus.personality import resolve_version

    return resolve_version(text)


def _lineus_name(text: str) -> str:
    from fabwire.lineus.personality import check_name

    return check_name(text)


def _lineus_serial(text: str) -> str:
    from fabwire.lineus.personality import check_serial

    return check_serial(text)


def _mmu_version(text: str) -> str:
    from fabwire.mmu.sim import firmware

    firmware(text)
    return text


def _mmu_faults(text: str) -> tuple[Any, ...]:
    from fabwire.mmu.faults import parse_fault

    return tuple(parse_fault(f) for f in text.split(",") if f.strip())


def _mmu_arithmetic(text: str) -> str:
    from fabwire.mmu import units

    return _choice(*units.FLOAT_FORMATS)(text)


_SPEED_SOURCE = "fabwire.simspeed: 100× slower to 10 000× faster, beyond which a simulator's timers misfire"

XYZ_OPTIONS: dict[str, SimOption] = {
    "model": SimOption(_xyz_model, "a model number or name that speaks XYZv3 (dv1MW0A000, miniMaker …)",
                       "fabwire.xyz.models.MODELS (miniMover's model table)"),
    "speed": SimOption(_speed, "a number from 0.01 to 10000", _SPEED_SOURCE),
    "link": SimOption(_choice("serial", "wifi"), "serial or wifi",
                      "the da Vinci's two reply framings (USB serial, Wi-Fi TCP)"),
    "fault": SimOption(_xyz_faults, "fault names joined by '+'", "fabwire.xyz.printer.FAULTS"),
    "strict": SimOption(_flag, "1 or 0", "refuse what a real printer would refuse silently"),
    "state": SimOption(_path, "a file path", "where the printer keeps its settings between runs"),
    "store": SimOption(_path, "a folder path", "where uploads are written"),
    "serial": SimOption(_xyz_serial, "1-32 letters and digits",
                        "the `i:` reply's serial number: 18 letters and digits on real printers"),
    "control": SimOption(_flag, "1 or 0", "the simulator's control commands (faults, buttons) on its link"),
}
LINEUS_OPTIONS: dict[str, SimOption] = {
    "speed": SimOption(_lineus_speed, "a number up to 10000, or 0/inf for no delay", _SPEED_SOURCE),
    "version": SimOption(_lineus_version, "a firmware release from 1.0.0 to 3.2.0 (1, 3, 3.x …)",
                         "fabwire.lineus.personality.RELEASED: the releases up to the last, Nov 2019"),
    "name": SimOption(_lineus_name, "1-32 of A-Z a-z 0-9 -", "the firmware's M550 machine name rule"),
    "serial": SimOption(_lineus_serial, "1-32 ASCII characters without spaces or quotes",
                        "the hello's SERIAL:\"…\" field (6 digits on real machines)"),
    "reply": SimOption(_choice("complete", "accept"), "complete or accept",
                       "when the firmware answers a move: once done, or once queued (firmware 3 lookahead)"),
    "step_time": SimOption(_number(0.0001, 1.0), "seconds from 0.0001 to 1",
                           "the firmware's motion tick (10 ms); beyond 1 s a drawing never ends"),
}
MMU_OPTIONS: dict[str, SimOption] = {
    "speed": SimOption(_speed, "a number from 0.01 to 10000", _SPEED_SOURCE),
    "version": SimOption(_mmu_version, "3.0.2, 3.0.3 or 3.0.4", "fabwire.mmu.codes.FIRMWARES (Prusa-Firmware-MMU)"),
    "fault": SimOption(_mmu_faults, "NAME[:N][@SKIP] joined by ','", "fabwire.mmu.faults.parse_fault"),
    "arithmetic": SimOption(_mmu_arithmetic, "pc or avr", "fabwire.mmu.units.FLOAT_FORMATS"),
    "phantom_requests": SimOption(_flag, "1 or 0", "repeat a request after a garbage byte, as the firmware does"),
}

SIMULATORS: dict[str, dict[str, SimOption] | None] = {"xyz": XYZ_OPTIONS, "lineus": LINEUS_OPTIONS,
                                                      "mmu": MMU_OPTIONS}
"""Each simulator's table of options; None for one registered without a table (its options are not checked)."""
PATH_OPTIONS = frozenset(name for options in SIMULATORS.values() if options for name, option in options.items()
                         if option.read is _path)
"""The options that name a file or folder on the machine the simulator runs on."""


def check_simulator(text: str, kind: DeviceKind | None) -> tuple[str, dict[str, str]]:
    """The simulator a sim:// address names and its options, each checked against that simulator's table: an
    InputError worded by `fabwire.checks.RULES` otherwise. `kind` (when given) is the kind it must simulate; with
    no name in the address it is that kind's simulator."""
    parts = urlsplit(text)
    name = parts.netloc or (kind.name if kind else "")
    if not name or name not in SIMULATORS:
        raise refuse("sim-unknown", name=excerpt(name, 20), known=", ".join(sorted(SIMULATORS)))
    if kind is not None and name in KINDS and name != kind.name:
        raise refuse("sim-kind", name=name, simulated=KINDS[name].a_title, wanted=kind.a_title)
    if parts.path not in ("", "/"):
        raise refuse("sim-path", address=excerpt(text, 60))
    if parts.fragment or text.endswith("#"):
        raise refuse("fragment", address=excerpt(text, 60))
    try:
        pairs = parse_qsl(parts.query, keep_blank_values=True, strict_parsing=bool(parts.query))
    except ValueError:
        raise refuse("sim-query", address=excerpt(text, 60), query=excerpt(parts.query, 40)) from None
    options: dict[str, str] = {}
    for key, value in pairs:
        control = CONTROL.search(key + value)  # %0A decodes to a line break
        if control:
            raise refuse("control", address=excerpt(text, 60), char=repr(control.group()))
        if key in options:
            raise refuse("sim-repeated", name=name, option=excerpt(key, 20))
        options[key] = value
    read_options(name, options)
    return name, options


def read_options(name: str, options: dict[str, str]) -> dict[str, Any]:
    """`options` (text, as in the address) read by simulator `name`'s table: each option's value, typed. An
    unknown option or a value the option cannot take is an InputError worded by `fabwire.checks.RULES`."""
    table = SIMULATORS.get(name)
    if table is None:
        return dict(options)
    values: dict[str, Any] = {}
    for key, text in options.items():
        option = table.get(key)
        if option is None:
            raise refuse("sim-option", name=name, option=excerpt(key, 20), hint=closest(key, table),
                         known=", ".join(table))
        try:
            values[key] = option.read(text)
        except (InputError, ValueError) as exc:
            raise refuse("sim-value", name=name, option=excerpt(key, 20), problem=str(exc)) from None
    return values


def register_options(name: str, table: dict[str, SimOption] | None) -> None:
    """Make `sim://name` an address; `table` its options (None: any options, unchecked)."""
    SIMULATORS.setdefault(name, table)
