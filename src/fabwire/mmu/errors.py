"""MMU error words as a Prusa printer shows them: printer code, title, the dialog's choices, and one text form.

Sources: the word layout is `MMU:src/logic/error_codes.h` (0x8000 marks an error, 0x0040/0x0080/0x0100 name the
pulley/selector/idler driver, TMC flags are OR-ed together). The printer code and title come from the printer's
converter `MK3:Firmware/mmu2_error_converter.cpp` `PrusaErrorCodeIndex` and `MK3:Firmware/mmu2/errors_list.h`:
exact words first; then the power-on self-test (all of 0xC200) for the first axis found; then, for the first axis
found (pulley, selector, idler), the first TMC flag found (IOIN, reset, charge-pump undervoltage, short, over-
temperature warning, over-temperature); anything else is a firmware runtime error (04505). The dialog's choices
and the button each one sends are `ButtonAvailable` in the same converter.

    format_error(0x8001) == "04101 FINDA DIDN'T TRIGGER (0x8001)"
"""

from __future__ import annotations

from dataclasses import dataclass

from fabwire import units
from fabwire.errors import DeviceError

RUNNING = 0x0000
ERROR_OK = 0x0001

AXIS_BITS = {0x0040: "pulley", 0x0080: "selector", 0x0100: "idler"}
"""In the converter's search order."""
AXIS_MASK = 0x01C0
TMC_FLAGS = {
    0x8200: "TMC_IOIN_MISMATCH",
    0x8400: "TMC_RESET",
    0x8800: "TMC_UNDERVOLTAGE_ON_CHARGE_PUMP",
    0x9000: "TMC_SHORT_TO_GROUND",
    0xA000: "TMC_OVER_TEMPERATURE_WARN",
    0xC000: "TMC_OVER_TEMPERATURE_ERROR",
}
"""Each flag with the error bit, in the converter's search order; a word 'contains' a flag when it has all its bits."""
TMC_WORDS = {
    0x8200: "driver IOIN mismatch",
    0x8400: "driver reset",
    0x8800: "undervoltage on charge pump",
    0x9000: "short to ground",
    0xA000: "over-temperature warning",
    0xC000: "over-temperature",
}
SOLDERING_NEEDS_ATTENTION = 0xC200
"""The power-on self-test failure; overlaps the IOIN and over-temperature flags, so the converter checks it first."""

RESET = "reset"
"""A choice the printer carries out itself by resetting the MMU (reset pin or X0)."""


@dataclass(frozen=True, slots=True)
class Choice:
    label: str
    """As on the printer's dialog: Retry, Continue, Reset MMU, Unload, Stop print, Disable MMU, Load, Eject."""
    button: int | str | None
    """The `B` value sent for it (0 Right, 1 Middle, 2 Left), RESET, or None when the printer acts alone."""


_RETRY = (Choice("Retry", 1),)
_CONTINUE = (Choice("Continue", 1),)
_RESET_ONLY = (Choice("Reset MMU", RESET),)
_LINK = (Choice("Reset MMU", RESET), Choice("Disable MMU", None))

