"""What can fail in an MMU3, where the firmware checks it, and how it recovers — the simulator's fault model.

A fault stands for a *cause* (a stalled axis, a dead driver, filament stuck under FINDA). As on the machine, a cause
stays until someone removes it (`MMUSimulator.remove_cause`, `fabwire mmu hands remove`): a bare NAME fails every
check until then. `NAME:N` is the test knob for "fails N checks, then the cause is gone". The command scripts consult
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

from fabwire.errors import InputError, closest, excerpt
from fabwire.mmu.errors import TMC_FLAGS, TMC_WORDS, format_error, tmc_error

Recovery = Literal["retry", "reset"]
_COUNT = re.compile(r"[0-9]{1,9}")
"""ASCII digits, few: `int()` also reads other scripts' digits and refuses more than 4,300 of them."""
AXES = ("pulley", "selector", "idler")
_AXIS_BITS = {"pulley": 0x0040, "selector": 0x0080, "idler": 0x0100}


Buttons = tuple[str, str, str]
"""What the MMU does with Left, Middle and Right while it shows the error (`MMU:src/logic/command_base.cpp`
`WaitForOneModuleErrorRecovery` and each command's `ERRWaitingForUser` case)."""

_RETRY: Buttons = ("ignored (the event is consumed, nothing moves)",
                   "Retry: the command runs the failed step again, so the check runs again",
                   "ignored (the event is consumed, nothing moves)")
_REHOME: Buttons = ("ignored (the event is consumed)",
                    "Retry: the axis homes again (`PlanHome`), so the check runs again; then the command resumes",
                    "ignored (the event is consumed)")
_RESET_ONLY: Buttons = ("ignored (not even consumed): only a reset or power-cycle helps",
                        "ignored (not even consumed): only a reset or power-cycle helps",
                        "ignored (not even consumed): only a reset or power-cycle helps")
_IN_CHARGE = " During T the printer is in charge: a press on the MMU is forwarded as `T<n> B<button>` and the " \
             "printer's own B1 is the Retry (`MMU:src/modules/user_input.cpp` `ConsumeEvent`)."


@dataclass(frozen=True, slots=True)
class FaultKind:
    name: str
    word: int
    """The error word the MMU reports when the check fails."""
    recovery: Recovery
    where: str
    """Where the firmware runs the check, in words."""
    check: str
    """The firmware file and function whose check raises the error (`MMU` = prusa3d/Prusa-Firmware-MMU)."""
    cause: str
    """What is wrong in the machine, and what the owner does to remove it (`fabwire mmu hands remove NAME`)."""
    clears: str
    """Where the firmware runs the check again once the cause is gone (file and function)."""
    buttons: Buttons
    """Left, Middle, Right while the error is shown."""


