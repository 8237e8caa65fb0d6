"""The MMU3's numeric vocabularies, with the names the firmware uses and what they mean to a person.

Wire values are hex; the enums hold the numbers, `describe_*` turn them into words.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass
from typing import Literal

from fabwire.mmu.errors import ErrorInfo, describe_error, format_error  # noqa: F401  (error words: own module)


class Progress(enum.IntEnum):
    OK = 0
    ENGAGING_IDLER = 1
    DISENGAGING_IDLER = 2
    UNLOADING_TO_FINDA = 3
    UNLOADING_TO_PULLEY = 4
    FEEDING_TO_FINDA = 5
    FEEDING_TO_BONDTECH = 6
    FEEDING_TO_NOZZLE = 7
    AVOIDING_GRIND = 8
    FINISHING_MOVES = 9
    ERR_DISENGAGING_IDLER = 10
    ERR_ENGAGING_IDLER = 11
    ERR_WAITING_FOR_USER = 12
    ERR_INTERNAL = 13
    ERR_HELPING_FILAMENT = 14
    ERR_TMC_FAILED = 15
    UNLOADING_FILAMENT = 16
    LOADING_FILAMENT = 17
    SELECTING_FILAMENT_SLOT = 18
    PREPARING_BLADE = 19
    PUSHING_FILAMENT = 20
    PERFORMING_CUT = 21
    RETURNING_SELECTOR = 22
    PARKING_SELECTOR = 23
    EJECTING_FILAMENT = 24
    RETRACTING_FROM_FINDA = 25
    HOMING = 26
    MOVING_SELECTOR = 27
    FEEDING_TO_FSENSOR = 28
    HW_TEST_BEGIN = 29
    HW_TEST_IDLER = 30
    HW_TEST_SELECTOR = 31
    HW_TEST_PULLEY = 32
    HW_TEST_CLEANUP = 33
    HW_TEST_EXEC = 34
    HW_TEST_DISPLAY = 35
    ERR_HW_TEST_FAILED = 36
    EMPTY = 255


PROGRESS_WORDS: dict[int, str] = {
    0: "OK",
    1: "Engaging idler",
    2: "Disengaging idler",
    3: "Unloading to FINDA",
    4: "Unloading to pulley",
    5: "Feeding to FINDA",
    6: "Feeding to extruder",
    7: "Feeding to nozzle",
    8: "Avoiding grind",
    9: "Finishing moves",
    10: "Disengaging idler (error)",
    11: "Engaging idler (error)",
    12: "Waiting for user",
    13: "Internal error",
    14: "Helping filament",
    15: "TMC driver failed",
    16: "Unloading filament",
    17: "Loading filament",
    18: "Selecting filament slot",
    19: "Preparing blade",
    20: "Pushing filament",
    21: "Performing cut",
    22: "Returning selector",
    23: "Parking selector",
    24: "Ejecting filament",
    25: "Retracting from FINDA",
    26: "Homing",
    27: "Moving selector",
    28: "Feeding to FSensor",
    29: "Hardware test: begin",
    30: "Hardware test: idler",
    31: "Hardware test: selector",
    32: "Hardware test: pulley",
    33: "Hardware test: cleanup",
    34: "Hardware test: running",
    35: "Hardware test: display",
    36: "Hardware test failed",
    255: "Empty",
}


def progress_words(code: int) -> str:
    return PROGRESS_WORDS.get(code, f"unknown progress 0x{code:x}")


def progress_name(code: int) -> str:
    try:
        return Progress(code).name
    except ValueError:
        return f"PROGRESS_{code:X}"


class Result(enum.IntEnum):
    OK = 0
    CANCELLED = 1


class Button(enum.IntEnum):
    """What `B` carries in both directions; Middle is the one the MMU's own recovery listens to."""

    RIGHT = 0
    MIDDLE = 1
    LEFT = 2


BUTTON_WORDS = {0: "Right", 1: "Middle", 2: "Left"}

BUTTON_ALIASES: dict[str, int] = {"right": 0, "middle": 1, "left": 2}
"""The buttons by their place. A dialog's words (Retry, Continue, Stop) are no fixed button: each error's dialog
says which it sends (`fabwire.mmu.errors`, `MMU.dialog_button`)."""


class FilamentState(enum.IntEnum):
    NOT_LOADED = 0
    AT_PULLEY = 1
    IN_SELECTOR = 2
    IN_FSENSOR = 4
    IN_NOZZLE = 8