PRINTER_ERRORS: dict[str, tuple[str, tuple[Choice, ...]]] = {
    # printer code: (title, dialog choices) — errors_list.h titles, words written out in full where the
    # printer's 20-column screen drops the apostrophe
    "04101": ("FINDA DIDN'T TRIGGER", _RETRY),
    "04102": ("FINDA FILAM. STUCK", _RETRY),
    "04103": ("FSENSOR DIDN'T TRIGG.", _RETRY),
    "04104": ("FSENSOR FIL. STUCK", _RETRY),
    "04105": ("PULLEY CANNOT MOVE", _RETRY),
    "04106": ("FSENSOR TOO EARLY", _RETRY),
    "04107": ("INSPECT FINDA", _RETRY),
    "04108": ("LOAD TO EXTR. FAILED", _CONTINUE),
    "04115": ("SELECTOR CANNOT HOME", _RETRY),
    "04116": ("SELECTOR CANNOT MOVE", _RETRY),
    "04125": ("IDLER CANNOT HOME", _RETRY),
    "04126": ("IDLER CANNOT MOVE", _RETRY),
    **{f"042{a}1": ("WARNING TMC TOO HOT", (Choice("Continue", 2), Choice("Reset MMU", RESET))) for a in "012"},
    **{f"042{a}2": ("TMC OVERHEAT ERROR", _RESET_ONLY) for a in "012"},
    **{f"043{a}1": ("TMC DRIVER ERROR", _RESET_ONLY) for a in "012"},
    **{f"043{a}2": ("TMC DRIVER RESET", _RESET_ONLY) for a in "012"},
    **{f"043{a}3": ("TMC UNDERVOLTAGE ERR", _RESET_ONLY) for a in "012"},
    **{f"043{a}4": ("TMC DRIVER SHORTED", _RESET_ONLY) for a in "012"},
    **{f"043{a}5": ("MMU SELFTEST FAILED", _RESET_ONLY) for a in "012"},
    "04306": ("MMU MCU ERROR", _RESET_ONLY),
    "04401": ("MMU NOT RESPONDING", _LINK),
    "04402": ("COMMUNICATION ERROR", _LINK),
    "04501": ("FIL. ALREADY LOADED", (Choice("Unload", 2), Choice("Continue", 0))),
    "04502": ("INVALID TOOL", (Choice("Stop print", None), Choice("Reset MMU", RESET))),
    "04503": ("QUEUE FULL", _RESET_ONLY),
    "04504": ("MMU FW UPDATE NEEDED", _LINK),
    "04505": ("FW RUNTIME ERROR", _RESET_ONLY),
    "04506": ("UNLOAD MANUALLY", _RETRY),
    "04507": ("FILAMENT EJECTED", _CONTINUE),
    "04508": ("FILAMENT CHANGE", (Choice("Load", None), Choice("Eject", None))),
}

_EXACT: dict[int, tuple[str, str, str, str]] = {
    # word: (firmware name, printer code, meaning, what a person should do)
    0x8001: ("FINDA_DIDNT_SWITCH_ON", "04101", "FINDA didn't trigger", "check the filament path, then Retry"),
    0x8002: ("FINDA_DIDNT_SWITCH_OFF", "04102", "FINDA didn't switch off: filament stuck",
             "free the filament from the selector, then Retry"),
    0x8003: ("FSENSOR_DIDNT_SWITCH_ON", "04103", "printer filament sensor didn't trigger",
             "check the filament reached the extruder and the sensor works, then Retry"),
    0x8004: ("FSENSOR_DIDNT_SWITCH_OFF", "04104", "printer filament sensor still sees filament",
             "pull the filament out of the extruder, then Retry"),
    0x8005: ("FILAMENT_ALREADY_LOADED", "04501", "filament already loaded", "Unload (Left) or Continue (Right)"),
    0x8006: ("INVALID_TOOL", "04502", "requested filament slot does not exist", "use a slot from 0 to 4"),
    0x8047: ("STALLED_PULLEY", "04105", "pulley stalled", "check the pulley can move freely, then Retry"),
    0x8087: ("HOMING_SELECTOR_FAILED", "04115", "selector cannot home",
             "check nothing blocks the selector, then Retry"),
    0x8107: ("HOMING_IDLER_FAILED", "04125", "idler cannot home", "check nothing blocks the idler, then Retry"),
    0x804B: ("MOVE_PULLEY_FAILED", "04105", "pulley cannot move", "check the pulley can move freely, then Retry"),
    0x808B: ("MOVE_SELECTOR_FAILED", "04116", "selector cannot move",
             "check nothing blocks the selector, then Retry"),
    0x810B: ("MOVE_IDLER_FAILED", "04126", "idler cannot move", "check nothing blocks the idler, then Retry"),
    0x8008: ("FINDA_VS_EEPROM_DISREPANCY", "04506",
             "FINDA sees filament but the MMU does not know which slot is loaded",
             "unload the filament manually, then Retry"),
    0x8009: ("FSENSOR_TOO_EARLY", "04106", "printer filament sensor triggered before the filament could reach it",
             "check the sensor and the bowden length, then Retry"),
    0x800A: ("FINDA_FLICKERS", "04107", "selector can't move: FINDA sees filament",
             "check the FINDA and remove filament from the selector, then Retry"),
    0x800C: ("FILAMENT_EJECTED", "04507", "filament ejected", "remove the filament, then Continue"),
    0x800D: ("MCU_UNDERVOLTAGE_VCC", "04306", "MMU supply voltage too low",
             "check the power supply, then reset the MMU"),
    0x8029: ("FILAMENT_CHANGE", "04508", "filament change requested by the printer",
             "follow the printer's instructions"),
    0x802A: ("LOAD_TO_EXTRUDER_FAILED", "04108", "loading to the extruder failed",
             "check the extruder, then Continue"),
    0x802B: ("QUEUE_FULL", "04503", "MMU motion queue overflow", "reset the MMU"),
    0x802C: ("VERSION_MISMATCH", "04504", "MMU firmware version not supported", "update the MMU firmware"),
    0x802D: ("PROTOCOL_ERROR", "04402", "communication with the MMU failed", "check the cable, then reset the MMU"),
    0x802E: ("MMU_NOT_RESPONDING", "04401", "the MMU does not answer",
             "check the cable and the MMU's power, then reset the MMU"),
    0x802F: ("INTERNAL", "04505", "MMU firmware internal error", "reset the MMU"),
}
_AXIS_DIGIT = {0x0040: "0", 0x0080: "1", 0x0100: "2"}
_TMC_CODE = {0x8200: "3{}1", 0x8400: "3{}2", 0x8800: "3{}3", 0x9000: "3{}4", 0xA000: "2{}1", 0xC000: "2{}2"}


