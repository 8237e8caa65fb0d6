"""An asyncio event loop on a fake clock: whenever nothing is ready to run, time jumps to the next timer.

Sleeps, heartbeats and timeouts then cost no wall time, so hours of protocol time run in seconds. Only for code
whose I/O is in memory (`memory_pair`): a real socket's bytes would not arrive while the clock jumps."""

from __future__ import annotations

import asyncio
from collections.abc import Coroutine
from typing import Any, TypeVar

T = TypeVar("T")


class FakeClockLoop(asyncio.SelectorEventLoop):
    def __init__(self) -> None:
        super().__init__()
        self._fake_now = 0.0

    def time(self) -> float:
        return self._fake_now

    def _run_once(self) -> None:
        ready: Any = self._ready  # type: ignore[attr-defined]
        scheduled: Any = self._scheduled  # type: ignore[attr-defined]
        if not ready and scheduled:
            self._fake_now = max(self._fake_now, scheduled[0].when())
        super()._run_once()  # type: ignore[misc]


def run_on_fake_clock(main: Coroutine[Any, Any, T]) -> T:
    """Run `main` to its end on a fresh FakeClockLoop; its clock starts at 0."""
    loop = FakeClockLoop()
    try:
        return loop.run_until_complete(main)
    finally:
        loop.close()