FILAMENT_WORDS = {0: "not loaded", 1: "at pulley", 2: "in selector", 4: "in filament sensor", 8: "in nozzle"}


class FSensor(enum.IntEnum):
    """Printer filament-sensor states a host reports with `f`; the MMU treats any non-zero value as 'on'."""

    NOT_PRESENT = 0
    AT_FSENSOR = 1
    IN_NOZZLE = 2
    UNAVAILABLE = 3


# ------------------------------------------------------------------------------------------- registers

class Access(enum.Enum):
    RO = "read-only"
    RW = "read/write"
    RW_304 = "read-only before 3.0.4, read/write from 3.0.4"


Store = Literal["none", "u8", "u16", "accel", "eeprom-u8", "bowden", "filament", "fsensor", "selector", "idler"]
"""How a write is kept (`fabwire.mmu.units`): "none" read-only; "u8"/"u16" the variable's width; "accel" motor
steps; "eeprom-u8" an EEPROM byte whose erased value reads as the default; "bowden" an EEPROM word read back only
inside 341..1000 mm; "filament" the load state (any byte, recorded in EEPROM from InSelector on); "fsensor" on/off;
"selector"/"idler" a planned move to a slot."""


@dataclass(frozen=True, slots=True)
class Register:
    address: int
    name: str
    bits: int
    access: Access
    default: int | None
    """The firmware's default (`config.h`) as written to the register; None where the machine's state decides."""
    meaning: str
    store: Store
    boot: int | None
    """What a read answers on 3.0.4 after power-on with an erased EEPROM, once the boot homing is done (None: the
    build, which depends on the version)."""
    source: str
    """The firmware's read and write functions for it (`MMU` = prusa3d/Prusa-Firmware-MMU)."""
    signed: bool = False
    """The firmware puts a signed number in it (two's complement, truncated to `bits`): a read of 60902 from the
    16-bit pulley position means -4634 mm."""

    def meant(self, value: int) -> int:
        """The number the firmware means by a read of `value` (its two's complement when `signed`)."""
        return value - (1 << self.bits) if self.signed and value >= 1 << (self.bits - 1) else value

    def shown(self, value: int) -> str:
        """A read as a person reads it: `60902 (-4634)` for a signed register's negative number, else the number."""
        meant = self.meant(value)
        return str(value) if meant == value else f"{value} ({meant})"

    def writable(self, version: tuple[int, int, int]) -> bool:
        if self.access is Access.RW:
            return True
        return self.access is Access.RW_304 and version >= (3, 0, 4)


