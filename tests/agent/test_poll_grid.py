"""Polls start on a grid (`on_poll_grid`) so that a bench's polls within one step wake the links' thread together:
a start is a grid point, never before the slot, less than a step after it; slots a whole number of steps apart stay
on the grid however long the agent runs."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from fabwire.agent.linkside import POLL_TICK_S, next_slot, on_poll_grid


@given(when=st.floats(0.0, 1e7, allow_nan=False))
def test_a_start_is_the_next_grid_point(when: float) -> None:
    start = on_poll_grid(when)
    assert abs(start / POLL_TICK_S - round(start / POLL_TICK_S)) < 1e-6
    assert start >= when - POLL_TICK_S * 1e-5
    assert start - when < POLL_TICK_S


@given(first=st.floats(0.0, 1e6, allow_nan=False), interval_steps=st.integers(1, 500))
def test_slots_a_whole_number_of_steps_apart_stay_on_the_grid(first: float, interval_steps: int) -> None:
    interval = interval_steps * POLL_TICK_S
    slot = on_poll_grid(first)
    for _ in range(20_000):  # hours of polls at 1 Hz
        after = next_slot(slot, interval)
        assert abs(after - slot - interval) < POLL_TICK_S / 100
        slot = after
        assert on_poll_grid(slot) == slot  # a poll on schedule waits for no later step


@given(slot=st.floats(0.0, 1e6, allow_nan=False), interval=st.floats(0.001, 100.0))
def test_an_interval_off_the_grid_is_kept_exactly(slot: float, interval: float) -> None:
    """Such a poll starts at the grid point after its slot; its schedule itself does not move."""
    steps = interval / POLL_TICK_S
    if abs(steps - round(steps)) > 1e-3:
        assert next_slot(slot, interval) == slot + interval
