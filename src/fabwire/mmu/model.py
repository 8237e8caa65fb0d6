"""The MMU3's machine: axes, filament, sensors, registers and the command state machines, in model time.

Time is an input: `advance(now)` runs every command script up to `now` (seconds of MMU time), so tests drive
it with a fake clock and the server drives it with real time × speed. Command scripts are generators that
yield `Wait`s (a progress code to report, a duration, an optional condition); durations come from the firmware's
distances, feedrates and accelerations, read live from the registers.
"""

from __future__ import annotations

import contextlib
import math
from collections import deque
from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from typing import Any

from fabwire.errors import InputError
from fabwire.mmu import codes
from fabwire.mmu.codes import ERROR_OK, RUNNING, FilamentState, FirmwareVersion
from fabwire.mmu.codes import Progress as P  # noqa: N817
from fabwire.mmu.protocol import (
    Accepted,
    ButtonPressed,
    CommandError,
    Finished,
    Processing,
    Rejected,
    Request,
    Response,
)

BOOT_SECONDS = 4.0
"""Power-on to RX enabled: FINDA debounce, the hardware self-test (≈3.6 s) and the bootloader."""
FINDA_DEBOUNCE = 0.1
IDLER_ANGLES = (218.0, 178.0, 138.0, 98.0, 58.0, 18.0)
IDLER_PARTIAL = (208.0, 168.0, 128.0, 88.0, 48.0)
SELECTOR_MM = (1.0, 15.0, 29.0, 43.0, 57.0, 71.0)
FINDA_MM = 27.85
"""Filament tip travel from its parked position at the pulley to where FINDA triggers."""
MAX_FEED_TO_FINDA = 62.85
EJECT_MM = 40.0
FSENSOR_WAIT = 4.0
HOMING_SECONDS = 4.0
UNKNOWN = 0xFF
NEVER = math.inf

ScriptGen = Generator["Wait", bool, None]
StepGen = Generator["Wait", bool, Any]


def move_time(distance: float, speed: float, accel: float) -> float:
    """Trapezoidal move: cruise plus ramps, or a triangle when the move is too short to reach `speed`."""
    distance, speed, accel = abs(distance), max(speed, 1.0), max(accel, 1.0)
    if distance == 0:
        return 0.0
    if distance >= speed * speed / accel:
        return distance / speed + speed / accel
    return 2.0 * math.sqrt(distance / accel)


@dataclass(slots=True)
class Wait:
    progress: int | None
    """Progress code to report while waiting (None keeps the current one)."""
    duration: float
    until: Callable[[], bool] | None = None
    """Ends the wait early when true; the script then receives True (False on timeout)."""


@dataclass(frozen=True, slots=True)
class Fault:
    name: str
    count: int = 1
    """How many times it fires; -1 = every time."""
    skip: int = 0
    """How many chances to fire pass harmlessly first (so a fault can hit, say, the second tool change)."""


FAULT_NAMES = {
    "finda-didnt-trigger": "feeding never reaches FINDA (E8001)",
    "finda-stuck": "FINDA stays on while unloading: filament stuck (E8002)",
    "fsensor-didnt-trigger": "the printer's sensor reports never reach the MMU while feeding (E8003)",
    "fsensor-stuck": "the printer's sensor stays on while unloading (E8004)",
    "fsensor-too-early": "the printer's sensor triggers during the fast bowden feed (E8009)",
    "homing-failed": "the selector stalls while homing or moving (E8087)",
    "idler-homing-failed": "the idler stalls while moving (E8107)",
    "finda-on-boot": "FINDA sees filament at power-on but no slot is known (X0 E8008)",
    "undervoltage": "the MCU supply drops: firmware panic (E800D)",
}
_TMC_KINDS = {"ioin": 0x0200, "reset": 0x0400, "undervoltage": 0x0800, "short": 0x1000, "overheat-warn": 0x2000,
              "overheat": 0x4000}
for _kind in _TMC_KINDS:
    for _axis in ("pulley", "selector", "idler"):
        FAULT_NAMES[f"tmc-{_kind}-{_axis}"] = f"{_axis} TMC driver: {codes.TMC_WORDS[_TMC_KINDS[_kind]]}"


