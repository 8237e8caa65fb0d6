"""A Line-us under the agent: its position each second while idle, and drawings sent stroke by stroke."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any, ClassVar

from fabwire.agent.drivers.base import Action, Driver, Identity, JobHandle, JobStopped, Param, summary
from fabwire.agent.offload import WorkCancelled, check_cancelled, in_thread
from fabwire.agent.opening import open_lineus
from fabwire.errors import DeviceBusy, InputError, LinkClosed
from fabwire.lineus.client import LineUs, Position
from fabwire.lineus.draw_cli import send_plan
from fabwire.lineus.drawing_lock import Drawer, DrawingLock, current_drawer, drawing_alone, robot_address
from fabwire.lineus.plot import Plan, PlanOptions
from fabwire.lineus.plot.intake import drawing_from_bytes, read_drawing
from fabwire.lineus.plot.plan import plan_drawing, plan_text
from fabwire.lineus.render import picture_png

PLAN_TIME_BUDGET = 0.3
"""Seconds the stroke ordering may take (the agent plans while it keeps polling other machines)."""


def _plan_file(path: Path, options: PlanOptions) -> Plan:
    """`plan_file` in two stages, stopping between them once cancelled (see `fabwire.agent.offload`)."""
    drawing = read_drawing(path, svg_text=options.svg_text)
    check_cancelled()
    return plan_drawing(drawing, options)


def _plan_upload(name: str, path: Path, options: PlanOptions) -> Plan:
    """An uploaded drawing planned as `lineus draw` plans a file, stopping between the stages once cancelled;
    refusals (InputError) name the upload."""
    try:
        drawing = drawing_from_bytes(name, path.read_bytes())
        check_cancelled()
        return plan_drawing(drawing, options)
    except InputError as exc:
        message = str(exc)
        raise InputError(message if name in message else f"{name}: {message}") from None


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
        Action("pen_height", "Set the pen height, 0 (down on the paper) to 1000 (up).",
               (Param("z", "float", "pen height, 0 down … 1000 up", 0, 1000),)),
        Action("list_drawings", "List the drawings stored on the machine (M20)."),
        Action("delete_drawing", "Delete a stored drawing (M30).",
               (Param("slot", "int", "stored drawing 1 to 32", 1, 32),), confirm=True),
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
        self._planning: threading.Event | None = None

    def _client(self) -> LineUs:
        if self.arm is None:
            raise LinkClosed("the Line-us is not connected")
        return self.arm

    async def connect(self) -> Identity:
        self.arm = await open_lineus(self.spec.address, self.spec.options)
        hello = self.arm.hello
        self.position = await self.arm.position()
        return Identity("Line-us", hello.serial or None, hello.version or None)

    def _other_drawer(self) -> Drawer | None:
        """Another program drawing on this robot (a `fabwire lineus draw` on this host), if any."""
        if self.arm is None:
            return None
        drawer = current_drawer(robot_address(self.arm.transport))
        return drawer if drawer is not None and drawer.pid != os.getpid() else None

    def _summary(self) -> dict[str, Any]:
        pos = self.position
        where = {"x": pos.x, "y": pos.y, "z": pos.z} if pos else None
        other = None if self.drawing else self._other_drawer()
        if other is not None:
            return summary(state="drawing", state_text=f"drawing from another program: {other.words()}", busy=True,
                           progress_percent=other.progress_percent, position=where,
                           pen_down=pos.pen_down if pos else None, actions=[])
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
        if action == "list_drawings":  # reads the robot's files: no motion, no lock
            drawings = await arm.list_drawings()
            return {"ok": True, "action": action,
                    "drawings": [{"slot": d.slot, "size_bytes": d.size, "path": d.path} for d in drawings]}
        if (other := self._other_drawer()) is not None:
            raise DeviceBusy(f"the Line-us is drawing for another program: {other.words()}")
        # held for the move itself, so no drawing starts on the robot in the middle of it
        with DrawingLock(robot_address(arm.transport), f"the action {action!r}",
                         command=f"fabwire serve ({self.spec.name})"):
            if action == "home":
                self.position = await arm.home()
            elif action == "pen_up":
                self.position = await arm.pen_up()
            elif action == "pen_down":
                self.position = await arm.pen_down()
            elif action == "move":
                self.position = await arm.move(params["x"], params["y"])
            elif action == "pen_height":
                self.position = await arm.move(z=params["z"])
            elif action == "delete_drawing":
                await arm.delete_drawing(params["slot"])
                return {"ok": True, "action": action, "slot": params["slot"]}
        pos = self.position
        return {"ok": True, "action": action, "position": pos.as_dict() if pos else None}

    def describe_upload(self, name: str, path: Path, *, check: bool = True) -> dict[str, Any]:
        """What a file library shows of a drawing, from the plan a job would draw (the same placement and ordering
        budget): `print_time_s` (the planner's drawing-time estimate), `pen_down_mm`, `strokes`, and `picture`
        (PNG bytes, (width, height)); refuses (InputError) what `check_upload` refuses, whatever `check` says,
        since the figures need the plan."""
        plan = _plan_upload(name, path, PlanOptions(time_budget=PLAN_TIME_BUDGET))
        figures = plan.figures().as_dict()
        return {"print_time_s": figures["estimated_s"], "pen_down_mm": figures["pen_down_length_mm"],
                "strokes": figures["strokes"], "picture": picture_png(plan.strokes)}

    def check_upload(self, name: str, path: Path) -> None:
        """The drawing intake's and the planner's refusal (not SVG, unreadable, nothing to draw, coordinates no
        arm can reach) before the upload is accepted, as `lineus draw` checks a file; run by `in_thread`, it
        stops between its stages (WorkCancelled) once the uploader is gone."""
        _plan_upload(name, path, PlanOptions(optimize=False))

    async def run_job(self, path: Path | None, job_type: str, handle: JobHandle, params: dict[str, Any]) -> str:
        arm = self._client()
        if self.drawing:
            raise DeviceBusy(f"the Line-us is busy ({self.drawing})")
        options = PlanOptions(time_budget=PLAN_TIME_BUDGET)
        self._stop = False
        self._planning = threading.Event()  # set by stop_job: the plan stops between its stages
        try:
            if job_type == "text":  # along the long side of the area, as `fabwire lineus text` writes it
                plan: Plan = await in_thread(plan_text, params["text"], replace(options, rotate_auto=True),
                                             cancel=self._planning)
            elif path is not None:
                plan = await in_thread(_plan_file, path, options, cancel=self._planning)
            else:
                raise InputError("a drawing job needs a file")
        except WorkCancelled:
            raise JobStopped("stopped while planning, before anything was drawn") from None
        finally:
            self._planning = None
        strokes = plan.strokes
        for note in plan.notes:  # what `lineus draw` prints: parts of the file left out, and why
            handle.note(note)
        handle.preview([_points(s) for s in strokes])
        notes = "; ".join(plan.notes)
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
            drawing = f"stroke {min(index + 2, len(strokes))} of {len(strokes)}"  # the one under the pen now
            self.drawing = f"drawing: {drawing}"
            self._progress = (100.0 * done_s / total, max(0.0, total - done_s))
            handle.stroke(_points(strokes[index]))
            handle.progress(self._progress[0], time_left_s=self._progress[1], message=drawing)
            if self._stop:
                raise JobStopped(f"stopped after stroke {index + 1} of {len(strokes)}")

        what = repr(params["text"]) if job_type == "text" else path.name if path is not None else "a drawing"
        try:
            async with drawing_alone(arm, what, command=f"fabwire serve ({self.spec.name})"):
                try:
                    await send_plan(arm, plan, on_stroke=drawn)
                    self.position = await arm.home()
                except JobStopped:
                    self.position = await arm.pen_up()
                    raise
        finally:
            self.drawing = None
        drew = f"drew {len(strokes)} strokes in {time.monotonic() - began:.0f} s"
        return f"{drew} (planner: {notes})" if notes else drew

    async def stop_job(self) -> None:
        """Stop planning at the end of its stage, or drawing after the stroke being drawn (a move in flight cannot
        be called back) and lift the pen."""
        self._stop = True
        if self._planning is not None:
            self._planning.set()
