"""The agent's links on a thread of their own: one event loop beside the agent's, sharing its interpreter."""

from __future__ import annotations

import asyncio
import sys
import threading
from collections.abc import Callable, Coroutine
from functools import partial
from pathlib import Path
from typing import Any, TypeVar

from fabwire.agent.core import DeviceSpec
from fabwire.agent.drivers.base import Identity
from fabwire.agent.links import LinkOwner
from fabwire.agent.linkside import LinkSide, Polled
from fabwire.agent.offload import check_within

T = TypeVar("T")
SWITCH_INTERVAL_S = 0.0005
DELIVER_EVERY_S = 0.01
"""How long a poll's result may wait on the links' loop for others to go to the agent's loop with it."""
STOP_WAIT_S = 30.0
"""How long the thread may take to finish what is scheduled on it when it is closed."""


class LinkThread:
    """A thread with an event loop of its own where an agent's device links live: connecting, polling and
    parsing a bench of machines, actions and jobs on the wire. The agent's own loop (its HTTP API, the dashboard,
    the event stream) only receives what each poll found, so a request waits for no machine's poll. One per agent,
    started with its first session, ended with its last; on uvloop where it is installed."""

    def __init__(self, home: asyncio.AbstractEventLoop | None = None) -> None:
        self.home = home or asyncio.get_running_loop()
        """The agent's loop, where `deliver` hands results over."""
        self._results: list[tuple[Callable[..., None], tuple[Any, ...]]] = []
        try:
            import uvloop
        except ImportError:
            self.loop = asyncio.new_event_loop()
        else:
            self.loop = uvloop.new_event_loop()
        self.users = 0
        self.on_empty: Callable[[], None] = lambda: None
        """Called when its last link is released (and the thread closed)."""
        # Hand the interpreter over between the two threads every 0.5 ms rather than 5: an API request waits for
        # the polling thread at most that long at each step of its handling.
        sys.setswitchinterval(min(sys.getswitchinterval(), SWITCH_INTERVAL_S))
        self._thread = threading.Thread(target=self.loop.run_forever, name="fabwire-links", daemon=True)
        self._thread.start()

    def deliver(self, callback: Callable[..., None], *args: Any) -> None:
        """From the links' loop: `callback(*args)` runs on the agent's loop within DELIVER_EVERY_S, after what was
        delivered before it, together with everything else delivered meanwhile: a bench's polls wake the agent's
        loop (and hand the interpreter over) about a hundred times a second however many machines there are."""
        if not self._results:
            self.loop.call_later(DELIVER_EVERY_S, self._hand_over)
        self._results.append((callback, args))

    def _hand_over(self) -> None:
        batch, self._results = self._results, []
        self.home.call_soon_threadsafe(run_all, batch)

    async def run(self, work: Coroutine[Any, Any, T]) -> T:
        """Run `work` on the links' loop and wait for it here; cancelling the wait cancels the work."""
        return await asyncio.wrap_future(asyncio.run_coroutine_threadsafe(work, self.loop))

    def open(self, spec: DeviceSpec, owner: LinkOwner, step_aside: Callable[[], None]) -> ThreadLink:
        """A link to the machine of `spec` on this thread, reporting to `owner` on the agent's loop."""
        self.users += 1
        return ThreadLink(self, spec, owner, step_aside)

    def close(self) -> None:
        """Stop the loop once what is scheduled on it has run, and wait for the thread."""
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(STOP_WAIT_S)
        if not self._thread.is_alive():
            self.loop.close()


def run_all(batch: list[tuple[Callable[..., None], tuple[Any, ...]]]) -> None:
    """Each callback as if scheduled on its own: one that fails is reported and the rest still run."""
    for callback, args in batch:
        try:
            callback(*args)
        except Exception as exc:  # as the loop reports a failed callback
            asyncio.get_running_loop().call_exception_handler(
                {"message": f"exception in callback {callback!r}", "exception": exc})


class ThreadLink:
    """A `fabwire.agent.links.DeviceLink` whose driver lives on a `LinkThread`."""

    def __init__(self, links: LinkThread, spec: DeviceSpec, owner: LinkOwner, step_aside: Callable[[], None]
                 ) -> None:
        home = links.home
        self._links = links
        self._owner = owner

        def emit(payload: dict[str, Any]) -> None:
            home.call_soon_threadsafe(owner.device_event, payload)

        self._side = LinkSide(spec, emit, lambda *polled: links.deliver(owner.polled, *polled), step_aside)
        self.driver = self._side.driver
        self.host: LinkThread = links

    async def connect(self) -> Identity:
        return await self._links.run(self.driver.connect())

    async def close(self) -> None:
        await self._links.run(self.driver.close())

    async def poll_forever(self) -> None:
        await self._links.run(self._side.poll_forever())

    async def poll_now(self) -> Polled | None:
        return await self._links.run(self._side.poll_now())

    async def act(self, action: str, params: dict[str, Any]) -> dict[str, Any]:
        return await self._links.run(self.driver.act(action, params))

    async def act_then_poll(self, action: str, params: dict[str, Any]) -> tuple[dict[str, Any], Polled | None]:
        return await self._links.run(self._side.act_then_poll(action, params))

    async def run_job(self, path: Path | None, job_type: str, params: dict[str, Any]) -> str:
        return await self._links.run(self.driver.run_job(path, job_type, _Handle(self._links.home, self._owner),
                                                         params))

    async def stop_job(self) -> None:
        await self._links.run(self.driver.stop_job())

    async def check_upload(self, name: str, path: Path) -> None:
        await check_within(self.driver.check_upload, name, path, name=name)

    async def describe_upload(self, name: str, path: Path, *, check: bool) -> dict[str, Any]:
        return await check_within(partial(self.driver.describe_upload, check=check), name, path, name=name)

    def release(self) -> None:
        links = self._links
        links.users -= 1
        if links.users <= 0:
            links.close()
            links.on_empty()


class _Handle:
    """The JobHandle a driver reports through, from the links' loop: each report runs on the agent's loop."""

    def __init__(self, home: asyncio.AbstractEventLoop, owner: LinkOwner) -> None:
        self._home = home
        self._owner = owner

    def progress(self, percent: float, *, time_left_s: float | None = None, message: str | None = None) -> None:
        self._home.call_soon_threadsafe(self._owner.job_progress, percent, time_left_s, message)

    def stroke(self, points: list[tuple[float, float]]) -> None:
        self._home.call_soon_threadsafe(self._owner.job_stroke, points)

    def preview(self, strokes: list[list[tuple[float, float]]]) -> None:
        self._home.call_soon_threadsafe(self._owner.job_preview, strokes)

    def note(self, text: str) -> None:
        self._home.call_soon_threadsafe(self._owner.job_note, text)
