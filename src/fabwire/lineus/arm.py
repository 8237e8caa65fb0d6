"""The simulated arm: model time, one executing move with at most one waiting behind it, and the ink.

Moves take the time `kinematics.MotionModel` gives them (divided by the speed factor); what the pen leaves on the
paper is `interpreter.Ink`'s to say, so the simulator and the drawing reader agree on every mark.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import math
import time
from dataclasses import dataclass

from fabwire.lineus import kinematics as kin
from fabwire.lineus.interpreter import HOME3, Ink, Point2, Point3

log = logging.getLogger("fabwire.lineus.sim")

HISTORY = 10_000
"""Recent moves kept for instrumentation (bounded and small, so a long-running simulator reaches its size soon)."""


@dataclass(frozen=True, slots=True)
class MoveRecord:
    """One executed move, in model seconds since the simulator started."""

    command: str
    start: Point3
    end: Point3
    started: float
    finished: float
    clamped: bool


@dataclass
class Job:
    command: str
    target: Point3
    clamped: bool
    rapid: bool
    done: asyncio.Future[MoveRecord]
    queued: float = 0.0


def _loop_time() -> float:
    """The running event loop's clock (the one its timers follow), or the monotonic clock outside one."""
    try:
        return asyncio.get_running_loop().time()
    except RuntimeError:
        return time.monotonic()


class Clock:
    """Model time: the event loop's time × speed, or (at infinite speed) time advanced only by the moves themselves.

    Following the loop's clock (rather than the wall) keeps model time and the loop's timers in step, also on a
    loop whose clock is not the wall's."""

    def __init__(self, speed: float) -> None:
        self.speed = speed
        self.instant = math.isinf(speed)
        self._t0 = _loop_time()
        self._virtual = 0.0

    def now(self) -> float:
        if self.instant:
            return self._virtual
        return (_loop_time() - self._t0) * self.speed

    def advance(self, moment: float) -> None:
        """At infinite speed, move model time on without waiting."""
        self._virtual = max(self._virtual, moment)

    async def sleep(self, seconds: float) -> None:
        """Wait `seconds` of model time. Timers (unlike motion) still pass in real time at infinite speed,
        so a periodic job cannot spin."""
        await asyncio.sleep(seconds if self.instant else seconds / self.speed)

    async def run_until(self, moment: float) -> None:
        if self.instant:
            self._virtual = max(self._virtual, moment)
            await asyncio.sleep(0)
            return
        remaining = (moment - self.now()) / self.speed
        if remaining > 0:
            await asyncio.sleep(remaining)


class Arm:
    """The physical arm: one executing move and at most one waiting behind it."""

    def __init__(self, clock: Clock, model: kin.MotionModel, ink: Ink | None = None) -> None:
        self.clock = clock
        self.model = model
        self.ink = ink or Ink(lift_over_notch=True)
        self.position: Point3 = HOME3
        self.planned: Point3 = self.position
        self.moves: collections.deque[MoveRecord] = collections.deque(maxlen=HISTORY)
        self._queue: asyncio.Queue[Job] = asyncio.Queue(maxsize=1)
        self._task: asyncio.Task[None] | None = None
        self._busy_until = 0.0
        self._moving = False

    @property
    def strokes(self) -> list[list[Point2]]:
        """Pen-down polylines so far; a one-point polyline is a dot."""
        return self.ink.strokes

    @property
    def travel(self) -> list[list[Point2]]:
        return self.ink.travel

    @property
    def collisions(self) -> list[Point2]:
        """Where the pen screw hit the body (firmware 1.0.1 lets the arm into the notch)."""
        return self.ink.collisions

    @property
    def busy(self) -> bool:
        return self._queue.qsize() > 0 or self.planned != self.position

    @property
    def has_room(self) -> bool:
        """A move submitted now is taken without waiting."""
        return not self._queue.full()

    async def submit(self, command: str, target: Point3, *, clamped: bool, rapid: bool) -> Job:
        """Queue a move once there is room; the job's `done` resolves when the arm has finished it."""
        job = Job(command, target, clamped, rapid, asyncio.get_running_loop().create_future(), self.clock.now())
        if self.clock.instant and not self._moving and self._queue.empty():
            # No motion delay and nothing ahead of it: the move is over as soon as it starts.
            self.planned = target
            began = max(self.clock.now(), self._busy_until)
            finished = began + self.model.move_time(self.position, target)
            self.clock.advance(finished)
            self._complete(job, began, finished)
            return job
        if self._task is None or self._task.done():
            self._task = asyncio.create_task(self._run(), name="lineus-arm")
        await self._queue.put(job)
        self.planned = target
        return job

    async def _run(self) -> None:
        while True:
            job = await self._queue.get()
            self._moving = True
            try:
                duration = self.model.move_time(self.position, job.target)
                # A move that was waiting behind the previous one starts the instant it ends (look-ahead).
                began = self._busy_until if job.queued <= self._busy_until else self.clock.now()
                finished = began + duration
                await self.clock.run_until(finished)
                self._complete(job, began, finished)
            finally:
                self._moving = False

    def _complete(self, job: Job, began: float, finished: float) -> None:
        start = self.position
        self._busy_until = finished
        seen = len(self.ink.collisions)
        self.ink.move(start, job.target, rapid=job.rapid)
        for x, y in self.ink.collisions[seen:]:
            log.warning("lineus arm drove the pen into the body at (%.0f, %.0f) (%s)", x, y, job.command)
        self.position = job.target
        record = MoveRecord(job.command, start, job.target, began, finished, job.clamped)
        self.moves.append(record)
        if not job.done.done():
            job.done.set_result(record)

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
