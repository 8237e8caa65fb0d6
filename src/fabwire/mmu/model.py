"""The MMU3 as a whole machine: power, faults, buttons and the firmware's request dispatch (`ProcessRequestMsg`).

Call `advance(now)` before reading state and `handle(request, now)` for each decoded request; time is model
seconds, so tests drive it with a fake clock and the server with real time × speed. State and the script engine
are in `fabwire.mmu.machine`, the command scripts in `fabwire.mmu.scripts`, what can fail in
`fabwire.mmu.faults`.
"""

from __future__ import annotations

from fabwire.mmu import codes, units
from fabwire.mmu.codes import FilamentState, FirmwareVersion
from fabwire.mmu.codes import Progress as P  # noqa: N817
from fabwire.mmu.errors import ERROR_OK, RUNNING
from fabwire.mmu.faults import Fault, FaultSet, parse_fault
from fabwire.mmu.machine import FINDA_DEBOUNCE, HOMING_SECONDS, Eeprom
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
from fabwire.mmu.scripts import FINDA_MM, Scripts


class MMUModel(Scripts):
    """The machine. `faults` are the causes present from power-on; more can be armed with `inject`."""

    def __init__(self, firmware: FirmwareVersion = codes.FIRMWARES["3.0.4"], *, faults: tuple[Fault, ...] = (),
                 now: float = 0.0, float_format: units.FloatFormat = units.FLOAT_FORMATS[units.DEFAULT_FLOAT]) -> None:
        super().__init__(firmware, FaultSet(faults), now, float_format)
        self.requests_seen = 0
        self.power_on(now)

    # ------------------------------------------------------------------------------------- control plane

    def inject(self, fault: Fault | str) -> None:
        """A new cause appears (a jam, a stalled axis…): the next checks of it fail until it is removed."""
        self.faults.arm(fault)

    def remove_cause(self, name: str | None = None) -> list[str]:
        """The owner's hands remove a cause (all when None): pull out the filament, free the jam. The error it
        raised stays on the screen until Retry or a reset runs the check again, as on the machine. Returns the
        causes that were present."""
        if name is not None:
            name = parse_fault(name).name
        removed = self.faults.clear(name)
        if "finda-on-boot" in removed and self.filament < FilamentState.IN_SELECTOR:
            self._set_finda(False)  # the filament that sat under FINDA is out now
        return removed

    def clear_faults(self, name: str | None = None) -> None:
        """`remove_cause`, without the list."""
        self.remove_cause(name)

    def causes(self) -> dict[str, int]:
        """The causes present: name → checks they will still fail (-1: until removed)."""
        return self.faults.present()

    def press(self, button: int) -> None:
        """A press on the MMU's own buttons (0 Right, 1 Middle, 2 Left)."""
        self._queue_event(button, printer=False)

    def power_cycle(self, now: float) -> None:
        """Switch the MMU off and on: like a reset, RAM is lost, the EEPROM and every cause stay."""
        self.advance(now)
        self.power_on(now)

    def set_finda(self, on: bool) -> None:
        """Force the FINDA (e.g. filament pushed in by hand)."""
        self._set_finda(on)

    # ---------------------------------------------------------------------------------------------- power

    def power_on(self, now: float, erase: bool = False) -> None:
        """Reboot: X0, X42 (erase) or power-on. The UART stays deaf until `booted_at`.

        At power-on the firmware runs the driver self-test (X0 Ec2xx), checks FINDA against the EEPROM
        (X0 E8008) and homes both axes unless filament is recorded as loaded; the supply is checked on every
        main-loop pass (`advance`)."""
        if erase:
            self.eeprom = Eeprom()
        self.reset_state(now)
        self.power_on_registers()
        self.active_slot = self.eeprom.slot if self.eeprom.slot is not None else 0
        selftest = self.faults.selftest()
        if selftest:
            self.state = int(P.ERR_HW_TEST_FAILED)
            self.error = selftest
            self._record("E", selftest)
            return
        if self.eeprom.slot is not None:
            # filament recorded: neither axis homes, positions stay unknown until a move completes
            self.filament = FilamentState.IN_NOZZLE
            self.tip = FINDA_MM + self._reg(0x22) + self._reg(0x0B)
            self._set_finda(True, at=now - FINDA_DEBOUNCE)
            self.homed = {"selector": True, "idler": True}
            return
        discrepancy = self.faults.hit("finda-on-boot")
        if discrepancy:
            self._set_finda(True, at=now - FINDA_DEBOUNCE)
        self.homing_until = dict.fromkeys(self.homing_until, self.booted_at + HOMING_SECONDS)
        self._start(self._startup(discrepancy))

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
        if self.state != P.OK or (self._script is not None and not self._preemptible):
            return Rejected(code, value)
        self._script = None  # the boot homing, if any: the new command waits for the axes itself
        self._preemptible = False
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
        """Re-derive the filament state from FINDA and the printer's sensor, then home (reference §5.5 H)."""
        fs = self.fsensor
        if self.finda_raw and fs:
            self.filament = FilamentState.IN_NOZZLE
        elif self.finda_raw or fs:
            self.filament = FilamentState.IN_SELECTOR
        else:
            self.filament = FilamentState.AT_PULLEY
        self._start(self._home())
        return True

    def _reset_mode(self, value: int) -> bool:
        self.stealth = value != 0
        self._finish()
        return True

    # ---------------------------------------------------------------------------------------------- buttons

    def _queue_event(self, button: int, printer: bool) -> None:
        if (self._script is not None and not self._preemptible) or self.printer_in_charge:
            self.events.append((button, printer))
            return
        # idle: manual operation, once a second has passed since the last command and nothing is loaded
        if self.state != P.OK or self.now - self.finished_at < 1.0 or self.filament > FilamentState.AT_PULLEY:
            return
        if button == codes.Button.MIDDLE:
            self._start(self._load(self.active_slot))
        elif button in (codes.Button.LEFT, codes.Button.RIGHT) and not self.finda_raw:
            step = -1 if button == codes.Button.LEFT else 1
            here = self.selector if self.selector <= 5 else 5
            self._start(self._manual_move(min(5, max(0, here + step))))
