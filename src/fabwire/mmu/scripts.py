"""The MMU3's command state machines as scripts over `Machine`, consulting the fault model where the firmware checks.

Durations come from the firmware's distances, feedrates and accelerations, read live from the registers
(reference §5.5). Each check that can fail asks `self.faults`; on Retry (Middle) the check runs again, so a
cause that persists brings the same error back (`MMU:src/logic/command_base.cpp`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from fabwire.mmu import codes
from fabwire.mmu.codes import FilamentState
from fabwire.mmu.codes import Progress as P  # noqa: N817
from fabwire.mmu.errors import ERROR_OK, RUNNING
from fabwire.mmu.faults import Recovery
from fabwire.mmu.machine import FINDA_DEBOUNCE, HOMING_SECONDS, NEVER, UNKNOWN, Machine, ScriptGen, StepGen, Wait

IDLER_ANGLES = (218.0, 178.0, 138.0, 98.0, 58.0, 18.0)
IDLER_PARTIAL = (208.0, 168.0, 128.0, 88.0, 48.0)
SELECTOR_MM = (1.0, 15.0, 29.0, 43.0, 57.0, 71.0)
FINDA_MM = 27.85
"""Filament tip travel from its parked position at the pulley to where FINDA triggers."""
MAX_FEED_TO_FINDA = 62.85
EJECT_MM = 40.0
FSENSOR_WAIT = 4.0
STALL_SECONDS = 0.2
"""How long a move runs before StallGuard reports the stall."""
HOMING_FAULTS = {"selector": ("homing-failed", 0x8087), "idler": ("idler-homing-failed", 0x8107)}


def move_time(distance: float, speed: float, accel: float) -> float:
    """Trapezoidal move: cruise plus ramps, or a triangle when the move is too short to reach `speed`."""
    distance, speed, accel = abs(distance), max(speed, 1.0), max(accel, 1.0)
    if distance == 0:
        return 0.0
    if distance >= speed * speed / accel:
        return distance / speed + speed / accel
    return 2.0 * math.sqrt(distance / accel)


def recovery_of(word: int) -> Recovery:
    """Driver errors (any TMC flag, the self-test) and panics wait for a reset; everything else reacts to Middle."""
    return "reset" if word & 0x7E00 or word in (0x800D, 0x802B, 0x802F) else "retry"


class Scripts(Machine):
    # ------------------------------------------------------------------------------------- waiting for the user

    def _wait_user(self, word: int) -> StepGen:
        """Error state 12 reporting `word`; returns on Middle, or never for errors only a reset clears."""
        self.error = word
        self.state = int(P.ERR_WAITING_FOR_USER)
        self._record("E", word)
        if recovery_of(word) == "reset":
            yield Wait(None, NEVER)
        yield Wait(None, NEVER, self._take_middle)
        self.error = RUNNING

    def _error(self, word: int) -> StepGen:
        """The common error path: park the idler (Pa), count a drive error, report `word`, wait for Middle."""
        self.error = RUNNING
        yield from self._move_idler(5, P.ERR_DISENGAGING_IDLER)
        self.eeprom.drive_errors = min(0xFFFF, self.eeprom.drive_errors + 1)
        self.events.clear()
        yield from self._wait_user(word)

    def _error_then_rehome(self, word: int) -> StepGen:
        """The error path of T and U: on Middle the firmware also invalidates homing (reference §5.5), so each
        axis that may home in this filament state homes again before it next moves (the idler unless filament
        reaches the sensor, the selector only with no filament in it and FINDA off, §5.5 axes)."""
        yield from self._error(word)
        if self.filament < FilamentState.IN_FSENSOR:
            self.homed["idler"] = False
        if self.filament < FilamentState.IN_SELECTOR and not self.finda_raw:
            self.homed["selector"] = False

    # ------------------------------------------------------------------------------------------------ axes

    def _set_position(self, axis: str, slot: int) -> None:
        if axis == "selector":
            self.selector = slot
        else:
            self.idler = slot

    def _home_once(self, axis: str, progress: int | None) -> StepGen:
        """Home `axis` (or wait for the homing under way); the error word when it fails, else 0."""
        self._set_position(axis, UNKNOWN)
        until = self.homing_until[axis]
        yield Wait(progress, max(0.0, until - self.now) if until else HOMING_SECONDS)
        self.homing_until[axis] = 0.0
        fault, stall = HOMING_FAULTS[axis]
        word = self.faults.axis_driver(axis) or (stall if self.faults.hit(fault) else 0)
        if word:
            return word
        self.homed[axis] = True
        self._set_position(axis, 5)
        return 0

    def _recover_axis(self, axis: str, word: int) -> StepGen:
        """An axis failed: wait for Retry, re-home (the check runs again) until it holds, then carry on."""
        saved = self.state
        while word:
            yield from self._wait_user(word)
            self.homed[axis] = False
            word = yield from self._home_once(axis, P.HOMING)
        self.state = saved
        self._record("P", saved)

    def _home_once_or_recover(self, axis: str, progress: int | None) -> StepGen:
        word = yield from self._home_once(axis, progress)
        if word:
            yield from self._recover_axis(axis, word)

    def _axis_ready(self, axis: str, progress: int | None) -> StepGen:
        """Before `axis` moves: homed, its driver healthy, no stall."""
        if not self.homed[axis]:
            yield from self._home_once_or_recover(axis, progress)
        fault, stall = HOMING_FAULTS[axis]
        word = self.faults.axis_driver(axis) or (stall if self.faults.hit(fault) else 0)
        if word:
            yield Wait(progress, STALL_SECONDS)
            yield from self._recover_axis(axis, word)

    def _pulley_ready(self, progress: int | None) -> StepGen:
        word = self.faults.axis_driver("pulley")
        if word:
            yield from self._wait_user(word)

    def _move_selector(self, slot: int, progress: int | None = None, speed: float | None = None) -> StepGen:
        yield from self._axis_ready("selector", progress)
        distance = SELECTOR_MM[slot] - SELECTOR_MM[min(self.selector, 5)]
        yield Wait(progress, move_time(distance, speed or self._reg(0x12), self._reg(0x0F)))
        self.selector = slot

    def _move_idler(self, slot: int, progress: int | None = None, partial: bool = False) -> StepGen:
        yield from self._axis_ready("idler", progress)
        here = IDLER_ANGLES[min(self.idler, 5)]
        there = IDLER_PARTIAL[slot] if partial else IDLER_ANGLES[slot]
        yield Wait(progress, move_time(there - here, self._reg(0x13), self._reg(0x10)))
        self.idler = slot

    def _move_both(self, slot: int, progress: int) -> StepGen:
        """Selector and idler travel at the same time; the step ends when the slower one arrives."""
        yield from self._axis_ready("selector", progress)
        yield from self._axis_ready("idler", progress)
        selector = move_time(SELECTOR_MM[slot] - SELECTOR_MM[min(self.selector, 5)], self._reg(0x12), self._reg(0x0F))
        idler = move_time(IDLER_ANGLES[slot] - IDLER_ANGLES[min(self.idler, 5)], self._reg(0x13), self._reg(0x10))
        yield Wait(progress, max(selector, idler))
        self.selector = slot
        self.idler = slot

    def _home_both(self, progress: int | None) -> StepGen:
        """Idler first, then the selector (it waits for the idler)."""
        for axis in ("idler", "selector"):
            if not self.homed[axis]:
                word = yield from self._home_once(axis, progress)
                if word:
                    self._preemptible = False
                    yield from self._recover_axis(axis, word)
                    self.error = ERROR_OK if progress is None else RUNNING

    # ------------------------------------------------------------------------------------------- the pulley

    def _slow(self) -> float:
        return float(self._reg(0x14))

    def _pulley_time(self, mm: float, speed: float) -> float:
        return move_time(mm, speed, self._reg(0x0E))

    def _feed(self, progress: int, mm: float, speed: float, until: Callable[[], bool] | None = None,
              extra: float = 0.0) -> StepGen:
        """Move the filament by `mm` (negative = pull); stops early when `until` holds. Returns True if it did."""
        yield from self._pulley_ready(progress)
        duration = self._pulley_time(mm, speed)
        start = self.now
        self.pulley_move = (start, duration, mm)
        hit = yield Wait(progress, duration + extra, until)
        self.pulley_move = None
        done = mm if not hit or duration == 0 else mm * min(1.0, (self.now - start) / duration)
        self.pulley_mm += done
        self.tip = max(0.0, self.tip + done)
        return hit

    # ---------------------------------------------------------------------------------------- sub-automata

    def _feed_to_finda(self, slot: int, limited: bool = True) -> StepGen:
        """'ok', 'failed' (E8001), 'refused' (E800A: selector would not move) or 'stopped' (an event)."""
        if self.finda_raw and self.selector != slot:
            return "refused"
        yield from self._move_both(slot, P.FEEDING_TO_FINDA)
        self.active_slot = slot
        self.filament = FilamentState.IN_SELECTOR
        if self.faults.hit("finda-didnt-trigger"):
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
        if self.finda_raw and self.faults.hit("finda-stuck"):
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
        stuck_sensor = self.faults.hit("fsensor-stuck")
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
        if self.faults.hit("finda-stuck"):
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
        early = self.faults.hit("fsensor-too-early")
        hit = yield from self._feed(P.FEEDING_TO_BONDTECH, bowden, self._reg(0x11),
                                    (lambda: True) if early else (lambda: self.fsensor))
        if hit:
            return 0x8009
        masked = self.faults.hit("fsensor-didnt-trigger")
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
            yield from self._error_then_rehome(code)
            while True:
                if self.finda_raw:
                    break  # restart the unload
                if self.fsensor:
                    yield from self._error_then_rehome(code)  # filament stuck in the extruder: stay in error
                    continue
                result = yield from self._feed_to_finda(self.active_slot)
                if result == "ok":
                    break
                yield from self._error_then_rehome(0x8001 if result == "failed" else 0x800A)

    # ---------------------------------------------------------------------------------------------- boot

    def _startup(self, discrepancy: bool) -> ScriptGen:
        """The firmware's startUp command (reported as X0): FINDA vs EEPROM, then homing in the background."""
        self.error = ERROR_OK
        if discrepancy:
            while True:
                yield from self._wait_user(0x8008)
                if not self.faults.hit("finda-on-boot"):
                    break  # Retry looks again: the user pulled the filament out
            self._set_finda(False)
            self.error = ERROR_OK
        self._preemptible = True  # already OK: a command may take over while the axes home
        yield from self._home_both(None)
        self._finish()

    # ------------------------------------------------------------------------------------------ commands

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
                yield from self._error_then_rehome(code)
                if code == 0x8001 and self.finda_raw:
                    restart = True
                    break
            if restart:
                continue
            code = yield from self._feed_to_bondtech()
            if code == 0:
                break
            yield from self._error_then_rehome(code)
        self.eeprom.slot = slot
        self._finish()

    def _load(self, slot: int) -> ScriptGen:
        """Unlimited feed to FINDA, retract, then a limited feed and retract to verify. On Middle after an error
        the firmware retracts again while FINDA is on and otherwise starts over with the unlimited feed
        (reference §5.5 LoadFilament)."""
        while True:
            result = yield from self._feed_to_finda(slot, limited=False)
            if result == "stopped":
                if self.finda_raw:
                    yield from self._retract_from_finda()
                yield from self._move_idler(5, P.DISENGAGING_IDLER)
                self._finish(int(codes.Result.CANCELLED))
                return
            if result != "ok":
                yield from self._error(0x800A)
                continue
            verified = yield from self._verify_load(slot)
            if verified:
                break
        yield from self._move_idler(5, P.DISENGAGING_IDLER)
        self._finish()

    def _verify_load(self, slot: int) -> StepGen:
        """Retract, feed to FINDA again (limited) and retract; False when an error sends the load back to its
        unlimited feed (FINDA off after Middle)."""
        while True:
            ok = yield from self._retract_from_finda()
            if ok:
                result = yield from self._feed_to_finda(slot)
                if result == "ok":
                    ok = yield from self._retract_from_finda()
                    if ok:
                        return True
                    code = 0x8002
                else:
                    code = 0x8001 if result == "failed" else 0x800A
            else:
                code = 0x8002
            yield from self._error(code)
            if not self.finda_raw:
                return False

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
        self.homed["selector"] = False
        yield from self._home_once_or_recover("selector", P.HOMING)
        self.pulley_mm -= 5
        yield from self._move_selector(slot, P.RETURNING_SELECTOR)
        self._finish()

    def _home(self) -> ScriptGen:
        """H: forget both positions and home again (the selector only when no filament is in it)."""
        self.homed["idler"] = False
        if self.filament < FilamentState.IN_SELECTOR:
            self.homed["selector"] = False
        yield from self._home_both(P.HOMING)
        self._finish()

    def _manual_move(self, slot: int) -> ScriptGen:
        yield from self._move_selector(slot, P.MOVING_SELECTOR)
        if slot < 5:
            self.active_slot = slot
        self._finish()