_REG = "MMU:src/registers.cpp registers[]"
REGISTERS: tuple[Register, ...] = (
    Register(0x00, "project_major", 8, Access.RO, 3, "firmware major version", "none", 3,
             f"{_REG} 0x00 (project_major)"),
    Register(0x01, "project_minor", 8, Access.RO, 0, "firmware minor version", "none", 0,
             f"{_REG} 0x01 (project_minor)"),
    Register(0x02, "project_revision", 8, Access.RO, None, "firmware revision", "none", 4,
             f"{_REG} 0x02 (project_revision)"),
    Register(0x03, "project_build", 16, Access.RO, None, "firmware build number", "none", None,
             f"{_REG} 0x03 (project_build_number)"),
    Register(0x04, "drive_errors", 16, Access.RO, 0, "drive errors counted since the EEPROM was reset", "none", 0,
             f"{_REG} 0x04 (globals.DriveErrors; no writer); permanent_storage.cpp DriveError::get"),
    Register(0x05, "progress", 8, Access.RO, None, "current progress code", "none", 0,
             f"{_REG} 0x05 (application.CurrentProgressCode)"),
    Register(0x06, "error", 16, Access.RO, None, "current error code", "none", 1,
             f"{_REG} 0x06 (application.CurrentErrorCode)"),
    Register(0x07, "filament_state", 8, Access.RW, 1, "where the filament is (0,1,2,4,8)", "filament", 1,
             f"{_REG} 0x07 (globals.FilamentLoaded / SetFilamentLoaded); globals.cpp SetFilamentLoaded"),
    Register(0x08, "finda", 8, Access.RO, 0, "FINDA sees filament (1) or not (0)", "none", 0,
             f"{_REG} 0x08 (finda.Pressed)"),
    Register(0x09, "fsensor", 8, Access.RW, 0, "printer filament sensor as reported by the printer", "fsensor", 0,
             f"{_REG} 0x09 (fsensor.Pressed / fsensor.ProcessMessage(v != 0))"),
    Register(0x0A, "motor_mode", 8, Access.RO, 0, "0 normal, 1 stealth", "none", 0,
             f"{_REG} 0x0a (globals.MotorsStealth)"),
    Register(0x0B, "extra_load_distance", 8, Access.RW, 30, "mm pushed from the filament sensor to the nozzle",
             "u8", 30, f"{_REG} 0x0b; globals.h SetFSensorToNozzle_mm(uint8_t)"),
    Register(0x0C, "fsensor_unload_check_distance", 8, Access.RW, 40, "mm pulled before the sensor must be clear",
             "u8", 40, f"{_REG} 0x0c; globals.h SetFSensorUnloadCheck_mm(uint8_t)"),
    Register(0x0D, "pulley_unload_feedrate", 16, Access.RW, 95, "mm/s", "u16", 95,
             f"{_REG} 0x0d; globals.h SetPulleyUnloadFeedrate_mm_s(uint16_t)"),
    Register(0x0E, "pulley_acceleration", 16, Access.RW_304, 800, "mm/s² (kept in steps/s², read back truncated)",
             "accel", 799, f"{_REG} 0x0e (motion.Acceleration / SetAcceleration(unitToSteps)); axisunit.h "
             "axisUnitToTruncatedUnit"),
    Register(0x0F, "selector_acceleration", 16, Access.RW_304, 200, "mm/s² (kept in steps/s², read back "
             "truncated)", "accel", 200, f"{_REG} 0x0f (motion.Acceleration / SetAcceleration(unitToSteps)); "
             "axisunit.h axisUnitToTruncatedUnit"),
    Register(0x10, "idler_acceleration", 16, Access.RW_304, 500, "deg/s² (kept in steps/s², read back truncated)",
             "accel", 499, f"{_REG} 0x10 (motion.Acceleration / SetAcceleration(unitToSteps)); axisunit.h "
             "axisUnitToTruncatedUnit"),
    Register(0x11, "pulley_load_feedrate", 16, Access.RW, 95, "mm/s", "u16", 95,
             f"{_REG} 0x11; globals.h SetPulleyLoadFeedrate_mm_s(uint16_t)"),
    Register(0x12, "selector_nominal_feedrate", 16, Access.RW, 45, "mm/s", "u16", 45,
             f"{_REG} 0x12; globals.h SetSelectorFeedrate_mm_s(uint16_t)"),
    Register(0x13, "idler_nominal_feedrate", 16, Access.RW, 300, "deg/s", "u16", 300,
             f"{_REG} 0x13; globals.h SetIdlerFeedrate_deg_s(uint16_t)"),
    Register(0x14, "pulley_slow_feedrate", 16, Access.RW, 20, "mm/s", "u16", 20,
             f"{_REG} 0x14; globals.h SetPulleySlowFeedrate_mm_s(uint16_t)"),
    Register(0x15, "selector_homing_feedrate", 16, Access.RW, 30, "mm/s", "u16", 30,
             f"{_REG} 0x15; globals.h SetSelectorHomingFeedrate_mm_s(uint16_t)"),
    Register(0x16, "idler_homing_feedrate", 16, Access.RW, 265, "deg/s", "u16", 265,
             f"{_REG} 0x16; globals.h SetIdlerHomingFeedrate_deg_s(uint16_t)"),
    Register(0x17, "pulley_sg_thrs", 8, Access.RW, 8, "pulley StallGuard threshold (EEPROM)", "eeprom-u8", 8,
             f"{_REG} 0x17; globals.cpp StallGuardThreshold / SetStallGuardThreshold; eeprom.cpp ReadByte(addr, "
             "default)"),
    Register(0x18, "selector_sg_thrs", 8, Access.RW, 3, "selector StallGuard threshold (EEPROM)", "eeprom-u8", 3,
             f"{_REG} 0x18; globals.cpp StallGuardThreshold / SetStallGuardThreshold; eeprom.cpp ReadByte(addr, "
             "default)"),
    Register(0x19, "idler_sg_thrs", 8, Access.RW, 7, "idler StallGuard threshold (EEPROM)", "eeprom-u8", 7,
             f"{_REG} 0x19; globals.cpp StallGuardThreshold / SetStallGuardThreshold; eeprom.cpp ReadByte(addr, "
             "default)"),
    Register(0x1A, "pulley_position", 16, Access.RO, 0, "pulley position, mm (signed)", "none", 0,
             f"{_REG} 0x1a (pulley.CurrentPosition_mm, int32 → uint16)", signed=True),
    Register(0x1B, "selector_slot", 8, Access.RW, None, "selector slot (5 = park, 255 = unknown)", "selector", 5,
             f"{_REG} 0x1b (selector.Slot / selector.MoveToSlot(uint8_t)); selector.cpp MoveToSlot"),
    Register(0x1C, "idler_slot", 8, Access.RW, None, "idler slot (5 = disengaged, 255 = unknown)", "idler", 5,
             f"{_REG} 0x1c (idler.Slot / d >= toolCount ? Disengage : Engage(d))"),
    Register(0x1D, "selector_cut_irun", 8, Access.RW, 40, "selector current while cutting", "u8", 40,
             f"{_REG} 0x1d; globals.h SetCutIRunCurrent(uint8_t)"),
    Register(0x1E, "pulley_irun", 8, Access.RW, 13, "pulley run current", "u8", 13,
             f"{_REG} 0x1e; motion.h SetIRunForAxis(axis, uint8_t)"),
    Register(0x1F, "selector_irun", 8, Access.RW, 31, "selector run current", "u8", 31,
             f"{_REG} 0x1f; motion.h SetIRunForAxis(axis, uint8_t)"),
    Register(0x20, "idler_irun", 8, Access.RW, 31, "idler run current", "u8", 31,
             f"{_REG} 0x20; motion.h SetIRunForAxis(axis, uint8_t)"),
    Register(0x21, "vcc", 16, Access.RO, 225, "supply voltage (placeholder value)", "none", 225,
             f"{_REG} 0x21 (constant 225)"),
    Register(0x22, "bowden_length", 16, Access.RW, 360, "bowden tube length, mm (341-1000)", "bowden", 360,
             f"{_REG} 0x22; permanent_storage.cpp BowdenLength::Get / Set"),
    Register(0x23, "cut_length", 8, Access.RW, 8, "mm of filament cut", "u8", 8,
             f"{_REG} 0x23; globals.h SetCutLength(uint8_t)"),
)
REGISTER_COUNT = len(REGISTERS)
REGISTERS_BY_NAME = {r.name: r for r in REGISTERS}