def _catalogue() -> dict[str, FaultKind]:
    kinds = [
        FaultKind("finda-didnt-trigger", 0x8001, "retry", "a limited feed to FINDA (T, L's verification, K, unload "
                  "recovery); L's first, unlimited feed never gives up",
                  "MMU:src/logic/feed_to_finda.cpp FeedToFinda::Step (Failed), raised by tool_change.cpp / "
                  "load_filament.cpp / cut_filament.cpp / unload_filament.cpp StepInner",
                  "the filament does not reach FINDA (tangled spool, filament not at the pulley): untangle it",
                  "MMU:src/logic/tool_change.cpp ToolChange::StepInner ERRWaitingForUser, Middle: FINDA off → "
                  "back to FeedingToFinda", _RETRY),
        FaultKind("finda-stuck", 0x8002, "retry", "unloading or retracting from FINDA: FINDA stays on",
                  "MMU:src/logic/unload_to_finda.cpp UnloadToFinda::Step (FailedFINDA) and retract_from_finda.cpp "
                  "RetractFromFinda::Step (Failed), raised by unload_filament.cpp UnloadFilament::StepInner",
                  "filament stuck under FINDA (a broken tip in the selector): pull it free",
                  "MMU:src/logic/unload_filament.cpp UnloadFilament::StepInner ERRWaitingForUser, Middle: FINDA on "
                  "→ the unload starts over", _RETRY),
        FaultKind("fsensor-didnt-trigger", 0x8003, "retry", "T: the printer's sensor never reports the filament",
                  "MMU:src/logic/feed_to_bondtech.cpp FeedToBondtech::Step (Failed), raised by tool_change.cpp "
                  "ToolChange::StepInner",
                  "the filament stops in the bowden before the printer's sensor, or no host reports the sensor: "
                  "free the path (and report the sensor)",
                  "MMU:src/logic/tool_change.cpp ToolChange::StepInner ERRWaitingForUser, Middle: the change "
                  "starts over", _RETRY),
        FaultKind("fsensor-stuck", 0x8004, "retry", "unloading: the printer's sensor stays on",
                  "MMU:src/logic/unload_to_finda.cpp UnloadToFinda::Step (FailedFSensor), raised by "
                  "unload_filament.cpp UnloadFilament::StepInner",
                  "filament stuck in the extruder above the printer's sensor: pull it out",
                  "MMU:src/logic/unload_filament.cpp UnloadFilament::StepInner ERRWaitingForUser, Middle: the "
                  "unload starts over", _RETRY),
        FaultKind("fsensor-too-early", 0x8009, "retry", "T: the printer's sensor triggers during the fast bowden "
                  "feed", "MMU:src/logic/feed_to_bondtech.cpp FeedToBondtech::Step (fsensor during the fast "
                  "move), raised by tool_change.cpp ToolChange::StepInner",
                  "the printer's sensor reads filament that is not there yet (stuck sensor, leftover piece): clear it",
                  "MMU:src/logic/tool_change.cpp ToolChange::StepInner ERRWaitingForUser, Middle: "
                  "FSENSOR_TOO_EARLY → the whole change again, unload first", _RETRY),
        FaultKind("homing-failed", 0x8087, "retry", "the selector stalls: at boot homing, homing after Retry, H, "
                  "and every selector move",
                  "MMU:src/modules/selector.cpp Selector::FinishHomingAndPlanMoveToParkPos (axis too short), "
                  "raised by src/logic/command_base.cpp CheckMovable",
                  "something blocks the selector (filament tip, debris): free it",
                  "MMU:src/logic/command_base.cpp WaitForOneModuleErrorRecovery, Middle: PlanHome", _REHOME),
        FaultKind("idler-homing-failed", 0x8107, "retry", "the idler stalls: at boot homing, homing after Retry, "
                  "H, and every idler move",
                  "MMU:src/modules/idler.cpp Idler::FinishHomingAndPlanMoveToParkPos (axis too short), raised by "
                  "src/logic/command_base.cpp CheckMovable",
                  "something blocks the idler: free it",
                  "MMU:src/logic/command_base.cpp WaitForOneModuleErrorRecovery, Middle: PlanHome", _REHOME),
        FaultKind("finda-on-boot", 0x8008, "retry", "power-on: FINDA sees filament but no slot is recorded "
                  "(X0 E8008); Retry looks at FINDA again",
                  "MMU:src/logic/start_up.cpp StartUp::CheckFINDAvsEEPROM (from StartUp::Reset)",
                  "filament left under FINDA while the EEPROM says nothing is loaded: pull it out",
                  "MMU:src/logic/start_up.cpp StartUp::StepInner ERRWaitingForUser, Middle: CheckFINDAvsEEPROM",
                  _RETRY),
        FaultKind("undervoltage", 0x800D, "reset", "the MCU supply, checked on every main-loop pass: boot, idle "
                  "and during commands (panic, E800d)",
                  "MMU:src/main.cpp RuntimeHWChecks → Panic(MCU_UNDERVOLTAGE_VCC)",
                  "the supply voltage is too low (power supply, wiring): fix the supply",
                  "MMU:src/main.cpp RuntimeHWChecks, on every loop pass after a reset or power-cycle", _RESET_ONLY),
    ]
    for axis in AXES:
        kinds.append(FaultKind(f"selftest-{axis}", 0xC200 | _AXIS_BITS[axis], "reset",
                               f"power-on hardware self-test of the {axis} driver (X0 Ec2xx)",
                               "MMU:src/logic/hw_sanity.cpp HWSanity::StepInner (MMU_SOLDERING_NEEDS_ATTENTION)",
                               f"the {axis} driver's pins do not read back (soldering, a loose motor cable): repair",
                               "MMU:src/logic/hw_sanity.cpp HWSanity, at the next power-on or reset", _RESET_ONLY))
    for flag, flag_name in TMC_FLAGS.items():
        kind = flag_name.removeprefix("TMC_").lower().replace("_", "-")
        short = {"ioin-mismatch": "ioin", "undervoltage-on-charge-pump": "undervoltage", "short-to-ground": "short",
                 "over-temperature-warn": "overheat-warn", "over-temperature-error": "overheat"}.get(kind, kind)
        for axis in AXES:
            kinds.append(FaultKind(
                f"tmc-{short}-{axis}", tmc_error(flag, axis), "reset",
                f"{axis} TMC driver: {TMC_WORDS[flag]}, checked whenever the {axis} moves",
                "MMU:src/hal/tmc2130.cpp TMC2130::CheckForErrors, raised by src/logic/command_base.cpp "
                "CheckMovable (TMC2130ToErrorCode)",
                f"the {axis} driver reports {TMC_WORDS[flag]}: let it cool, fix the wiring or the supply",
                "MMU:src/logic/command_base.cpp WaitForOneModuleErrorRecovery (\"TMC errors cannot be recovered "
                "safely, waiting for power cycling the MMU\"): the check runs at the axis' next move after a reset",
                _RESET_ONLY))
    return {k.name: k for k in kinds}