def parse_fault(text: str) -> Fault:
    """`NAME`, `NAME:COUNT` or `NAME:always`, optionally `NAME@SKIP…` to let SKIP chances pass first."""
    name, _, count_text = text.strip().partition(":")
    name, _, skip_text = name.partition("@")
    name = name.strip().lower().replace("_", "-")
    skip = 0
    if skip_text:
        if not skip_text.strip().isdigit():
            raise InputError(f"fault skip after '@' must be a whole number, not {skip_text!r}")
        skip = int(skip_text)
    if name.startswith("tmc-") and name.removeprefix("tmc-") in _TMC_KINDS:
        name += "-pulley"
    if name not in FAULT_NAMES:
        raise InputError(f"unknown MMU fault {name!r}; known: {', '.join(sorted(FAULT_NAMES))}")
    if not count_text:
        return Fault(name, skip=skip)
    if count_text in ("always", "-1"):
        return Fault(name, -1, skip)
    if not count_text.isdigit() or int(count_text) < 1:
        raise InputError(f"fault count must be a positive number or 'always', not {count_text!r}")
    return Fault(name, int(count_text), skip)


@dataclass(slots=True)
class HistoryItem:
    t: float
    command: str
    kind: str
    """'P' progress, 'E' error, 'F' finished."""
    value: int


@dataclass
class Eeprom:
    """What survives a reset (X0); X42 wipes it."""

    slot: int | None = None
    drive_errors: int = 0
    bowden: int = 360
    sg: dict[int, int] = field(default_factory=lambda: {0x17: 8, 0x18: 3, 0x19: 7})


