"""What an MMU that really finished a command shows in its registers, so `F0` alone is never taken for success.

An MMU that answers `A` and then `F0` without moving (a lying or broken device, a stale reply after a reboot, the
firmware's brief `T<n> F0` before `E800a` — reference §5.5 ToolChange quirk) still shows the old state: filament
not where the command puts it, FINDA (register 0x08), the filament state (0x07), the selector slot (0x1B) or the
motor mode (0x0A) contradicting it. Each command's end state is from reference §5.5.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from fabwire.mmu.codes import FILAMENT_WORDS, FilamentState
from fabwire.mmu.protocol import Request

UNKNOWN_SLOT = 0xFF
"""Selector register value while its position is not known (after a reboot with filament loaded)."""
SETTLE = 1.0
"""MMU seconds the end state has to show after `F0` (the FINDA debounce is 0.1 s)."""
HOME_SETTLE = 10.0
"""`H` may report `F0` while the axes still home in the background (reference §5.5 Home): 3-6 s."""


@dataclass(frozen=True, slots=True)
class Expect:
    """Register `address` must satisfy `holds`; `wanted` says what in words, `shown` names a read value."""

    address: int
    holds: Callable[[int], bool]
    wanted: str
    shown: Callable[[int], str]


def _finda(on: bool) -> Expect:
    return Expect(0x08, lambda v: bool(v) == on, f"FINDA {'on' if on else 'off'}",
                  lambda v: f"FINDA {'on' if v else 'off'}")


def _filament(test: Callable[[int], bool], wanted: str) -> Expect:
    return Expect(0x07, test, f"filament {wanted}", lambda v: f"filament {FILAMENT_WORDS.get(v, str(v))}")


def _selector(slot: int, unknown_ok: bool = False) -> Expect:
    return Expect(0x1B, lambda v: v == slot or (unknown_ok and v == UNKNOWN_SLOT), f"selector at slot {slot}",
                  lambda v: "selector position unknown" if v == UNKNOWN_SLOT else
                  ("selector parked" if v == 5 else f"selector at slot {v}"))


def _homed(address: int, axis: str) -> Expect:
    return Expect(address, lambda v: v != UNKNOWN_SLOT, f"{axis} homed",
                  lambda v: f"{axis} position unknown" if v == UNKNOWN_SLOT else f"{axis} at {v}")


def end_state(request: Request) -> tuple[list[Expect], float]:
    """The registers `request` leaves behind when it finished with result 0, and MMU seconds to wait for them."""
    code, slot = request.code, request.value
    if code == "T":  # filament in the nozzle; a T to the slot already loaded after a reboot keeps it unknown
        return [_finda(True), _filament(lambda v: v == FilamentState.IN_NOZZLE, "in the nozzle"),
                _selector(slot, unknown_ok=True)], SETTLE
    if code == "L":  # fed to FINDA and back: parked at the pulley, selector on the slot
        return [_finda(False), _selector(slot)], SETTLE
    if code == "U":
        return [_finda(False), _filament(lambda v: v <= FilamentState.AT_PULLEY, "at the pulley or out")], SETTLE
    if code == "K":
        return [_finda(False), _selector(slot)], SETTLE
    if code == "E":  # out of the MMU, the selector parked away from the slot (4 for slots 0-2, else 0)
        return [_finda(False), _filament(lambda v: v == FilamentState.NOT_LOADED, "not loaded"),
                _selector(4 if slot <= 2 else 0)], SETTLE
    if code == "H":
        return [_homed(0x1B, "selector"), _homed(0x1C, "idler")], HOME_SETTLE
    if code == "M":
        mode = int(slot != 0)
        return [Expect(0x0A, lambda v: v == mode, f"motor mode {'stealth' if mode else 'normal'}",
                       lambda v: f"motor mode {'stealth' if v else 'normal'}")], SETTLE
    return [], 0.0