def _contains(word: int, mask: int) -> bool:
    return word & mask == mask


def first_axis(word: int) -> int | None:
    """The axis bit the printer looks at: the first of pulley, selector, idler present in `word`."""
    return next((bit for bit in AXIS_BITS if word & bit), None)


def printer_code(word: int) -> str:
    """The five-digit code a Prusa printer shows for a 16-bit MMU error word (04505 when it knows none better)."""
    if word in _EXACT:
        return _EXACT[word][1]
    axis = first_axis(word)
    if axis is None:
        return "04505"
    digit = _AXIS_DIGIT[axis]
    if _contains(word, SOLDERING_NEEDS_ATTENTION):
        return f"043{digit}5"
    flag = next((f for f in TMC_FLAGS if _contains(word, f)), None)
    return "04505" if flag is None else "04" + _TMC_CODE[flag].format(digit)


@dataclass(frozen=True, slots=True)
class ErrorInfo:
    code: int
    """The 16-bit word from the MMU (or the printer's own, 0x802x)."""
    name: str
    """Firmware name, e.g. FINDA_DIDNT_SWITCH_ON or TMC_RESET|TMC_SHORT_TO_GROUND_IDLER."""
    title: str
    """As on the printer's screen, e.g. FINDA DIDN'T TRIGGER."""
    meaning: str
    action: str
    printer_code: str
    choices: tuple[Choice, ...]
    """What the printer's dialog offers for it."""

    @property
    def retryable(self) -> bool:
        """The dialog offers Retry (Middle): a host may press it on its own."""
        return any(c.label == "Retry" for c in self.choices)

    def button_for(self, label: str) -> int | str | None:
        """The button a dialog choice sends ('Retry', 'Continue', 'Stop', …); None when the dialog lacks it."""
        wanted = label.lower()
        for choice in self.choices:
            if choice.label.lower() == wanted or choice.label.lower().split()[0] == wanted:
                return choice.button
        return None

    def __str__(self) -> str:
        return units.mmu_error(self.printer_code, self.title, self.code)

    def answers(self, command: str = "fabwire mmu") -> str:
        """The commands that answer this error as the printer's dialog would: "`fabwire mmu button retry`, or
        `fabwire mmu reset --yes`" (a reset always works; errors whose dialog offers no MMU button get only that)."""
        words = {"retry": "retry", "continue": "continue"}
        by_button = {0: "right", 1: "middle", 2: "left"}
        buttons = [words.get(c.label.lower(), by_button[c.button]) for c in self.choices if isinstance(c.button, int)]
        return ", ".join(f"`{command} button {b}`" for b in dict.fromkeys(buttons)) + \
            (", or " if buttons else "") + reset_line(command)

    def explained(self, *, command: str = "", detail: str = "") -> str:
        """The one line that tells a person about it, printer code first:
        `04101 FINDA DIDN'T TRIGGER (0x8001) during T1: <detail> — FINDA didn't trigger; check the filament path,
        then Retry`."""
        text = str(self)
        if command:
            text += f" during {command}"
        if detail:
            text += f": {detail}"
        return f"{text} — {self.meaning}; {self.action}"


