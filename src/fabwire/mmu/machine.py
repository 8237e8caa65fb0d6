"""The MMU3's state in model time: axes, filament, sensors, button events, registers, and the script engine.

Time is an input: `advance(now)` runs the current command script up to `now` (seconds of MMU time). Scripts are
generators that yield `Wait`s (a progress code to report, a duration, an optional condition). The command
scripts themselves live in `fabwire.mmu.scripts`; request dispatch in `fabwire.mmu.model`.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from typing import Any

from fabwire.mmu import codes, units
from fabwire.mmu.codes import FilamentState, FirmwareVersion
from fabwire.mmu.codes import Progress as P  # noqa: N817
from fabwire.mmu.errors import ERROR_OK, RUNNING
from fabwire.mmu.faults import FaultSet

BOOT_SECONDS = 4.0
"""Power-on to RX enabled: FINDA debounce, the hardware self-test (≈3.6 s) and the bootloader."""
FINDA_DEBOUNCE = 0.1
HOMING_SECONDS = 4.0
"""Idler then selector homing (reference §5.5: 3-6 s)."""
UNKNOWN = 0xFF
"""Slot register value while an axis has no valid position (`MMU:src/modules/movable_base.h`)."""
NEVER = math.inf

ScriptGen = Generator["Wait", bool, None]
StepGen = Generator["Wait", bool, Any]


@dataclass(slots=True)
class Wait:
    progress: int | None
    """Progress code to report while waiting (None keeps the current one)."""
    duration: float
    until: Callable[[], bool] | None = None
    """Ends the wait early when true; the script then receives True (False on timeout)."""


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
    cells: dict[int, int] = field(default_factory=lambda: {0x17: 0xFF, 0x18: 0xFF, 0x19: 0xFF, 0x22: 0xFFFF})
    """Register-backed cells as the firmware keeps them: erased (0xff / 0xffff) until written; a read of an erased
    cell answers the default (`fabwire.mmu.units.report`)."""


class Machine:
    """State and engine shared by the scripts and the request dispatcher."""

    def __init__(self, firmware: FirmwareVersion, faults: FaultSet, now: float,
                 float_format: units.FloatFormat = units.FLOAT_FORMATS[units.DEFAULT_FLOAT]) -> None:
        self.firmware = firmware
        self.float_format = float_format
        self.faults = faults
        self.eeprom = Eeprom()
        self.history: deque[HistoryItem] = deque(maxlen=4000)
        self.reset_state(now)

    def reset_state(self, now: float) -> None:
        """Everything a reboot forgets (not the EEPROM, the history or the causes of faults)."""
        self.now = now
        self.booted_at = now + BOOT_SECONDS
        self.regs: dict[int, int] = {}
        self.command = ("X", 0)
        self.state = int(P.OK)
        self.error = ERROR_OK
        self.result = 0
        self.printer_in_charge = False
        self.events: deque[tuple[int, bool]] = deque(maxlen=4)
        self.finished_at = now
        self.fsensor = False
        self.stealth = False
        self.selector = UNKNOWN
        self.idler = UNKNOWN
        self.homed = {"selector": False, "idler": False}
        self.homing_until = {"selector": 0.0, "idler": 0.0}
        """When a homing already under way (boot) ends; a move that needs the axis waits for it."""
        self.pulley_mm = 0.0
        self.pulley_move: tuple[float, float, float] | None = None
        """(start, seconds, mm) of the pulley move under way: the position register follows it."""
        self.tip = 0.0
        self.finda_raw = False
        self.finda_since = now
        self.filament: int = FilamentState.AT_PULLEY
        """The firmware's load state: one of FilamentState, or any byte written to register 0x07."""
        self.active_slot = 0
        self.panicked = False
        self._script: ScriptGen | None = None
        self._wait: Wait | None = None
        self._deadline = NEVER
        self._preemptible = False
        """The running script is the boot homing, which a new command takes over (the firmware's startUp
        command is already OK while the axes home)."""

    @property
    def newer(self) -> bool:
        """3.0.4 behaviour (M answered, unload waits for the sensor, accelerations writable)."""
        return self.firmware.triple >= (3, 0, 4)

    @property
    def booting(self) -> bool:
        return self.now < self.booted_at

    # ---------------------------------------------------------------------------------------- engine

    def advance(self, now: float) -> None:
        """Run the current script up to `now` (never backwards); the supply is checked on every pass."""
        while True:
            if not self.booting and not self.panicked and self.faults.armed("undervoltage"):
                self._check_supply()
            if self._script is None or self._wait is None:
                break
            wait = self._wait
            if wait.until is not None and wait.until():
                self._resume(True)
            elif self._deadline <= now:
                self.now = max(self.now, self._deadline)
                self._resume(False)
            else:
                break
        self.now = max(self.now, now)

    def _check_supply(self) -> None:
        if self.faults.hit("undervoltage"):
            self.panic(0x800D)

    def panic(self, word: int) -> None:
        """The firmware's Panic: every motor stops, state 13 for good, new commands rejected until a reset."""
        self._script = None
        self._wait = None
        self._deadline = NEVER
        self.panicked = True
        self.printer_in_charge = False
        self.state = int(P.ERR_INTERNAL)
        self.error = word
        self._record("E", word)

    def next_deadline(self) -> float | None:
        """When the model next changes on its own (None: only a request can change it)."""
        if self.booting:
            return self.booted_at
        if self._script is not None and self._deadline != NEVER:
            return self._deadline
        return None

    def _start(self, script: ScriptGen) -> None:
        self._script = script
        self._preemptible = False
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
        """A setting as a read of its register answers it (the units the scripts compute with)."""
        register = codes.REGISTERS[address]
        if register.store == "accel" and not register.writable(self.firmware.triple):
            return register.default or 0  # up to 3.0.3 the read returns the config constant
        return units.report(register, self.regs[address], self.float_format)

    def power_on_registers(self) -> None:
        """The settings a reboot restores: the config defaults as the firmware keeps them, the EEPROM cells as
        stored."""
        self.regs = {r.address: units.store(r, r.default, self.float_format) for r in codes.REGISTERS
                     if r.default is not None and r.store != "none"}
        self.regs.update(self.eeprom.cells)

    def _pulley_now(self) -> float:
        if self.pulley_move is None:
            return self.pulley_mm
        start, seconds, mm = self.pulley_move
        return self.pulley_mm + mm * (min(1.0, (self.now - start) / seconds) if seconds > 0 else 1.0)

    def read_register(self, address: int) -> int | None:
        """`MMU:src/registers.cpp` `ReadRegister`; None (→ `R`) for an address past the map."""
        if address >= codes.REGISTER_COUNT:
            return None
        fw = self.firmware
        live = {
            0x00: fw.major, 0x01: fw.minor, 0x02: fw.revision, 0x03: fw.build,
            0x04: self.eeprom.drive_errors, 0x05: self.state, 0x06: self.error, 0x07: self.filament,
            0x08: int(self.finda), 0x09: int(self.fsensor), 0x0A: int(self.stealth),
            0x1A: int(self._pulley_now()) & 0xFFFF,  # int32 millimetres truncated to 16 bits: negatives wrap
            0x1B: self.selector,
            0x1C: self.idler,
            0x21: 225,
        }
        if address in live:
            return live[address] & 0xFFFF
        return self._reg(address)

    def write_register(self, address: int, value: int) -> bool:
        """`MMU:src/registers.cpp` `WriteRegister`: False (→ `R`) for read-only or unknown registers; values are
        not range-checked, only cut to the variable behind the register or converted to its units
        (`fabwire.mmu.units`)."""
        if address >= codes.REGISTER_COUNT:
            return False
        register = codes.REGISTERS[address]
        if not register.writable(self.firmware.triple):
            return False
        kept = units.store(register, value, self.float_format)
        if address == 0x07:  # globals.cpp SetFilamentLoaded(ActiveSlot(), v): any byte; EEPROM from InSelector on
            self.filament = kept
            if kept in (FilamentState.NOT_LOADED, FilamentState.AT_PULLEY):
                self.eeprom.slot = None
            elif kept in (FilamentState.IN_SELECTOR, FilamentState.IN_FSENSOR, FilamentState.IN_NOZZLE):
                self.eeprom.slot = self.active_slot
        elif address == 0x09:
            self.fsensor = bool(kept)
        elif address == 0x1B:
            # selector.cpp MoveToSlot: refused while moving or while FINDA is pressed away from the slot; a slot
            # past park (6+) would index past the firmware's position table, so the simulator leaves it alone
            if kept <= 5 and not (self.finda_raw and self.selector != kept) and self._script is None:
                self.selector = kept
        elif address == 0x1C:
            self.idler = kept
        else:
            self.regs[address] = kept
            if address in self.eeprom.cells:
                self.eeprom.cells[address] = kept
        return True
