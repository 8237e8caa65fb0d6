"""The fault injector: each mode does what it says, and a seed replays the same faults."""

from __future__ import annotations

import asyncio
import contextlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fabwire.errors import InputError, LinkClosed
from fabwire.transport import FaultPlan, FaultyTransport, memory_pair

DATA = bytes(range(256)) * 8


async def drain(link: FaultyTransport | object, expected: int, limit: float = 2.0) -> bytes:
    got = bytearray()
    try:
        async with asyncio.timeout(limit):
            while len(got) < expected:
                got += await link.read()  # type: ignore[attr-defined]
    except TimeoutError:
        pass
    return bytes(got)


async def send_through(plan: FaultPlan) -> tuple[bytes, list[int], FaultyTransport]:
    """Write DATA through a faulty host end; return what the device got and the chunk sizes it saw."""
    host, device = memory_pair()
    faulty = FaultyTransport(host, plan)
    sizes: list[int] = []
    got = bytearray()

    async def reader() -> None:
        try:
            while True:
                chunk = await device.read()
                sizes.append(len(chunk))
                got.extend(chunk)
        except LinkClosed:
            pass

    task = asyncio.create_task(reader())
    with contextlib.suppress(LinkClosed):
        await faulty.write(DATA)
    await asyncio.sleep(0.01)
    await faulty.close()
    await task
    return bytes(got), sizes, faulty


async def test_split_delivers_everything_in_small_pieces() -> None:
    got, sizes, _ = await send_through(FaultPlan(chunk=3, seed=1))
    assert got == DATA
    assert max(sizes) <= 3
    assert len(sizes) > len(DATA) // 3


async def test_same_seed_same_faults_other_seed_other_faults() -> None:
    plan = FaultPlan(chunk=5, drop=0.1, corrupt=0.01, seed=42)
    first, sizes1, _ = await send_through(plan)
    second, sizes2, _ = await send_through(plan)
    third, _, _ = await send_through(FaultPlan(chunk=5, drop=0.1, corrupt=0.01, seed=43))
    assert (first, sizes1) == (second, sizes2)
    assert first != third


async def test_drop_loses_whole_pieces() -> None:
    got, _, faulty = await send_through(FaultPlan(chunk=16, drop=0.25, seed=7))
    assert 0 < len(got) < len(DATA)
    assert faulty.dropped == len(DATA) - len(got)


async def test_corrupt_flips_bits_without_changing_length() -> None:
    got, _, faulty = await send_through(FaultPlan(corrupt=0.02, seed=3))
    assert len(got) == len(DATA)
    flipped = sum(1 for a, b in zip(got, DATA, strict=True) if a != b)
    assert flipped == faulty.corrupted > 0
    assert all(bin(a ^ b).count("1") == 1 for a, b in zip(got, DATA, strict=True) if a != b)


async def test_disconnect_after_n_bytes_closes_the_link() -> None:
    got, _, faulty = await send_through(FaultPlan(disconnect_after=100, seed=1))
    assert got == DATA[:100]
    assert faulty.closed
    with pytest.raises(LinkClosed, match="injected"):
        await faulty.write(b"more")


async def test_silent_after_n_bytes_swallows_writes_and_reads_block() -> None:
    host, device = memory_pair()
    faulty = FaultyTransport(host, FaultPlan(silent_after=10))
    await faulty.write(b"0123456789abcdef")
    assert await drain(device, 16, 0.2) == b"0123456789"
    await device.write(b"reply")
    assert await drain(faulty, 5, 0.2) == b""  # the peer seems to have gone quiet
    await faulty.close()


async def test_read_side_faults_apply_to_what_the_wrapped_end_receives() -> None:
    host, device = memory_pair()
    faulty = FaultyTransport(device, FaultPlan(chunk=2, side="read", seed=5))
    await host.write(DATA[:64])
    pieces = []
    async with asyncio.timeout(2):
        while sum(map(len, pieces)) < 64:
            pieces.append(await faulty.read())
    assert b"".join(pieces) == DATA[:64]
    assert max(map(len, pieces)) <= 2


async def test_delay_holds_pieces_back() -> None:
    loop = asyncio.get_running_loop()
    start = loop.time()
    got, _, _ = await send_through(FaultPlan(chunk=64, delay=0.01, seed=2))
    assert got == DATA
    assert loop.time() - start > 0  # the delays were awaited (lower bound only: no flaky upper bound)


def test_plan_parses_from_text_and_rejects_nonsense() -> None:
    plan = FaultPlan.parse("chunk=1, delay=0.5, drop=0.1, corrupt=0.01, silent_after=9, disconnect-after=99, seed=4")
    assert plan == FaultPlan(chunk=1, delay=0.5, drop=0.1, corrupt=0.01, silent_after=9, disconnect_after=99, seed=4)
    for bad in ("chunk", "chunk=x", "explode=1", "side=up"):
        with pytest.raises(InputError):
            FaultPlan.parse(bad)


@pytest.mark.parametrize("text", ["delay=nan", "delay=1e308", "delay=-1", "corrupt=nan", "drop=2", "chunk=-1",
                                  "silent_after=-3", "seed=" + "9" * 5000, "x" * 5000 + "=1", "side=sideways"])
def test_a_fault_plan_out_of_range_is_one_input_error(text: str) -> None:
    with pytest.raises(InputError) as caught:
        FaultPlan.parse(text)
    assert len(str(caught.value)) < 300


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=80) | st.lists(st.tuples(
    st.sampled_from(["chunk", "delay", "drop", "corrupt", "silent_after", "disconnect_after", "seed", "side"]),
    st.text(max_size=12) | st.floats().map(str) | st.integers().map(str)), max_size=5).map(
        lambda items: ",".join(f"{k}={v}" for k, v in items)))
def test_any_fault_plan_text_is_a_plan_in_range_or_one_input_error(text: str) -> None:
    try:
        plan = FaultPlan.parse(text)
    except InputError:
        return
    assert 0 <= plan.drop <= 1
    assert 0 <= plan.corrupt <= 1
    assert 0 <= plan.delay <= 60
    assert plan.chunk >= 0
