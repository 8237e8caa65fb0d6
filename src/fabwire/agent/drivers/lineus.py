"""A Line-us under the agent: its position each second while idle, and drawings sent stroke by stroke."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

from fabwire.agent.drivers.base import Action, Driver, Identity, JobHandle, JobStopped, Param, summary
from fabwire.agent.opening import open_lineus
from fabwire.errors import DeviceBusy, InputError, LinkClosed
from fabwire.lineus.client import LineUs, Position
from fabwire.lineus.draw_cli import send_plan
from fabwire.lineus.plot import Plan, PlanOptions
from fabwire.lineus.plot.intake import drawing_from_bytes
from fabwire.lineus.plot.plan import plan_drawing, plan_file, plan_text

PLAN_TIME_BUDGET = 0.3
"""Seconds the stroke ordering may take (the agent plans while it keeps polling other machines)."""


def _points(stroke: Any) -> list[tuple[float, float]]:
    return [(round(float(x), 1), round(float(y), 1)) for x, y in stroke.tolist()]


class LineUsDriver(Driver):
    kind = "lineus"
    interval_s = 1.0
    actions = (
        Action("home", "Lift the pen and go home."),
        Action("pen_up", "Lift the pen."),
        Action("pen_down", "Lower the pen."),
        Action("move", "Move to a point (Line-us units, pen as it is).",
               (Param("x", "float", "x in Line-us units", -2000, 3000), Param("y", "float", "y", -2000, 3000))),
        Action("text", "Write text in a single-stroke font (runs as a job).",
               (Param("text", "str", "the words to write"),), job=True),
    )
    job_types: ClassVar[Mapping[str, str]] = dict.fromkeys((".svg", ".svgz", ".gcode", ".gc", ".nc", ".ngc"), "draw")

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.arm: LineUs | None = None
        self.position: Position | None = None
        self.drawing: str | None = None
        """Words for the drawing in progress: while it runs, polls read no position (the moves report it)."""
        self._progress: tuple[float, float | None] = (0.0, None)
        self._stop = False

    def _client(self) -> LineUs:
        if self.arm is None:
            raise LinkClosed("the Line-us is not connected")
        return self.arm

    async def connect(self) -> Identity:
        self.arm = await open_lineus(self.spec.address, self.spec.options)
        hello = self.arm.hello
        self.position = await self.arm.position()
        return Identity("Line-us", hello.serial or None, hello.version or None)

    def _summary(self) -> dict[str, Any]:
        pos = self.position
        where = {"x": pos.x, "y": pos.y, "z": pos.z} if pos else None
        if self.drawing:
            percent, left = self._progress
            return summary(state="drawing", state_text=self.drawing, busy=True, progress_percent=round(percent, 1),
                           time_left_s=left, position=where, pen_down=pos.pen_down if pos else None, actions=[])
        return summary(state="idle", state_text="idle", position=where, pen_down=pos.pen_down if pos else None,
                       actions=[a.name for a in self.actions])

    async def poll(self) -> tuple[dict[str, Any] | None, dict[str, Any]]:
        if not self.drawing:
            self.position = await self._client().position()
        pos = self.position
        status = pos.as_dict() if pos else None  # the shape `fabwire lineus position --json` prints
        return status, self._summary()

    async def close(self) -> None:
        arm, self.arm = self.arm, None
        if arm is not None:
            await arm.close()

    async def act(self, action: str, params: dict[str, Any]) -> dict[str, Any]:
        arm = self._client()
        if self.drawing:
            raise DeviceBusy(f"the Line-us is busy ({self.drawing}): cancel the job first")
        if action == "home":
            self.position = await arm.home()
        elif action == "pen_up":
            self.position = await arm.pen_up()
        elif action == "pen_down":
            self.position = await arm.pen_down()
        elif action == "move":
            self.position = await arm.move(params["x"], params["y"])
        pos = self.position
        return {"ok": True, "action": action, "position": pos.as_dict() if pos else None}

    def check_upload(self, name: str, path: Path) -> None:
        """The drawing intake's and the planner's refusal (not SVG, unreadable, nothing to draw, coordinates no
        arm can reach) before the upload is accepted, as `lineus draw` checks a file."""
        try:
            plan_drawing(drawing_from_bytes(name, path.read_bytes()), PlanOptions(optimize=False))
        except InputError as exc:
            message = str(exc)
            raise InputError(message if name in message else f"{name}: {message}") from None

    async def run_job(self, path: Path | None, job_type: str, handle: JobHandle, params: dict[str, Any]) -> str:
        arm = self._client()
        if self.drawing:
            raise DeviceBusy(f"the Line-us is busy ({self.drawing})")
        options = PlanOptions(time_budget=PLAN_TIME_BUDGET)
        if job_type == "text":
            plan: Plan = await asyncio.to_thread(plan_text, params["text"], options)
        elif path is not None:
            plan = await asyncio.to_thread(plan_file, path, options)
        else:
            raise InputError("a drawing job needs a file")
        strokes = plan.strokes
        handle.preview([_points(s) for s in strokes])
        per_stroke = plan.stroke_seconds()
        total = sum(per_stroke) or 1.0
        done_s = 0.0
        began = time.monotonic()
        self.drawing = f"drawing: stroke 1 of {len(strokes)}"
        self._progress = (0.0, total)

        def drawn(index: int) -> None:
            nonlocal done_s
            done_s += per_stroke[index]
            last = strokes[index][-1]
            self.position = Position(float(last[0]), float(last[1]), 1000.0)
            self.drawing = f"drawing: stroke {min(index + 2, len(strokes))} of {len(strokes)}"
            self._progress = (100.0 * done_s / total, max(0.0, total - done_s))
            handle.stroke(_points(strokes[index]))
            handle.progress(self._progress[0], time_left_s=self._progress[1],
                            message=f"stroke {index + 1} of {len(strokes)}")
            if self._stop:
                raise JobStopped(f"stopped after stroke {index + 1} of {len(strokes)}")

        self._stop = False
        try:
            await send_plan(arm, plan, on_stroke=drawn)
            self.position = await arm.home()
        except JobStopped:
            self.position = await arm.pen_up()
            raise
        finally:
            self.drawing = None
        return f"drew {len(strokes)} strokes in {time.monotonic() - began:.0f} s"

    async def stop_job(self) -> None:
        """Stop after the stroke being drawn (a move in flight cannot be called back) and lift the pen."""
        self._stop = True
