"""Code tables: progress words, register map and access rules, enums, firmware personalities."""

from __future__ import annotations

import asyncio

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from fabwire.errors import InputError
from fabwire.mmu import codes
from fabwire.mmu.client import MMU, resolve_register
from fabwire.mmu.errors import MMUError
from fabwire.transport import open_transport


def test_unknown_progress_codes_still_describe_themselves() -> None:
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
    assert codes.BUTTON_ALIASES == {"right": codes.Button.RIGHT, "middle": codes.Button.MIDDLE,
                                    "left": codes.Button.LEFT}  # by place only: a dialog's words vary by error
    assert codes.FilamentState.IN_NOZZLE == 8
    assert codes.FIRMWARES["3.0.2"].build == 878
    assert str(codes.FIRMWARES["3.0.4"]) == "3.0.4+936"


async def test_sim_url_options() -> None:
    transport = await open_transport("sim://mmu?speed=100&version=3.0.3&fault=finda-didnt-trigger:always")
    async with asyncio.timeout(20):
        async with MMU(transport, time_scale=100, auto_retries=0) as mmu:
            assert str(await mmu.version()) == "3.0.3+896"
            with pytest.raises(MMUError, match=r"^04101 FINDA DIDN'T TRIGGER \(0x8001\) during T1"):
                await mmu.tool_change(1, timeout=5)
    await transport.close()
    with pytest.raises(InputError, match=r"sim://mmu option 'speed': expected a number from 0\.01 to 10000, not"):
        await open_transport("sim://mmu?speed=fast")
    with pytest.raises(InputError, match="unknown MMU firmware"):
        await open_transport("sim://mmu?version=9.9.9")


@given(st.text(max_size=30) | st.from_regex(r"0x[0-9a-fA-F]{1,6000}", fullmatch=True)
       | st.from_regex(r"[0-9]{1,6000}", fullmatch=True))
@example("4294967295")
@example("0xFFFFFFFF")
@example("5000000000")
def test_a_typed_register_word_is_a_number_or_nothing(text: str) -> None:
    number = codes.parse_word(text)
    key = text.strip().lower()
    if number is None:
        return
    assert key.isascii()
    assert 0 <= number < 1 << 32
    assert number == int(key, 0 if key.startswith("0x") else 10)


@pytest.mark.parametrize("text", ["0x-1", "1_0", "\u0663", "-1", "+5", "0x", "", "0b1", "1e3", "5000000000",
                                  "0x100000000", "4294967296"])
def test_words_python_reads_but_a_person_did_not_mean_are_refused(text: str) -> None:
    assert codes.parse_word(text) is None
    assert codes.find_register(text) is None
