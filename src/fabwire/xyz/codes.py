"""da Vinci codes in words: states and substates, error words, cartridge colours and lengths, materials, nozzles
(reference §3; miniMover's and XYZware's tables)."""

from __future__ import annotations

import msgspec

STATE_NAMES: dict[int, str] = {
    9500: "print initial", 9501: "print heating", 9502: "printing", 9503: "print calibrating",
    9504: "print calibrating done", 9505: "printing", 9506: "print cooling done", 9507: "print cooling end",
    9508: "print ending", 9509: "print finished", 9510: "print job done", 9511: "idle", 9512: "print stopped",
    9513: "loading filament", 9514: "unloading filament", 9515: "auto calibration", 9516: "jog mode",
    9517: "fatal error", 9520: "checking file", 9530: "loading filament", 9531: "unloading filament",
    9532: "jogging", 9533: "fatal error", 9534: "homing", 9535: "calibrating bed", 9536: "cleaning nozzle",
    9537: "reading SD file", 9538: "printing SD file", 9539: "engraver: place object", 9540: "adjusting Z offset",
    9601: "print paused", 9602: "cancelling print", 9700: "busy", 9800: "scanner idle", 9801: "scanner running",
    30: "busy",
}
SUBSTATE_NAMES: dict[tuple[int, int], str] = {
    (9530, 11): "heating", (9530, 12): "loading", (9530, 14): "done",
    (9531, 21): "heating", (9531, 22): "unloading", (9531, 24): "done",
    (9532, 30): "moving", (9534, 5): "homing",
    (9535, 40): "starting", (9535, 41): "lower the detector", (9535, 43): "measuring",
    (9535, 44): "raise the detector",
    (9536, 51): "warming up", (9536, 52): "ready to clean", (9539, 30): "place object",
}
IDLE, PRINTING, PRINT_DONE, FILE_CHECK, PAUSED, CANCELLING = 9511, 9505, 9509, 9520, 9601, 9602
PRINT_STOP = 9512


def translate_state(code: int) -> int:
    """Old firmwares report 0–17; map them onto the 95xx codes."""
    if 0 <= code <= 4:
        return 9500 + code
    if 5 <= code <= 10:
        return 9501 + code
    if code == 11:
        return 9505
    if 12 <= code <= 17:
        return 9500 + code
    return code


ERROR_CODES: dict[int, tuple[str, str]] = {
    0x001B: ("M_MACHINE_BUSY", "the printer is busy"),
    0x001F: ("SCANNER_ERROR", "scanner error"),
    0x0020: ("SCANNER_BUSY", "scanner busy"),
    0x0101: ("M_THERMAL_HEATER_OUT_TIMER", "the extruder cannot reach its target temperature"),
    0x0102: ("M_THERMAL_BED_OUT_TIMER", "the bed cannot reach its target temperature"),
    0x0103: ("M_THERMAL_HEATER_OUT_CONTROL", "the extruder is too hot"),
    0x0104: ("M_THERMAL_BED_OUT_CONTROL", "the bed is too hot"),
    0x0105: ("L_ERROR_SD_CARD", "storage (SD card) error"),
    0x0108: ("M_MACHINE_ERROR_X_AXIS", "X axis error (motion or endstop)"),
    0x0109: ("M_MACHINE_ERROR_Y_AXIS", "Y axis error (motion or endstop)"),
    0x010A: ("M_MACHINE_ERROR_Z_AXIS", "Z axis error (motion or endstop)"),
    0x010B: ("M_FLASHMEMORY_ERROR", "memory error"),
    0x010D: ("L_ERROR_FLASH_RAM", "internal communication error; restart the printer"),
    0x010E: ("L_ERROR_NOZZLE_EEPROM", "extruder storage error; replace the extruder"),
    0x010F: ("L_40W35W_NOZZLE_EEPROM", "incompatible nozzle"),
    0x0201: ("M_PC_COMMUNICATION_ERROR", "connection between computer and printer failed"),
    0x0202: ("M_FW_UPDATE_ERROR", "firmware update failed"),
    0x0203: ("M_FILAMENT_JAM", "filament jam"),
    0x0205: ("M_FILAMENT_WRONG", "wrong filament"),
    0x0206: ("M_NO_CASSETTE", "no filament cartridge installed"),
    0x0207: ("M_CASSETTE_EMPTY", "filament cartridge empty"),
    0x0208: ("M_CASSETTE_EEPROM_WRITE_ERROR", "cannot write the cartridge tag"),
    0x0209: ("M_CASSETTE_EEPROM_READ_ERROR", "cannot read the cartridge tag"),
    0x020C: ("L_ERROR_SD_CARD", "SD card error"),
    0x020D: ("L_FILE_VERSION", "unsupported file version: the printer rejected the file"),
    0x020F: ("L_FILAMENT_NO_INSTALL", "filament not installed"),
    0x0401: ("M_TOP_DOOR_OPEN", "top door open"),
    0x0402: ("M_FRONT_DOOR_OPEN", "front door open"),
    0x0403: ("M_FILAMENT_LOW", "filament low"),
    0x0404: ("M_FILAMENT_LOW_TO_EMPTY", "filament nearly empty"),
    0x0405: ("M_FILAMENT_END", "filament ran out"),
}
_OLD_ERRORS = {2: 0x0101, 3: 0x001B, 4: 0x0103, 5: 0x0104, 6: 0x0105, 7: 0x0208, 8: 0x0209, 9: 0x0108, 10: 0x0109,
               11: 0x010A, 14: 0x0202, 15: 0x0203, 16: 0x0405, 17: 0x0205, 18: 0x010B, 20: 0x0401, 21: 0x0402,
               23: 0x0404, 24: 0x0405, 28: 0x0206, 29: 0x0207, 0x020B: 0x020C}
