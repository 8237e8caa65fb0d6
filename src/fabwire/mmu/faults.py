"""What can fail in an MMU3, where the firmware checks it, and how it recovers — the simulator's fault model.

A fault stands for a *cause* (a stalled axis, a dead driver, filament stuck under FINDA). Armed with a count it
makes that many checks fail, then the cause is gone; `always` keeps it until `clear`. The command scripts consult
`FaultSet.hit(name)` exactly where the firmware runs the check, so Retry — which re-runs the check that failed —
brings the same error back while the cause persists. Recovery rules (`MMU:src/logic/command_base.cpp`
`WaitForOneModuleErrorRecovery`, reference §5.4): mechanical and sensor errors recover on Middle (Retry), which
re-runs the check; TMC driver errors, the power-on self-test and the VCC panic recover only through a reset,
after which the check runs again at boot or at the next move of that axis.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

from fabwire.errors import InputError
from fabwire.mmu.errors import TMC_FLAGS, TMC_WORDS, format_error, tmc_error

Recovery = Literal["retry", "reset"]
_COUNT = re.compile(r"[0-9]{1,9}")
"""ASCII digits, few: `int()` also reads other scripts' digits and refuses more than 4,300 of them."""
AXES = ("pulley", "selector", "idler")
_AXIS_BITS = {"pulley": 0x0040, "selector": 0x0080, "idler": 0x0100}


@dataclass(frozen=True, slots=True)
class FaultKind:
    name: str
    word: int
    """The error word the MMU reports when the check fails."""
    recovery: Recovery
    where: str
    """Where the firmware runs the check, in words."""


def _catalogue() -> dict[str, FaultKind]:
    kinds = [
        FaultKind("finda-didnt-trigger", 0x8001, "retry", "a limited feed to FINDA (T, L's verification, K, unload "
                  "recovery); L's first, unlimited feed never gives up"),
        FaultKind("finda-stuck", 0x8002, "retry", "unloading or retracting from FINDA: FINDA stays on"),
        FaultKind("fsensor-didnt-trigger", 0x8003, "retry", "T: the printer's sensor never reports the filament"),
        FaultKind("fsensor-stuck", 0x8004, "retry", "unloading: the printer's sensor stays on"),
        FaultKind("fsensor-too-early", 0x8009, "retry", "T: the printer's sensor triggers during the fast bowden "
                  "feed"),
        FaultKind("homing-failed", 0x8087, "retry", "the selector stalls: at boot homing, homing after Retry, H, "
                  "and every selector move"),
        FaultKind("idler-homing-failed", 0x8107, "retry", "the idler stalls: at boot homing, homing after Retry, "
                  "H, and every idler move"),
        FaultKind("finda-on-boot", 0x8008, "retry", "power-on: FINDA sees filament but no slot is recorded "
                  "(X0 E8008); Retry looks at FINDA again"),
        FaultKind("undervoltage", 0x800D, "reset", "the MCU supply, checked on every main-loop pass: boot, idle "
                  "and during commands (panic, E800d)"),
    ]
    for axis in AXES:
        kinds.append(FaultKind(f"selftest-{axis}", 0xC200 | _AXIS_BITS[axis], "reset",
                               f"power-on hardware self-test of the {axis} driver (X0 Ec2xx)"))
    for flag, flag_name in TMC_FLAGS.items():
        kind = flag_name.removeprefix("TMC_").lower().replace("_", "-")
        short = {"ioin-mismatch": "ioin", "undervoltage-on-charge-pump": "undervoltage", "short-to-ground": "short",
                 "over-temperature-warn": "overheat-warn", "over-temperature-error": "overheat"}.get(kind, kind)
        for axis in AXES:
            kinds.append(FaultKind(f"tmc-{short}-{axis}", tmc_error(flag, axis), "reset",
                                   f"{axis} TMC driver: {TMC_WORDS[flag]}, checked whenever the {axis} moves"))
    return {k.name: k for k in kinds}


FAULTS = _catalogue()
FAULT_NAMES = {name: f"{kind.where}: {format_error(kind.word)}" for name, kind in FAULTS.items()}
TMC_KINDS = sorted({name.split("-", 1)[1].rsplit("-", 1)[0] for name in FAULTS if name.startswith("tmc-")})


@dataclass(frozen=True, slots=True)
class Fault:
    name: str
    count: int = 1
    """How many checks fail; -1 = every check until cleared."""
    skip: int = 0
    """How many checks pass first (so a fault can hit, say, the second tool change)."""


def parse_fault(text: str) -> Fault:
    """`NAME`, `NAME:COUNT` or `NAME:always`, optionally `NAME@SKIP…` to let SKIP checks pass first.

    Raises InputError for an unknown name or a bad count/skip."""
    name, _, count_text = text.strip().partition(":")
    name, _, skip_text = name.partition("@")
    name = name.strip().lower().replace("_", "-")
    skip = 0
    if skip_text:
        if not _COUNT.fullmatch(skip_text.strip()):
            raise InputError(f"fault skip after '@' must be a whole number below a billion, not {skip_text[:20]!r}")
        skip = int(skip_text)
    if name.startswith("tmc-") and name.removeprefix("tmc-") in TMC_KINDS:
        name += "-pulley"
    if name not in FAULTS:
        raise InputError(f"unknown MMU fault {name[:40]!r}; known: {', '.join(sorted(FAULTS))}")
    count_text = count_text.strip()
    if not count_text:
        return Fault(name, skip=skip)
    if count_text in ("always", "-1"):
        return Fault(name, -1, skip)
    if not _COUNT.fullmatch(count_text) or int(count_text) < 1:
        raise InputError(f"fault count must be a positive number below a billion or 'always', "
                         f"not {count_text[:20]!r}")
    return Fault(name, int(count_text), skip)


class FaultSet:
    """The causes present in one machine. Survives resets: a reset clears errors, not their causes."""

    def __init__(self, faults: tuple[Fault, ...] = ()) -> None:
        self._left: dict[str, int] = {}
        self._skip: dict[str, int] = {}
        for fault in faults:
            self.arm(fault)

    def arm(self, fault: Fault | str) -> None:
        fault = parse_fault(fault) if isinstance(fault, str) else fault
        self._left[fault.name] = fault.count
        self._skip[fault.name] = fault.skip

    def clear(self, name: str | None = None) -> None:
        """Remove one cause (or all): the next check of it passes."""
        if name is None:
            self._left.clear()
            self._skip.clear()
        else:
            self._left.pop(name, None)
            self._skip.pop(name, None)

    def armed(self, name: str) -> bool:
        return self._left.get(name, 0) != 0

    def hit(self, name: str) -> bool:
        """Run the check for `name`: True when it fails (consumes one failure, or one skipped pass)."""
        left = self._left.get(name, 0)
        if left == 0:
            return False
        if self._skip.get(name, 0) > 0:
            self._skip[name] -= 1
            return False
        if left > 0:
            self._left[name] = left - 1
        return True

    def axis_driver(self, axis: str) -> int:
        """Check every driver fault of `axis` (as a move does): the OR of the failing flags' words, 0 if none."""
        word = 0
        for name in FAULTS:
            if name.startswith("tmc-") and name.endswith("-" + axis) and self.hit(name):
                word |= FAULTS[name].word
        return word

    def selftest(self) -> int:
        """The power-on self-test over all three drivers: 0 or 0xC200 with the failing axes' bits."""
        word = 0
        for axis in AXES:
            if self.hit(f"selftest-{axis}"):
                word |= FAULTS[f"selftest-{axis}"].word
        return word