FAULTS = _catalogue()
LINE_FAULTS = {
    "phantom-reply": "after a reply, a line of one garbage byte (`a\\n`): the firmware's response decoder would "
                     "report the reply complete a second time (Prusa-Firmware-MMU protocol.cpp DecodeResponse, the "
                     "first-field error path); a host must never act on that phantom",
}
"""Faults of the line rather than the machine: no error word, no check in the firmware; the count works the same
(a bare name until removed, NAME:N for N replies)."""
FAULT_NAMES = {name: f"{kind.where}: {format_error(kind.word)}" for name, kind in FAULTS.items()} | LINE_FAULTS
TMC_KINDS = sorted({name.split("-", 1)[1].rsplit("-", 1)[0] for name in FAULTS if name.startswith("tmc-")})


HANDS = {
    "remove": "remove a cause (NAME, or every cause): pull the filament out, free the jam, fix the supply",
    "press": "press one of the MMU's own buttons: left, middle or right",
    "power-cycle": "switch the MMU off and on (RAM lost; EEPROM and causes stay)",
    "inject": "a cause appears: NAME (until removed) or NAME:N (fails N checks)",
    "causes": "list the causes present",
}
"""The control plane: what the owner's hands can do to a running simulator (`MMUSimulator.hands`)."""
PHYSICAL_BUTTONS = {"right": 0, "middle": 1, "left": 2}


@dataclass(frozen=True, slots=True)
class Fault:
    name: str
    count: int = -1
    """How many checks fail; -1 (a bare NAME) = every check until the cause is removed."""
    skip: int = 0
    """How many checks pass first (so a fault can hit, say, the second tool change)."""


def parse_fault(text: str) -> Fault:
    """`NAME` (the cause stays until removed; `NAME:always` says the same), `NAME:COUNT` (fails COUNT checks, then
    the cause is gone), optionally `NAME@SKIP…` to let SKIP checks pass first.

    Raises InputError for an unknown name or a bad count/skip."""
    name, _, count_text = text.strip().partition(":")
    name, _, skip_text = name.partition("@")
    name = name.strip().lower().replace("_", "-")
    skip = 0
    if skip_text:
        if not _COUNT.fullmatch(skip_text.strip()):
            raise InputError("fault skip after '@' must be a whole number below a billion, "
                             f"not {excerpt(skip_text, 20)}")
        skip = int(skip_text)
    if name.startswith("tmc-") and name.removeprefix("tmc-") in TMC_KINDS:
        name += "-pulley"
    if name not in FAULTS and name not in LINE_FAULTS:
        raise InputError(f"unknown MMU fault {excerpt(name, 40)}{closest(name[:100], FAULT_NAMES)}; "
                         "`fabwire sim mmu --help` lists them")
    count_text = count_text.strip()
    if not count_text:
        return Fault(name, skip=skip)
    if count_text in ("always", "-1"):
        return Fault(name, -1, skip)
    if not _COUNT.fullmatch(count_text) or int(count_text) < 1:
        raise InputError(f"fault count must be a positive number below a billion or 'always', "
                         f"not {excerpt(count_text, 20)}")
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

    def clear(self, name: str | None = None) -> list[str]:
        """Remove one cause (or all): the next check of it passes. Returns the names that were present."""
        present = [n for n, left in self._left.items() if left != 0 and (name is None or n == name)]
        if name is None:
            self._left.clear()
            self._skip.clear()
        else:
            self._left.pop(name, None)
            self._skip.pop(name, None)
        return present

    def present(self) -> dict[str, int]:
        """The causes still there: name → checks it will still fail (-1: until removed)."""
        return {n: left for n, left in self._left.items() if left != 0}

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