IDLE_NOISE: dict[str, frozenset[int]] = {"dvF110B000": frozenset({2})}
"""`e:` values a model reports while nothing is wrong (the 1.1 Plus says `e:2` when idle)."""
NO_CARTRIDGE = 0x40000206
FILE_REJECTED = 0x020D
HEATER_TIMEOUT = 0x40000101
DOOR_OPEN = 0x0401


class ErrorWord(msgspec.Struct, frozen=True):
    """One `e:` value decoded: where (extruder 1/2 or machine), the code, its name and meaning."""

    raw: int
    source: str
    code: int
    name: str
    meaning: str

    @classmethod
    def decode(cls, raw: int) -> ErrorWord:
        high = (raw >> 24) & 0xFF
        source = {0x40: "extruder 1", 0x20: "extruder 2"}.get(high, "machine")
        code = _OLD_ERRORS.get(raw & 0xFFFF, raw & 0xFFFF)
        name, meaning = ERROR_CODES.get(code, ("UNKNOWN", f"unknown error 0x{code:04X}"))
        return cls(raw, source, code, name, meaning)

    def __str__(self) -> str:
        where = f" ({self.source})" if self.source != "machine" else ""
        return f"0x{self.raw:08X} {self.meaning}{where}"


COLOURS = {
    "0": "Bronze", "1": "Silver", "2": "Clear Red", "3": "Clear", "4": "Bottle Green", "5": "Neon Magenta",
    "6": "SteelBlue", "7": "Sun Orange", "8": "Pearl White", "9": "Copper", "A": "Purple", "B": "Blue",
    "C": "Neon Tangerine", "D": "Viridity", "E": "Olivine", "F": "Gold", "G": "Green", "H": "Neon Green",
    "I": "Snow White", "J": "Neon Yellow", "K": "Black", "L": "Violet", "M": "Grape Purple", "N": "Purpurine",
    "O": "Clear Yellow", "P": "Clear Green", "Q": "Clear Tangerine", "R": "Red", "S": "Cyber Yellow",
    "T": "Tangerine", "U": "Clear Blue", "V": "Clear Purple", "W": "White", "X": "Clear Magenta", "Y": "Yellow",
    "Z": "Nature",
}
CARTRIDGE_LENGTHS = {"3": 120_000, "5": 185_000, "6": 240_000}
MATERIALS = {41: "ABS", 46: "TPE", 47: "PETG", 50: "PLA", 51: "PLA", 54: "Tough PLA", 56: "PVA"}
NOZZLES = {"3": 0.3, "84": 0.3, "1": 0.4, "77": 0.4, "82": 0.4, "2": 0.4, "54": 0.6, "56": 0.8, "75": 0.3}
