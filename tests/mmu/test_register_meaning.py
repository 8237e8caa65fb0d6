"""What a register read means, register by register (`fabwire.mmu.codes.REGISTERS`): the firmware puts the pulley's
int32 millimetres into the 16-bit register 0x1a, so a read of 60902 is -4634 mm; every other register holds an
unsigned number. `status`, `read` and `registers` say the same number."""

from __future__ import annotations

import asyncio

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fabwire.mmu import MMU, codes
from fabwire.mmu.sim import MMUSimulator

from .test_client import LIMIT, SPEED, over_memory

SIGNED = {0x1A}
"""Registers the firmware fills with a signed number (MMU:src/registers.cpp: 0x1a pulley.CurrentPosition_mm, an
int32 truncated to uint16); the rest are counts, speeds, currents, slots and flags."""


def test_the_table_marks_exactly_the_signed_registers() -> None:
    assert {reg.address for reg in codes.REGISTERS if reg.signed} == SIGNED


@given(st.sampled_from(codes.REGISTERS), st.data())
def test_every_registers_read_means_one_number(reg: codes.Register, data: st.DataObject) -> None:
    value = data.draw(st.integers(0, (1 << reg.bits) - 1))
    meant = reg.meant(value)
    if reg.signed:
        assert -(1 << (reg.bits - 1)) <= meant < 1 << (reg.bits - 1)
        assert meant & ((1 << reg.bits) - 1) == value  # the same bits
        assert reg.shown(value) == (str(value) if meant >= 0 else f"{value} ({meant})")
    else:
        assert meant == value
        assert reg.shown(value) == str(value)


@pytest.mark.parametrize("position", [-4634.0, -1.0, 0.0, 250.0, 32767.0, -32768.0])
async def test_status_and_read_agree_on_the_pulley_position(position: float) -> None:
    sim = MMUSimulator(speed=SPEED)
    async with asyncio.timeout(LIMIT), over_memory(sim) as transport, MMU(transport, time_scale=SPEED) as mmu:
        sim.model.pulley_mm = position
        raw = await mmu.read_register("pulley_position")
        assert raw == int(position) & 0xFFFF  # what crosses the wire
        assert codes.REGISTERS[0x1A].meant(raw) == int(position)
        assert (await mmu.refresh()).pulley == int(position)