_WORD = re.compile(r"0x[0-9a-f]{1,8}|[0-9]{1,10}")


def parse_word(text: str) -> int | None:
    """A register address or value as a person types it: ASCII decimal, or hex with 0x (case-insensitive), as an
    int from 0 to 2**32 - 1; None for anything else (signs, underscores, other scripts' digits, a number beyond 32
    bits). The caller checks the register's own range, so 70000 can be refused as out of range, not as garbage."""
    key = text.strip().lower()
    if not _WORD.fullmatch(key):
        return None
    number = int(key, 16) if key.startswith("0x") else int(key)
    return number if number <= 0xFFFF_FFFF else None


def find_register(text: str) -> Register | None:
    """A register by name or by address (decimal, or hex with 0x)."""
    key = text.strip().lower().replace("-", "_")
    if key in REGISTERS_BY_NAME:
        return REGISTERS_BY_NAME[key]
    address = parse_word(text)
    return REGISTERS[address] if address is not None and 0 <= address < REGISTER_COUNT else None


# ---------------------------------------------------------------------------------------------- versions

@dataclass(frozen=True, slots=True)
class FirmwareVersion:
    major: int
    minor: int
    revision: int
    build: int

    @property
    def triple(self) -> tuple[int, int, int]:
        return (self.major, self.minor, self.revision)

    def __str__(self) -> str:
        return f"{self.major}.{self.minor}.{self.revision}+{self.build}"


FIRMWARES = {
    "3.0.2": FirmwareVersion(3, 0, 2, 878),
    "3.0.3": FirmwareVersion(3, 0, 3, 896),
    "3.0.4": FirmwareVersion(3, 0, 4, 936),
}
"""The versions a simulated MMU can report (S0-S3; builds = the firmware repository's commit count). A printer
accepts exactly one: the MK3/MK3S firmware (Prusa-Firmware `mmu2_supported_version.h`) insists on 3.0.2, the
Buddy firmware (MK4, MK3.5, XL: Prusa-Firmware-Buddy `mmu2_supported_version.h`) on 3.0.3, recent Core One
firmware on 3.0.4 — pair `fabwire sim mmu --version` with the printer. 3.0.4 stays the default."""
