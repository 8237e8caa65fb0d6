"""Drawing a vpype document's passes on a Line-us: one plan per layer, the arm parked at home for a pen change
between layers, a progress bar, and progress saved after every stroke so an interrupted drawing resumes where it
stopped (`lineus-draw --resume`)."""

from __future__ import annotations

import asyncio
import sys
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from fabwire.cli_support import DeviceContext
from fabwire.errors import InputError, LinkError
from fabwire.lineus.draw_cli import DrawProgress, send_plan, state_dir
from fabwire.lineus.plot import Plan
from fabwire.vpype.passes import PassPlan

PEN_CHANGE: list[list[float]] = []
"""In the saved progress, an empty stroke marks where one pass ends and the next pen goes in."""

PenChange = Callable[[int, str], Awaitable[None]]
"""Called with the arm parked before pass `index` (labelled) starts; returns when the new pen is in."""


def flatten(plans: Sequence[PassPlan]) -> list[list[list[float]]]:
    """The passes' strokes in drawing order with a pen-change mark between passes (what the progress file keeps)."""
    out: list[list[list[float]]] = []
    for index, one in enumerate(plans):
        if index:
            out.append(PEN_CHANGE)
        out.extend(np.round(stroke, 3).tolist() for stroke in one.plan.strokes)
    return out


def unflatten(strokes: Sequence[list[list[float]]]) -> list[Plan]:
    """The per-pass plans a progress file describes (the inverse of `flatten`)."""
    passes: list[list[list[list[float]]]] = [[]]
    for stroke in strokes:
        if stroke == PEN_CHANGE:
            passes.append([])
        else:
            passes[-1].append(stroke)
    return [Plan(tuple(np.asarray(s, dtype=float).reshape(-1, 2) for s in one)) for one in passes]


async def ask_on_stdin(index: int, label: str) -> None:
    """Prompt on stderr and wait for Enter on standard input; InputError when nobody can answer (EOF)."""
    print(f"pen change: put in the pen for {label}, then press Enter", file=sys.stderr, flush=True)
    answer = await asyncio.to_thread(sys.stdin.readline)
    if not answer:
        raise InputError(f"no answer on standard input for the pen change before {label}; "
                         "use --no-pause to draw every layer with one pen")


@dataclass
class DrawResult:
    strokes: int
    drawn: int
    resumed_at: int
    elapsed_seconds: float


async def _run(dctx: DeviceContext, plans: list[Plan], labels: list[str], progress: DrawProgress,
               pen_z: float, pen_change: PenChange | None) -> None:
    from fabwire.lineus.client import LineUs
    from fabwire.lineus.drawing_lock import drawing_alone

    seconds = [t for plan in plans for t in [0.0, *plan.stroke_seconds()]][1:]  # a pen change costs no estimate
    weights = [max(1, round(t * 1000)) for t in seconds]
    async with dctx.open(LineUs) as arm, drawing_alone(arm, f"a vpype document ({len(plans)} layer(s))") as lock:
        with Progress(TextColumn("[progress.description]{task.description}"), BarColumn(),
                      TextColumn("{task.percentage:>3.0f}%"), TimeRemainingColumn(),
                      console=dctx.output.err) as bar:
            task = bar.add_task("drawing", total=sum(weights), completed=sum(weights[: progress.done]))
            flat = 0
            for index, plan in enumerate(plans):
                if index:
                    if progress.done <= flat:
                        await arm.home()
                        if pen_change is not None:
                            bar.stop()
                            await pen_change(index, labels[index])
                            bar.start()
                        progress.done = flat + 1
                        progress.save()
                    flat += 1
                first = flat

                def done(stroke: int, first: int = first, label: str = labels[index],
                         count: int = len(plan.strokes)) -> None:
                    progress.done = first + stroke + 1
                    progress.save()
                    bar.update(task, completed=sum(weights[: progress.done]),
                               description=f"{label}: stroke {stroke + 1}/{count}")
                    lock.update(100.0 * sum(weights[: progress.done]) / max(1, sum(weights)),
                                f"{label}: stroke {stroke + 1} of {count}")

                def reached(stroke: int, vertex: int, first: int = first, label: str = labels[index],
                            count: int = len(plan.strokes), strokes: tuple[Any, ...] = plan.strokes) -> None:
                    """Within a stroke, the bar moves with each vertex the arm reports reaching."""
                    at = first + stroke
                    share = vertex / max(1, len(strokes[stroke]) - 1)
                    bar.update(task, completed=sum(weights[:at]) + min(1.0, share) * weights[at],
                               description=f"{label}: stroke {stroke + 1}/{count}")

                start = max(0, progress.done - first)
                if start < len(plan.strokes):
                    # the new layer's name at once, not after its first stroke
                    bar.update(task, description=f"{labels[index]}: stroke {start + 1}/{len(plan.strokes)}")
                    await send_plan(arm, plan, start=start, pen_z=pen_z, on_stroke=done, on_point=reached)
                flat += len(plan.strokes)
        await arm.home()


def draw_passes(dctx: DeviceContext, plans: Sequence[PassPlan], key: str, *, state: Path | None, resume: bool,
                pen_z: float, pen_change: PenChange | None) -> DrawResult:
    """Draw the passes (or, with `resume`, what a saved progress for the same `key` has left) and clear the
    progress when done. Raises LinkError/TimeoutError after saving the progress, InputError for a damaged or
    foreign progress file."""
    path = state or state_dir() / f"vpype-{key[:24]}.json"
    progress = DrawProgress.load(path, key) if resume else None
    if resume and progress is None:
        raise InputError(f"nothing to resume: there is no progress file {path} for this document with these layers "
                         "and options; run lineus-draw without --resume to draw it from the beginning")
    if progress is None:
        progress = DrawProgress(path, key, flatten(plans))
        progress.save()
    elif progress.done:
        dctx.output.note(f"resuming at step {progress.done + 1} of {len(progress.strokes)}")
    labels = [one.layer.label for one in plans]
    passes = unflatten(progress.strokes)
    if len(passes) != len(labels):
        raise InputError(f"resume state {path} has {len(passes)} layers, the document {len(labels)}")
    first = progress.done
    began = time.monotonic()
    try:
        asyncio.run(_run(dctx, passes, labels, progress, pen_z, pen_change))
    except (KeyboardInterrupt, LinkError, TimeoutError, InputError):
        if progress.done:
            dctx.output.note(f"stopped at step {progress.done} of {len(progress.strokes)}; "
                             "run the same pipeline with lineus-draw --resume to continue")
        elif first == 0:
            progress.clear()
        raise
    progress.clear()
    total = sum(len(plan.strokes) for plan in passes)
    drawn_before = sum(1 for s in progress.strokes[:first] if s != PEN_CHANGE)
    return DrawResult(total, total - drawn_before, drawn_before, time.monotonic() - began)