class MMUModel:
    """The machine. Call `advance(now)` before reading state; `handle(request, now)` for each decoded request."""

    def __init__(self, firmware: FirmwareVersion = codes.FIRMWARES["3.0.4"], *, faults: tuple[Fault, ...] = (),
                 now: float = 0.0) -> None:
        self.firmware = firmware
        self.faults: dict[str, int] = {}
        self._fault_skips: dict[str, int] = {}
        for fault in faults:
            self.inject(fault)
        self.eeprom = Eeprom()
        self.history: deque[HistoryItem] = deque(maxlen=4000)
        self.requests_seen = 0
        self.now = now
        self.power_on(now)

    # ------------------------------------------------------------------------------------- control plane

    @property
    def newer(self) -> bool:
        """3.0.4 behaviour (M answered, unload waits for the sensor, accelerations writable)."""
        return self.firmware.triple >= (3, 0, 4)

    def inject(self, fault: Fault | str) -> None:
        fault = parse_fault(fault) if isinstance(fault, str) else fault
        self.faults[fault.name] = fault.count
        self._fault_skips[fault.name] = fault.skip

    def clear_faults(self) -> None:
        self.faults.clear()
        self._fault_skips.clear()

    def press(self, button: int) -> None:
        """A press on the MMU's own buttons."""
        self._queue_event(button, printer=False)

    def set_finda(self, on: bool) -> None:
        """Force the FINDA (e.g. filament pushed in by hand)."""
        self._set_finda(on)

    def _fault(self, name: str) -> bool:
        left = self.faults.get(name, 0)
        if left == 0:
            return False
        if self._fault_skips.get(name, 0) > 0:
            self._fault_skips[name] -= 1
            return False
        if left > 0:
            self.faults[name] = left - 1
        return True

    # ---------------------------------------------------------------------------------------- power

    def power_on(self, now: float, erase: bool = False) -> None:
        """Reboot: X0, X42 (erase) or power-on. The UART stays deaf until `booted_at`."""
        if erase:
            self.eeprom = Eeprom()
        self.now = now
        self.booted_at = now + BOOT_SECONDS
        self.regs: dict[int, int] = {r.address: r.default for r in codes.REGISTERS if r.default is not None}
        self.regs[0x22] = self.eeprom.bowden
        self.regs.update(self.eeprom.sg)
        self.command = ("X", 0)
        self.state = int(P.OK)
        self.error = ERROR_OK
        self.result = 0
        self.printer_in_charge = False
        self.events: deque[tuple[int, bool]] = deque(maxlen=4)
        self.finished_at = now
        self.fsensor = False
        self.stealth = False
        self.selector = 5
        self.idler = 5
        self.homing_until = 0.0
        self.pulley_mm = 0.0
        self.finda_raw = False
        self.finda_since = now
        self.active_slot = self.eeprom.slot if self.eeprom.slot is not None else 0
        self._script: ScriptGen | None = None
        self._wait: Wait | None = None
        self._deadline = NEVER
        if self.eeprom.slot is not None:
            self.filament = FilamentState.IN_NOZZLE
            self.tip = FINDA_MM + self.regs[0x22] + self.regs[0x0B]
            self._set_finda(True, at=now - FINDA_DEBOUNCE)
        else:
            self.filament = FilamentState.AT_PULLEY
            self.tip = 0.0
        if self._fault("finda-on-boot") and self.eeprom.slot is None:
            self._set_finda(True, at=now - FINDA_DEBOUNCE)
            self._start(self._boot_discrepancy())

    @property
    def booting(self) -> bool:
        return self.now < self.booted_at

    # ---------------------------------------------------------------------------------------- engine

    def advance(self, now: float) -> None:
        """Run the current script up to `now` (never backwards)."""
        while self._script is not None and self._wait is not None:
            wait = self._wait
            if wait.until is not None and wait.until():
                self._resume(True)
            elif self._deadline <= now:
                self.now = max(self.now, self._deadline)
                self._resume(False)
            else:
                break
        self.now = max(self.now, now)

    def next_deadline(self) -> float | None:
        """When the model next changes on its own (None: only a request can change it)."""
        if self.booting:
            return self.booted_at
        if self._script is not None and self._deadline != NEVER:
            return self._deadline
        if self.homing_until > self.now:
            return self.homing_until
        return None

    def _start(self, script: ScriptGen) -> None:
        self._script = script
        self.error = RUNNING
        self._resume(None)

    def _resume(self, value: bool | None) -> None:
        assert self._script is not None
        try:
            wait = self._script.send(value)  # type: ignore[arg-type]
        except StopIteration:
            self._script = None
            self._wait = None
            self._deadline = NEVER
            return
        self._wait = wait
        if wait.progress is not None and wait.progress != self.state:
            self.state = wait.progress
            self._record("P", wait.progress)
        self._deadline = self.now + wait.duration

    def _record(self, kind: str, value: int) -> None:
        self.history.append(HistoryItem(self.now, f"{self.command[0]}{self.command[1]:x}", kind, value))

    def _finish(self, result: int = 0) -> None:
        self.state = int(P.OK)
        self.error = ERROR_OK
        self.result = result
        self.printer_in_charge = False
        self.finished_at = self.now
        self._record("F", result)

    # ---------------------------------------------------------------------------------------- sensors

    def _set_finda(self, on: bool, at: float | None = None) -> None:
        if on != self.finda_raw:
            self.finda_raw = on
            self.finda_since = self.now if at is None else at

    @property
    def finda(self) -> bool:
        """Debounced FINDA: on only after staying pressed for 100 ms."""
        return self.finda_raw and self.now - self.finda_since >= FINDA_DEBOUNCE

    def _queue_event(self, button: int, printer: bool) -> None:
        if self._script is not None or self.printer_in_charge:
            self.events.append((button, printer))
            return
        # idle: manual operation, once a second has passed since the last command and nothing is loaded
        if self.state != P.OK or self.now - self.finished_at < 1.0 or self.filament > FilamentState.AT_PULLEY:
            return
        if button == codes.Button.MIDDLE:
            self._start(self._load(self.active_slot))
        elif button in (codes.Button.LEFT, codes.Button.RIGHT) and not self.finda_raw:
            step = -1 if button == codes.Button.LEFT else 1
            target = min(5, max(0, (self.selector if self.selector <= 5 else 5) + step))
            self._start(self._manual_move(target))

    def _manual_move(self, slot: int) -> ScriptGen:
        yield from self._move_selector(slot, P.MOVING_SELECTOR)
        if slot < 5:
            self.active_slot = slot
        self._finish()

    def _take_middle(self) -> bool:
        """Consume events the running state machine may see; True when one was Middle."""
        middle = False
        keep: list[tuple[int, bool]] = []
        for button, printer in self.events:
            if self.printer_in_charge and not printer:
                keep.append((button, printer))
            elif button == codes.Button.MIDDLE:
                middle = True
        self.events = deque(keep, maxlen=4)
        return middle

    def _take_any(self) -> bool:
        taken = any(printer or not self.printer_in_charge for _, printer in self.events)
        if taken:
            self._take_middle()
        return taken

    # ---------------------------------------------------------------------------------------- registers

    def _reg(self, address: int) -> int:
        return self.regs[address]

    def read_register(self, address: int) -> int | None:
        if address >= codes.REGISTER_COUNT:
            return None
        fw = self.firmware
        live = {
            0x00: fw.major, 0x01: fw.minor, 0x02: fw.revision, 0x03: fw.build,
            0x04: self.eeprom.drive_errors, 0x05: self.state, 0x06: self.error, 0x07: int(self.filament),
            0x08: int(self.finda), 0x09: int(self.fsensor), 0x0A: int(self.stealth),
            0x1A: int(self.pulley_mm) & 0xFFFF,
            0x1B: UNKNOWN if self.now < self.homing_until else self.selector,
            0x1C: UNKNOWN if self.now < self.homing_until else self.idler,
        }
        if address in live:
            return live[address] & 0xFFFF
        if address == 0x22:
            value = self.regs[0x22]
            return value if 341 <= value <= 1000 else 360
        return self.regs[address]

    def write_register(self, address: int, value: int) -> bool:
        if address >= codes.REGISTER_COUNT:
            return False
        register = codes.REGISTERS[address]
        if not register.writable(self.firmware.triple):
            return False
        value &= (1 << register.bits) - 1
        if address == 0x07:
            with contextlib.suppress(ValueError):
                self.filament = FilamentState(value)
        elif address == 0x09:
            self.fsensor = value != 0
        elif address == 0x1B:
            if value <= 5 and not (self.finda_raw and self.selector != value) and self._script is None:
                self.selector = value
        elif address == 0x1C:
            self.idler = 5 if value >= 5 else value
        elif address == 0x22:
            self.eeprom.bowden = value
            self.regs[address] = value
        else:
            if address in self.eeprom.sg:
                self.eeprom.sg[address] = value
            self.regs[address] = value
        return True

    # ---------------------------------------------------------------------------------------- requests

    def handle(self, request: Request, now: float) -> Response | None:
        """Process one decoded request as the firmware's `ProcessRequestMsg` does; None = no reply."""
        self.advance(now)
        self.requests_seen += 1
        code, value = request.code, request.value
        reply: Response | None
        if code == "Q":
            reply = self._status()
        elif code == "P":
            reply = Accepted("P", value, int(self.finda))
        elif code in "SR":
            data = self.read_register(value)
            reply = Rejected(code, value) if data is None else Accepted(code, value, data)
        elif code == "W":
            ok = self.write_register(value, request.value2)
            reply = (Accepted if ok else Rejected)("W", value)
        elif code == "B":
            self._queue_event(value, printer=True)
            reply = Accepted("B", value)
        elif code == "f":
            self.fsensor = value != 0
            reply = Accepted("f", value)
        elif code == "X":
            self.power_on(now, erase=value == 42)
            reply = None
        elif code == "M" and not self.newer:
            reply = None
        elif code in "TLUEKHM":
            reply = self._plan(code, value)
        else:
            reply = None
        self.advance(now)
        return reply

    def _status(self) -> Response:
        code, value = self.command
        if self.printer_in_charge:
            for i, (button, printer) in enumerate(self.events):
                if not printer:
                    del self.events[i]
                    return ButtonPressed(code, value, button)
        if self.error == RUNNING:
            return Processing(code, value, self.state)
        if self.error == ERROR_OK:
            return Finished(code, value, self.result)
        return CommandError(code, value, self.error)

    def _plan(self, code: str, value: int) -> Response:
        if self.state != P.OK or self._script is not None:
            return Rejected(code, value)
        self.command = (code, value)
        self.result = 0
        accepted = {"T": self._reset_tool_change, "L": self._reset_load, "U": self._reset_unload,
                    "E": self._reset_eject, "K": self._reset_cut, "H": self._reset_home,
                    "M": self._reset_mode}[code](value)
        return (Accepted if accepted else Rejected)(code, value)

    def _invalid_tool(self) -> bool:
        self.error = 0x8006
        self._record("E", 0x8006)
        return False

    def _reset_tool_change(self, slot: int) -> bool:
        if slot >= 5:
            return self._invalid_tool()
        if slot == self.active_slot and self.filament == FilamentState.IN_NOZZLE:
            self._finish()
            return True
        self.printer_in_charge = True
        self._start(self._tool_change(slot))
        return True

    def _reset_load(self, slot: int) -> bool:
        if slot >= 5:
            return self._invalid_tool()
        if self.filament > FilamentState.IN_SELECTOR or (
                self.filament == FilamentState.IN_SELECTOR and self.active_slot != slot):
            self.error = ERROR_OK
            return False
        self._start(self._load(slot))
        return True

    def _reset_unload(self, _value: int) -> bool:
        if not self.finda_raw and self.filament < FilamentState.IN_SELECTOR:
            self._finish()
            return True
        self._start(self._unload())
        return True

    def _reset_eject(self, slot: int) -> bool:
        if slot >= 5:
            return self._invalid_tool()
        self._start(self._eject(slot))
        return True

    def _reset_cut(self, slot: int) -> bool:
        if slot >= 5:
            return self._invalid_tool()
        self._start(self._cut(slot))
        return True

    def _reset_home(self, _value: int) -> bool:
        fs = self.fsensor
        if self.finda_raw and fs:
            self.filament = FilamentState.IN_NOZZLE
        elif self.finda_raw or fs:
            self.filament = FilamentState.IN_SELECTOR
        else:
            self.filament = FilamentState.AT_PULLEY
        self.state = int(P.HOMING)
        self._record("P", self.state)
        self.homing_until = self.now + HOMING_SECONDS
        if self.filament < FilamentState.IN_SELECTOR:
            self.selector = 5
        self.idler = 5
        self._finish()
        return True

    def _reset_mode(self, value: int) -> bool:
        self.stealth = value != 0
        self._finish()
        return True

    # ---------------------------------------------------------------------------------------- motion steps

    def _slow(self) -> float:
        return float(self._reg(0x14))

    def _pulley_time(self, mm: float, speed: float) -> float:
        return move_time(mm, speed, self._reg(0x0E))

    def _feed(self, progress: int, mm: float, speed: float, until: Callable[[], bool] | None = None,
              extra: float = 0.0) -> StepGen:
        """Move the filament by `mm` (negative = pull); stops early when `until` holds. Returns True if it did."""
        duration = self._pulley_time(mm, speed)
        start = self.now
        hit = yield Wait(progress, duration + extra, until)
        done = mm if not hit or duration == 0 else mm * min(1.0, (self.now - start) / duration)
        self.pulley_mm += done
        self.tip = max(0.0, self.tip + done)
        return hit

    def _tmc_check(self, axis: str) -> StepGen:
        for kind, flag in _TMC_KINDS.items():
            if self._fault(f"tmc-{kind}-{axis}"):
                code = codes.tmc_error(flag, axis)
                self.error = code
                self.state = int(P.ERR_WAITING_FOR_USER)
                self._record("E", code)
                if flag == 0x2000:  # warning: Middle continues
                    yield Wait(None, NEVER, self._take_middle)
                    self.error = RUNNING
                    return None
                yield Wait(None, NEVER)
        if self._fault("undervoltage"):
            self.error = 0x800D
            self.state = int(P.ERR_INTERNAL)
            self._record("E", 0x800D)
            yield Wait(None, NEVER)
        return None

    def _axis_failed(self, code: int) -> StepGen:
        """Homing failure: wait for Middle, rehome the axis, then carry on where the command was."""
        saved = self.state
        self.error = code
        self.state = int(P.ERR_WAITING_FOR_USER)
        self._record("E", code)
        yield Wait(None, NEVER, self._take_middle)
        self.error = RUNNING
        yield Wait(P.HOMING, HOMING_SECONDS)
        self.state = saved
        self._record("P", saved)

    def _move_selector(self, slot: int, progress: int | None = None, speed: float | None = None) -> StepGen:
        yield from self._tmc_check("selector")
        if self._fault("homing-failed"):
            yield Wait(progress, 0.2)
            yield from self._axis_failed(0x8087)
        distance = SELECTOR_MM[slot] - SELECTOR_MM[self.selector if self.selector <= 5 else 5]
        yield Wait(progress, move_time(distance, speed or self._reg(0x12), self._reg(0x0F)))
        self.selector = slot

    def _move_idler(self, slot: int, progress: int | None = None, partial: bool = False) -> StepGen:
        yield from self._tmc_check("idler")
        if self._fault("idler-homing-failed"):
            yield Wait(progress, 0.2)
            yield from self._axis_failed(0x8107)
        here = IDLER_ANGLES[self.idler if self.idler <= 5 else 5]
        there = IDLER_PARTIAL[slot] if partial else IDLER_ANGLES[slot]
        yield Wait(progress, move_time(there - here, self._reg(0x13), self._reg(0x10)))
        self.idler = slot

    def _move_both(self, slot: int, progress: int) -> StepGen:
        """Selector and idler travel at the same time; the step ends when the slower one arrives."""
        for axis, fault, code in (("selector", "homing-failed", 0x8087), ("idler", "idler-homing-failed", 0x8107)):
            yield from self._tmc_check(axis)
            if self._fault(fault):
                yield Wait(progress, 0.2)
                yield from self._axis_failed(code)
        selector = move_time(SELECTOR_MM[slot] - SELECTOR_MM[min(self.selector, 5)], self._reg(0x12), self._reg(0x0F))
        idler = move_time(IDLER_ANGLES[slot] - IDLER_ANGLES[min(self.idler, 5)], self._reg(0x13), self._reg(0x10))
        yield Wait(progress, max(selector, idler))
        self.selector = slot
        self.idler = slot

    def _error(self, code: int) -> StepGen:
        """The common error path: park the idler (Pa), report the error (state 12), wait for Middle."""
        self.error = RUNNING
        yield from self._move_idler(5, P.ERR_DISENGAGING_IDLER)
        self.error = code
        self.state = int(P.ERR_WAITING_FOR_USER)
        self.eeprom.drive_errors = min(0xFFFF, self.eeprom.drive_errors + 1)
        self.events.clear()
        self._record("E", code)
        yield Wait(None, NEVER, self._take_middle)
        self.error = RUNNING

    # ---------------------------------------------------------------------------------------- sub-automata

    def _feed_to_finda(self, slot: int, limited: bool = True) -> StepGen:
        """'ok', 'failed' (E8001), 'refused' (E800A: selector would not move) or 'stopped' (an event)."""
        if self.finda_raw and self.selector != slot:
            return "refused"
        yield from self._move_both(slot, P.FEEDING_TO_FINDA)
        yield from self._tmc_check("pulley")
        self.active_slot = slot
        self.filament = FilamentState.IN_SELECTOR
        if self._fault("finda-didnt-trigger"):
            if limited:
                yield from self._feed(P.FEEDING_TO_FINDA, MAX_FEED_TO_FINDA, self._slow())
                return "failed"
            while True:
                stopped = yield from self._feed(P.FEEDING_TO_FINDA, MAX_FEED_TO_FINDA, self._slow(), self._take_any)
                if stopped:
                    return "stopped"
        to_finda = max(0.0, FINDA_MM - self.tip) + 0.5
        until = None if limited else self._take_any
        stopped = yield from self._feed(P.FEEDING_TO_FINDA, to_finda, self._slow(), until)
        if stopped:
            return "stopped"
        self._set_finda(True)
        yield Wait(None, FINDA_DEBOUNCE)
        return "ok"

    def _retract_from_finda(self) -> StepGen:
        yield from self._move_idler(self.active_slot, P.RETRACTING_FROM_FINDA)
        if self.finda_raw and self._fault("finda-stuck"):
            yield from self._feed(P.RETRACTING_FROM_FINDA, -FINDA_MM, self._reg(0x0D))
            return False
        yield from self._feed(P.RETRACTING_FROM_FINDA, -self.tip, self._reg(0x0D))
        self.tip = 0.0
        self._set_finda(False)
        self.filament = FilamentState.AT_PULLEY
        return True

    def _unload_to_finda(self) -> StepGen:
        """0 when FINDA is clear, else the error code (E8002 FINDA, E8004 sensor)."""
        if not self.finda_raw:
            return 0
        stuck_sensor = self._fault("fsensor-stuck")
        if self.newer:
            start = self.now
            yield from self._move_idler(self.active_slot, P.UNLOADING_TO_FINDA, partial=True)
            if stuck_sensor or self.fsensor:
                clear = yield Wait(P.UNLOADING_TO_FINDA, max(0.0, FSENSOR_WAIT - (self.now - start)),
                                   (lambda: False) if stuck_sensor else (lambda: not self.fsensor))
                if not clear:
                    return 0x8004
            yield from self._move_idler(self.active_slot, P.UNLOADING_TO_FINDA)
            yield from self._feed(P.UNLOADING_TO_FINDA, -20.0, self._slow())
            check = float(self._reg(0x0C))
            yield from self._feed(P.UNLOADING_TO_FINDA, -min(check, max(0.0, self.tip - FINDA_MM)),
                                  self._reg(0x0D))
            if self.fsensor:
                return 0x8004
        else:
            yield from self._move_idler(self.active_slot, P.UNLOADING_TO_FINDA)
        yield from self._tmc_check("pulley")
        if self._fault("finda-stuck"):
            yield from self._feed(P.UNLOADING_TO_FINDA, -(1000 + 42.85 + 20), self._reg(0x0D))
            self.tip = FINDA_MM + 1
            return 0x8002
        yield from self._feed(P.UNLOADING_TO_FINDA, -max(0.0, self.tip - FINDA_MM + 1), self._reg(0x0D))
        self._set_finda(False)
        self.filament = FilamentState.IN_SELECTOR
        return 0

    def _feed_to_bondtech(self) -> StepGen:
        """0 when the filament reached the nozzle, else E8003 / E8009."""
        slot = self.active_slot
        yield from self._move_idler(slot, P.FEEDING_TO_BONDTECH)
        bowden = float(self.read_register(0x22) or 360)
        early = self._fault("fsensor-too-early")
        hit = yield from self._feed(P.FEEDING_TO_BONDTECH, bowden, self._reg(0x11),
                                    (lambda: True) if early else (lambda: self.fsensor))
        if hit:
            return 0x8009
        masked = self._fault("fsensor-didnt-trigger")
        hit = yield from self._feed(P.FEEDING_TO_FSENSOR, max(0.0, 1000 - bowden), self._slow(),
                                    (lambda: False) if masked else (lambda: self.fsensor))
        if not hit:
            return 0x8003
        self.filament = FilamentState.IN_FSENSOR
        yield from self._feed(P.FEEDING_TO_NOZZLE, self._reg(0x0B), self._slow())
        self.filament = FilamentState.IN_NOZZLE
        idler = self._pulley_time(5, self._slow())
        yield from self._move_idler(slot, P.FEEDING_TO_BONDTECH, partial=True)
        yield from self._feed(P.FEEDING_TO_BONDTECH, 5, self._slow(), extra=max(0.0, idler))
        yield from self._move_idler(5, P.DISENGAGING_IDLER)
        return 0

    def _unload_sequence(self) -> StepGen:
        """Unload with its own recovery rules; returns when the filament is at the pulley."""
        while True:
            code = yield from self._unload_to_finda()
            if code == 0:
                ok = yield from self._retract_from_finda()
                if ok:
                    return None
                code = 0x8002
            yield from self._error(code)
            while True:
                if self.finda_raw:
                    break  # restart the unload
                if self.fsensor:
                    yield from self._error(code)  # filament stuck in the extruder: stay in error
                    continue
                result = yield from self._feed_to_finda(self.active_slot)
                if result == "ok":
                    break
                yield from self._error(0x8001 if result == "failed" else 0x800A)

    # ---------------------------------------------------------------------------------------- commands

    def _boot_discrepancy(self) -> ScriptGen:
        self.error = 0x8008
        self.state = int(P.ERR_WAITING_FOR_USER)
        self._record("E", 0x8008)
        yield Wait(None, NEVER, self._take_middle)
        self._set_finda(False)  # the user pulled the filament out
        self._finish()

    def _tool_change(self, slot: int) -> ScriptGen:
        while True:
            if self.filament >= FilamentState.IN_SELECTOR or self.finda_raw:
                yield from self._unload_sequence()
                if not self.newer:
                    yield from self._move_idler(5, P.DISENGAGING_IDLER)
            restart = False
            while True:
                result = yield from self._feed_to_finda(slot)
                if result == "ok":
                    break
                code = 0x8001 if result == "failed" else 0x800A
                yield from self._error(code)
                if code == 0x8001 and self.finda_raw:
                    restart = True
                    break
            if restart:
                continue
            code = yield from self._feed_to_bondtech()
            if code == 0:
                break
            yield from self._error(code)
        self.eeprom.slot = slot
        self._finish()

    def _load(self, slot: int) -> ScriptGen:
        while True:
            result = yield from self._feed_to_finda(slot, limited=False)
            if result == "stopped":
                if self.finda_raw:
                    yield from self._retract_from_finda()
                yield from self._move_idler(5, P.DISENGAGING_IDLER)
                self._finish(int(codes.Result.CANCELLED))
                return
            if result == "ok":
                break
            yield from self._error(0x800A)
        while True:
            ok = yield from self._retract_from_finda()
            if not ok:
                yield from self._error(0x8002)
                continue
            result = yield from self._feed_to_finda(slot)
            if result != "ok":
                yield from self._error(0x8001 if result == "failed" else 0x800A)
                continue
            ok = yield from self._retract_from_finda()
            if ok:
                break
            yield from self._error(0x8002)
        yield from self._move_idler(5, P.DISENGAGING_IDLER)
        self._finish()

    def _unload(self) -> ScriptGen:
        yield from self._unload_sequence()
        yield from self._move_idler(5, P.DISENGAGING_IDLER)
        self.eeprom.slot = None
        self._finish()

    def _eject(self, slot: int) -> ScriptGen:
        if self.finda_raw or self.filament >= FilamentState.IN_SELECTOR:
            yield from self._unload_sequence()
            yield from self._move_idler(5, P.DISENGAGING_IDLER)
            self.eeprom.slot = None
        while True:
            if self.finda_raw:
                yield from self._error(0x800A)
                continue
            yield from self._move_selector(4 if slot <= 2 else 0, P.PARKING_SELECTOR)
            break
        yield from self._move_idler(slot, P.ENGAGING_IDLER)
        self.active_slot = slot
        yield from self._feed(P.EJECTING_FILAMENT, EJECT_MM, self._slow())
        self.filament = FilamentState.NOT_LOADED
        self.tip = 0.0
        yield from self._error(0x800C)
        self._finish()

    def _cut(self, slot: int) -> ScriptGen:
        while True:
            if self.filament >= FilamentState.IN_SELECTOR or self.finda_raw:
                yield from self._unload_sequence()
            yield from self._move_idler(slot, P.SELECTING_FILAMENT_SLOT)
            if self.finda_raw and self.selector != slot:
                yield from self._error(0x800A)
                continue
            yield from self._move_selector(slot, P.SELECTING_FILAMENT_SLOT)
            result = yield from self._feed_to_finda(slot)
            if result != "ok":
                yield from self._error(0x8001 if result == "failed" else 0x800A)
                continue
            ok = yield from self._retract_from_finda()
            if not ok:
                yield from self._error(0x8002)
                continue
            break
        yield from self._move_selector(min(slot + 1, 5), P.PREPARING_BLADE)
        yield from self._feed(P.PUSHING_FILAMENT, FINDA_MM + self._reg(0x23) + 5, self._slow())
        yield from self._move_idler(5, P.DISENGAGING_IDLER)
        yield from self._move_selector(slot, P.PERFORMING_CUT, speed=self._reg(0x15))
        self.tip = 0.0
        self.filament = FilamentState.AT_PULLEY
        yield Wait(P.HOMING, HOMING_SECONDS)
        self.pulley_mm -= 5
        yield from self._move_selector(slot, P.RETURNING_SELECTOR)
        self._finish()
