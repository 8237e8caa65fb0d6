"""A machine's link as it runs on the links' loop (the agent's links thread, or its links' process): the driver,
polls on the grid's schedule, a poll out of turn, an action followed by a poll."""

from __future__ import annotations

import asyncio
import math
import random
import time
from collections.abc import Callable
from typing import Any

from fabwire.agent.core import DeviceSpec
from fabwire.agent.drivers.base import Driver, Emit
from fabwire.errors import FabwireError

LINK_FAILURES = (FabwireError, OSError, TimeoutError, EOFError)
"""What ends a connection (the clients raise FabwireError subclasses; the OS may still say OSError)."""

POLL_TICK_S = 0.05
"""Polls start on a grid of this step (`on_poll_grid`): the polls of a bench that fall within one step wake the links'
loop once, together, and their replies are read in the same turns of that loop. A wake-up of the loop, not the
work of a poll, is most of what a poll costs (measured: a 20 ms step cut the CPU per poll of 250 printers by a
quarter, 50 ms by a third more). A poll starts at most this much after its slot; at 1 s, the interval, a whole
number of steps, the slots themselves lie on the grid and a poll starts on time."""
GRID_SLACK = 1e-6
"""Steps a slot may lie past a grid point and still count as on it (a float's rounding)."""

Polled = tuple[dict[str, Any] | None, dict[str, Any]]
"""A poll's (`--json status` dict or None, summary)."""
Deliver = Callable[[dict[str, Any] | None, dict[str, Any], float, float, float], None]
"""Takes a scheduled poll's (status, summary, wall-clock time s, lag s behind its slot, interval s) to the agent."""


def on_poll_grid(when: float) -> float:
    """The first instant of the poll grid (every POLL_TICK_S of the loop's clock) at or after `when`."""
    return math.ceil(when / POLL_TICK_S - GRID_SLACK) * POLL_TICK_S


def next_slot(slot: float, interval: float) -> float:
    """The slot `interval` after `slot`; put back on the grid when the interval is a whole number of steps, so that
    the float sum of many intervals does not drift off it."""
    later = slot + interval
    steps = interval / POLL_TICK_S
    return on_poll_grid(later) if abs(steps - round(steps)) < GRID_SLACK else later


def make_driver(spec: DeviceSpec, emit: Emit) -> Driver:
    """Import only the kind in use: a bench of printers never loads the drawing stack."""
    if spec.kind == "xyz":
        from fabwire.agent.drivers.xyz import XYZDriver

        return XYZDriver(spec, emit)
    if spec.kind == "lineus":
        from fabwire.agent.drivers.lineus import LineUsDriver

        return LineUsDriver(spec, emit)
    from fabwire.agent.drivers.mmu import MMUDriver

    return MMUDriver(spec, emit)


class LinkSide:
    """One machine's driver and the work done with it on the links' loop. `deliver` takes each scheduled poll's
    result to the agent; `step_aside` runs between polls (the links thread waits there for the agent's requests)."""

    def __init__(self, spec: DeviceSpec, emit: Emit, deliver: Deliver, step_aside: Callable[[], None]) -> None:
        self.driver = make_driver(spec, emit)
        self._deliver = deliver
        self._step_aside = step_aside

    async def poll_forever(self) -> None:
        """Poll on schedule until cancelled or the link fails (raising what the driver raised)."""
        loop = asyncio.get_running_loop()
        driver = self.driver
        interval = driver.interval_s
        slot = on_poll_grid(loop.time() + random.uniform(0, interval))  # spread a bench's polls over the second
        await asyncio.sleep(slot - loop.time())
        while True:
            lag = loop.time() - slot
            status, summary = await driver.poll()
            self._step_aside()
            self._deliver(status, summary, time.time(), lag, interval)
            slot = next_slot(slot, interval)
            now = loop.time()
            if slot < now:
                slot = on_poll_grid(now)  # fell behind: start again from now rather than firing a burst
            await asyncio.sleep(on_poll_grid(slot) - now)

    async def poll_now(self) -> Polled | None:
        """A poll out of turn, or None when it fails (the scheduled polls report that)."""
        try:
            return await self.driver.poll()
        except LINK_FAILURES:
            return None

    async def act_then_poll(self, action: str, params: dict[str, Any]) -> tuple[dict[str, Any], Polled | None]:
        """The action, then a poll, so the state is the one the action left by the time its reply goes out (an
        upload right after "print removed" finds the printer ready, not the state of the poll before). A poll that
        fails leaves the state to the next scheduled one: the action itself was done."""
        result = await self.driver.act(action, params)
        return result, await self.poll_now()