def _tmc_words(word: int) -> tuple[str, str]:
    flags = [f for f in TMC_FLAGS if _contains(word, f) and not (f == 0x8200 and _contains(word, 0xC200))]
    return "|".join(TMC_FLAGS[f] for f in flags), ", ".join(TMC_WORDS[f] for f in flags)


def reset_line(command: str = "fabwire mmu") -> str:
    """The reset a message advises, quoted: "`fabwire mmu reset --yes`". `--yes` because the advice is often run
    where nobody can answer the reboot's question (a script, a pipe)."""
    return f"`{command} reset --yes`"


def describe_error(word: int) -> ErrorInfo:
    """Everything known about any 16-bit MMU error word, combined driver flags included."""
    pcode = printer_code(word)
    title, choices = PRINTER_ERRORS[pcode]
    if word in _EXACT:
        name, _, meaning, action = _EXACT[word]
        return ErrorInfo(word, name, title, meaning, action, pcode, choices)
    axes = [name for bit, name in AXIS_BITS.items() if word & bit]
    axis_words = " and ".join(axes) or "no axis"
    suffix = "_" + "_".join(a.upper() for a in axes) if axes else ""
    if _contains(word, SOLDERING_NEEDS_ATTENTION) and axes:
        return ErrorInfo(word, "MMU_SOLDERING_NEEDS_ATTENTION" + suffix, title,
                         f"{axis_words} driver failed the power-on self-test (soldering needs attention)",
                         "check the MMU board, then reset the MMU", pcode, choices)
    names, words = _tmc_words(word)
    if names and axes:
        warn_only = names == TMC_FLAGS[0xA000]
        action = "let the MMU cool down, then Continue or reset the MMU" if warn_only else "reset the MMU"
        return ErrorInfo(word, names + suffix, title, f"{axis_words} driver: {words}", action, pcode, choices)
    return ErrorInfo(word, f"ERROR_{word:04X}", title, f"unknown MMU error 0x{word:04x}", "reset the MMU", pcode,
                     choices)


def format_error(word: int) -> str:
    """The one text form of an MMU error, printer code first: '04101 FINDA DIDN'T TRIGGER (0x8001)'."""
    return str(describe_error(word))


def tmc_error(flag: int, axis: str) -> int:
    """The word a driver fault on one axis produces (`flag` from TMC_FLAGS)."""
    bit = {v: k for k, v in AXIS_BITS.items()}[axis]
    return flag | bit


class MMUError(DeviceError):
    """The MMU stopped in an error; the message leads with the printer code: '04101 FINDA DIDN'T TRIGGER (0x8001)'."""

    def __init__(self, word: int, *, command: str = "", detail: str = "") -> None:
        info = describe_error(word)
        super().__init__(str(info), info.meaning, action=info.action)
        self.info = info
        self.command = command
        self.args = (info.explained(command=command, detail=detail),)

    def __str__(self) -> str:
        return str(self.args[0])
