"""Code tables: names, words, axis bits and TMC flag combinations, register map and access rules."""

from __future__ import annotations

import asyncio

import pytest

from fabwire.errors import InputError
from fabwire.mmu import codes
from fabwire.mmu.client import MMU, resolve_register
from fabwire.transport import open_transport


@pytest.mark.parametrize(("code", "name", "printer", "retryable"), [
    (0x8001, "FINDA_DIDNT_SWITCH_ON", "04101", True),
    (0x8002, "FINDA_DIDNT_SWITCH_OFF", "04102", True),
    (0x8003, "FSENSOR_DIDNT_SWITCH_ON", "04103", True),
    (0x8004, "FSENSOR_DIDNT_SWITCH_OFF", "04104", True),
    (0x8006, "INVALID_TOOL", "04502", False),
    (0x8087, "HOMING_FAILED_SELECTOR", "04115", True),
    (0x8107, "HOMING_FAILED_IDLER", "04125", True),
    (0x8047, "STALLED_PULLEY", "04105", True),
    (0x8009, "FSENSOR_TOO_EARLY", "04106", True),
    (0x800A, "FINDA_FLICKERS", "04107", True),
    (0x800C, "FILAMENT_EJECTED", "04507", False),
    (0x808B, "MOVE_FAILED_SELECTOR", "04116", True),
    (0x9040, "TMC_SHORT_TO_GROUND_PULLEY", "04304", False),
    (0xA100, "TMC_OVER_TEMPERATURE_WARN_IDLER", "04221", False),
    (0xC080, "TMC_OVER_TEMPERATURE_ERROR_SELECTOR", "04212", False),
    (0xC240, "MMU_SOLDERING_NEEDS_ATTENTION", "", False),
    (0x802E, "MMU_NOT_RESPONDING", "04401", False),
])
def test_error_table(code: int, name: str, printer: str, retryable: bool) -> None:
    info = codes.describe_error(code)
    assert (info.name, info.printer_code, info.retryable) == (name, printer, retryable)
    assert info.meaning
    assert info.action


def test_tmc_flags_combine_into_words() -> None:
    info = codes.describe_error(0x84C0)
    assert info.name == "TMC_RESET_PULLEY_SELECTOR"
    assert info.meaning == "pulley and selector driver: driver reset"
    both = codes.describe_error(0x8000 | 0x0400 | 0x1000 | 0x0100)
    assert both.name == "TMC_RESET|TMC_SHORT_TO_GROUND_IDLER"
    assert "driver reset, short to ground" in both.meaning
    assert codes.tmc_error(0x1000, "idler") == 0x9100


def test_unknown_codes_still_describe_themselves() -> None:
    assert codes.describe_error(0x1234).name == "ERROR_1234"
    assert codes.progress_words(0x77).startswith("unknown progress")
    assert codes.progress_name(0x1C) == "FEEDING_TO_FSENSOR"
    assert codes.progress_words(0x1C) == "Feeding to FSensor"
    assert codes.progress_words(6) == "Feeding to extruder"


def test_register_map() -> None:
    assert len(codes.REGISTERS) == 0x24
    assert [r.address for r in codes.REGISTERS] == list(range(0x24))
    assert codes.find_register("0x22") is codes.find_register("bowden-length") is codes.find_register("34")
    assert codes.find_register("0x24") is None
    accel = codes.REGISTERS_BY_NAME["pulley_acceleration"]
    assert not accel.writable((3, 0, 3))
    assert accel.writable((3, 0, 4))
    assert resolve_register("fsensor", for_write=True).address == 9
    with pytest.raises(InputError, match="read-only"):
        resolve_register("finda", for_write=True)
    with pytest.raises(InputError, match="read-only on this firmware"):
        resolve_register(0x0E, for_write=True, version=(3, 0, 3))


def test_enums() -> None:
    assert codes.BUTTON_ALIASES["retry"] == codes.BUTTON_ALIASES["continue"] == codes.Button.MIDDLE
    assert codes.BUTTON_ALIASES["stop"] == codes.Button.RIGHT
    assert codes.FilamentState.IN_NOZZLE == 8
    assert codes.FIRMWARES["3.0.2"].build == 878
    assert str(codes.FIRMWARES["3.0.4"]) == "3.0.4+936"


async def test_sim_url_options() -> None:
    transport = await open_transport("sim://mmu?speed=100&version=3.0.3&fault=finda-didnt-trigger:always")
    async with asyncio.timeout(20):
        async with MMU(transport, time_scale=100, auto_retries=0) as mmu:
            assert str(mmu.version) == "3.0.3+896"
            with pytest.raises(Exception, match="FINDA didn't trigger"):
                await mmu.tool_change(1, timeout=5)
    await transport.close()
    with pytest.raises(InputError, match="speed must be a number"):
        await open_transport("sim://mmu?speed=fast")
    with pytest.raises(InputError, match="unknown MMU firmware"):
        await open_transport("sim://mmu?version=9.9.9")
