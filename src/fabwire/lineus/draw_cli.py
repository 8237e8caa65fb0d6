"""`fabwire lineus draw | text | preview`: plan a drawing, show it, estimate it, and draw it stroke by stroke
with progress that survives an interruption (`--resume`)."""

from __future__ import annotations

import asyncio
import hashlib
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click
import numpy as np
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from fabwire import units
from fabwire.cli_support import App, DeviceContext, FiniteRange, pass_app, pass_device
from fabwire.console import Output
from fabwire.errors import InputError, LinkError
from fabwire.files import same_file
from fabwire.lineus.draw_options import PEN_Z
from fabwire.lineus.kinematics import UNITS_PER_MM
from fabwire.lineus.plot import (
    MoveTo,
    PenDown,
    PenUp,
    Plan,
    PlanOptions,
    plan_drawing,
    plan_file,
    plan_text,
    read_drawing,
)
from fabwire.lineus.plot.intake import STDIN
from fabwire.lineus.plot.optimize import MAX_TIME_BUDGET_S
from fabwire.lineus.plot.svgtext import TEXT_MODES
from fabwire.lineus.plot.text import DEFAULT_FONT
from fabwire.lineus.render import DEFAULT_DPI, PICTURE_SUFFIXES, dpi_scale, picture_suffix_problem, write_drawing

if TYPE_CHECKING:
    from fabwire.lineus.client import LineUs

F = TypeVar("F", bound=Callable[..., Any])
STATE_VERSION = 1

MAX_TEXT = 65536
"""Characters of text read from standard input at most (a page of text is a few thousand)."""


def _rotation(ctx: click.Context, param: click.Parameter, value: str) -> float | None:
    """--rotate: degrees, or 'auto' (given to the command as None)."""
    if value.strip().lower() == "auto":
        return None
    try:
        degrees = float(value)
    except ValueError:
        raise click.BadParameter(f"{value!r} is neither a number of degrees nor 'auto'") from None
    if not math.isfinite(degrees):
        raise click.BadParameter(f"{value!r} is not a finite number of degrees")
    return degrees


DPI = click.option("--dpi", type=FiniteRange(10, 1200), default=DEFAULT_DPI, show_default=True,
                   help="Resolution of PNG pictures, dots per inch of paper.")


def placement_options(func: F) -> F:
    """Options shared by every command that plans a drawing."""
    options = [
        click.option("--fit/--no-fit", "fit", default=None,
                     help="Scale and centre into the drawing area (default: yes for SVG and text, no for G-code)."),
        click.option("--margin", type=FiniteRange(min=0), default=2.0, show_default=True,
                     help="Empty border when fitting, mm."),
        click.option("--rotate", default="0", show_default=True, callback=_rotation, metavar="DEGREES|auto",
                     help="Rotate the drawing by DEGREES counter-clockwise before placing it; 'auto' turns it by 90 "
                          "when that lets it be larger."),
        click.option("--full-area", is_flag=True,
                     help="Fit into the whole reachable area instead of the official app's drawing area."),
        click.option("--clip", is_flag=True, help="Without --fit: leave out lines outside the area instead of "
                                                  "refusing the drawing."),
        click.option("--no-optimize", "no_optimize", is_flag=True,
                     help="Keep the file's own line order and directions."),
        click.option("--optimize-time", type=FiniteRange(0.0, MAX_TIME_BUDGET_S), default=1.0, show_default=True,
                     help="Work the ordering may spend improving pen-up travel, in nominal CPU seconds (counted, "
                          "not timed: the same plan on any machine)."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


RESTART = click.option("--restart", is_flag=True,
                       help="Draw from the beginning, even when an earlier run finished or stopped part way.")


def _one_start(resume: bool, restart: bool) -> None:
    if resume and restart:
        raise InputError("--resume and --restart exclude each other: carry on, or start over")


SVG_TEXT = click.option("--svg-text", type=click.Choice(TEXT_MODES), default=TEXT_MODES[0], show_default=True,
                        expose_value=False, callback=lambda ctx, _, value: ctx.meta.__setitem__("svg_text", value),
                        help="SVG <text>: draw it in single-stroke letters, or leave it out (outline: convert text "
                             "to paths first).")


def _options(fit: bool | None, margin: float, rotate: float | None, clip: bool, no_optimize: bool,
             optimize_time: float, full_area: bool = False) -> PlanOptions:
    svg_text = click.get_current_context().meta.get("svg_text", TEXT_MODES[0])
    return PlanOptions(fit=fit, margin_mm=margin, rotate_deg=rotate or 0.0, rotate_auto=rotate is None, clip=clip,
                       optimize=not no_optimize, time_budget=optimize_time, full_area=full_area, svg_text=svg_text)


def figures_text(plan: Plan) -> str:
    f = plan.figures()
    lines = [
        f"strokes {f.strokes}, segments {f.segments}, pen lifts {f.pen_lifts}",
        f"pen down {f.pen_down_length / UNITS_PER_MM:.0f} mm, pen-up travel {f.pen_up_travel / UNITS_PER_MM:.0f} mm",
        f"estimated drawing time {units.duration(f.estimated_seconds)}",
    ]
    return "\n".join(lines)


def _figures(plan: Plan, resumed: DrawProgress | None) -> str:
    """The figures said before drawing: of what is left when a drawing resumes, else of the whole plan."""
    return figures_text(resumed.remaining()) if resumed is not None and not resumed.complete else figures_text(plan)


def _report(output: Output, plan: Plan, extra: dict[str, Any] | None = None, written: tuple[Path, ...] = ()) -> None:
    """The plan's notes and figures, and a line for each file `written`; JSON carries the notes too."""
    for note in plan.notes:
        output.note(note)
    data = {**plan.figures().as_dict(), "notes": list(plan.notes), **(extra or {})}
    output.result(data, "\n".join([figures_text(plan), *(f"wrote {path}" for path in written)]))


# -- resume state ---------------------------------------------------------------------------------------------------


def state_dir() -> Path:
    from fabwire.config import state_path

    return state_path() / "lineus"


@dataclass
class DrawProgress:
    """Where a drawing got to: the planned strokes (so a resume draws exactly the same plan), how many are done,
    and in the stroke after them the last vertex the Line-us acknowledged reaching with the pen down."""

    path: Path
    key: str
    strokes: list[list[list[float]]]
    done: int = 0
    point: int = 0
    source: str = ""
    """Digest of what is drawn (the file's bytes, the text)."""
    choices: dict[str, str] = field(default_factory=dict)
    """The planning options it was drawn with, as the command line gives them (`{"--margin": "2"}`)."""

    @property
    def complete(self) -> bool:
        return self.done >= len(self.strokes)

    def remaining(self) -> Plan:
        """What is left to draw, as a plan (the interrupted stroke from its last acknowledged vertex)."""
        rest = [np.asarray(s, dtype=float).reshape(-1, 2) for s in self.strokes[self.done :]]
        if rest and self.point:
            rest[0] = rest[0][self.point :]
        return Plan(tuple(rest))

    def reached(self, stroke: int, point: int) -> None:
        self.done, self.point = stroke, point

    def save(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(self.path.name + ".tmp")
        tmp.write_text(json.dumps({"version": STATE_VERSION, "key": self.key, "done": self.done, "point": self.point,
                                   "source": self.source, "choices": self.choices, "strokes": self.strokes}),
                       encoding="utf-8")
        tmp.replace(self.path)

    def clear(self) -> None:
        self.path.unlink(missing_ok=True)

    @classmethod
    def load(cls, path: Path, key: str | None) -> DrawProgress | None:
        """The progress saved in `path` (None if there is none); InputError when it is unreadable, damaged, or
        (with a `key`) for another drawing or other options."""
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return None
        except (OSError, ValueError) as exc:
            raise InputError(f"resume state {path} is unreadable ({exc}); delete it to start over") from exc
        if not isinstance(data, dict) or data.get("version") != STATE_VERSION:
            raise InputError(f"resume state {path} is not a drawing progress file; delete it to start over")
        if key is not None and data.get("key") != key:
            raise InputError(f"resume state {path} belongs to a different drawing or different options")
        strokes = data.get("strokes")
        done = data.get("done")
        point = data.get("point", 0)
        if (not isinstance(strokes, list) or not isinstance(done, int) or not 0 <= done <= len(strokes)
                or not isinstance(point, int) or point < 0
                or (point and (done >= len(strokes) or not isinstance(strokes[done], list)
                               or point >= len(strokes[done])))):
            raise InputError(f"resume state {path} is damaged; delete it to start over")
        source, choices = data.get("source", ""), data.get("choices", {})
        if not isinstance(source, str) or not isinstance(choices, dict):
            raise InputError(f"resume state {path} is damaged; delete it to start over")
        return cls(path, str(data.get("key", "")), strokes, done, point, source,
                   {str(k): str(v) for k, v in choices.items()})


def plan_choices(options: PlanOptions, **extra: str) -> dict[str, str]:
    """The options that shape a plan, as the command line spells them, for naming what a resume would change."""
    def flag(on: bool) -> str:
        return "on" if on else "off"

    return {"--fit": "default" if options.fit is None else flag(options.fit), "--margin": f"{options.margin_mm:g}",
            "--rotate": "auto" if options.rotate_auto else f"{options.rotate_deg:g}",
            "--full-area": flag(options.full_area), "--clip": flag(options.clip),
            "--no-optimize": flag(not options.optimize), "--svg-text": options.svg_text, **extra}


def resumable(path: Path, source: str, choices: dict[str, str], name: str) -> DrawProgress:
    """The progress `--resume` carries on from: the one in `path`, for the same drawing planned with the same
    options. Otherwise InputError naming what differs and pointing to --restart: a resume never starts over."""
    restart = "or --restart to draw it from the beginning"
    progress = DrawProgress.load(path, None)
    if progress is None:
        raise InputError(f"nothing to resume for {name}: there is no progress file {path}; use --restart to draw "
                         "it from the beginning")
    if progress.source and progress.source != source:
        raise InputError(f"cannot resume {name}: the progress file {path} is for another drawing; give the file "
                         f"it was for, {restart}")
    changed = [f"{option} {progress.choices.get(option, '(not recorded)')} (now {value})"
               for option, value in choices.items() if progress.choices.get(option) != value]
    if changed:
        raise InputError(f"cannot resume {name}: it was planned with {'; '.join(changed)}; give the same options "
                         f"to carry on, {restart}")
    return progress


def progress_path(state: Path | None, source: str) -> Path:
    """The progress file: `--state`, or one per drawing (whatever its options) in the user's state directory."""
    return state or state_dir() / f"draw-{source[:24]}.json"


def _plan_from_state(progress: DrawProgress) -> Plan:
    strokes = tuple(np.asarray(s, dtype=float).reshape(-1, 2) for s in progress.strokes)
    return Plan(strokes)


# -- drawing --------------------------------------------------------------------------------------------------------


async def send_plan(arm: LineUs, plan: Plan, *, start: int = 0, point: int = 0, pen_z: float = 0.0,
                    on_stroke: Callable[[int], None] | None = None,
                    on_point: Callable[[int, int], None] | None = None) -> None:
    """Draw the plan's strokes from `start` on (that one from its vertex `point`): lift, travel, drop (to
    `pen_z`), draw, lift. `on_point(stroke, vertex)` after each acknowledged vertex with the pen down,
    `on_stroke(i)` after each stroke."""
    lifted = await arm.pen_up()
    here = (lifted.x, lifted.y)
    for index in range(start, len(plan.strokes)):
        vertex = point if index == start else 0
        down = False
        for move in plan.stroke_moves(index, from_point=vertex, here=here):
            if isinstance(move, MoveTo):
                reached = await arm.move(move.x, move.y)
                here = (reached.x, reached.y)
                if down:
                    vertex += 1
                    if on_point is not None:
                        on_point(index, vertex)
            elif isinstance(move, PenDown):
                await arm.pen_down(pen_z)
                down = True
            elif isinstance(move, PenUp):
                await arm.pen_up()
                down = False
        if on_stroke is not None:
            on_stroke(index)


async def _send(dctx: DeviceContext, plan: Plan, progress: DrawProgress, pen_z: float,
                what: str, told: list[str]) -> tuple[int, float]:
    """Draw alone on the robot (`DrawingLock`), saving progress per stroke; an interrupt lifts the pen before the
    connection closes."""
    from fabwire.lineus.client import LineUs
    from fabwire.lineus.drawing_lock import drawing_alone

    per_stroke = plan.stroke_seconds()
    weights = [max(1, round(t * 1000)) for t in per_stroke]  # the bar advances by estimated milliseconds
    total = len(plan.strokes)
    began = time.monotonic()
    async with dctx.open(LineUs) as arm, drawing_alone(arm, what) as lock:
        for note in told:
            dctx.output.note(note)
        with Progress(
            TextColumn("[progress.description]{task.description}"),
            BarColumn(),
            TextColumn("{task.percentage:>3.0f}%"),
            TimeRemainingColumn(),
            console=dctx.output.err,
            disable=dctx.output.json_mode,
        ) as bar:
            estimate = sum(per_stroke[progress.done :], 0.0)
            all_weight = sum(weights)
            task = bar.add_task(f"drawing (estimate {estimate:.0f} s)", total=all_weight,
                                completed=sum(weights[: progress.done]))
            lock.update(100.0 * sum(weights[: progress.done]) / all_weight, f"stroke {progress.done + 1} of {total}")

            def done(index: int) -> None:
                progress.reached(index + 1, 0)
                progress.save()
                bar.update(task, advance=weights[index], description=f"stroke {index + 1}/{total}")
                lock.update(100.0 * sum(weights[: index + 1]) / all_weight,
                            f"stroke {min(index + 2, total)} of {total}")

            await send_plan(arm, plan, start=progress.done, point=progress.point, pen_z=pen_z, on_stroke=done,
                            on_point=progress.reached)
        await arm.home()
    return total, time.monotonic() - began


def _draw(dctx: DeviceContext, plan: Plan, existing: DrawProgress | None, path: Path, source: str,
          choices: dict[str, str], what: dict[str, str], pen_z: float, told: list[str]) -> None:
    """Draw `plan` (or carry on with `existing` progress), saving progress in `path` for --resume; `what` names
    what is drawn in the JSON result: {"file": path} or {"text": text}; `told` (the planner's notes and figures)
    is said once the robot is this command's, so a refused second drawing says only who is drawing."""
    name = _name(what)
    progress = existing
    if progress is not None and progress.complete:
        dctx.output.result(
            {**what, "complete": True, "strokes": len(progress.strokes), "drawn": 0},
            f"{name} has been drawn completely already; use --restart to draw it again")
        return
    if progress is not None:
        plan = _plan_from_state(progress)
        left = progress.remaining().figures().estimated_seconds
        where = f" at its vertex {progress.point + 1}" if progress.point else ""
        dctx.output.note(f"resuming {name} at stroke {progress.done + 1} of {len(progress.strokes)}{where}; "
                         f"about {units.duration(left)} left")
    else:
        key = hashlib.sha256(json.dumps([source, choices], sort_keys=True).encode()).hexdigest()
        progress = DrawProgress(path, key, [np.round(s, 3).tolist() for s in plan.strokes], source=source,
                                choices=choices)
        plan = _plan_from_state(progress)
        progress.save()
    first = progress.done
    try:
        total, elapsed = asyncio.run(_send(dctx, plan, progress, pen_z, name, told))
    except (KeyboardInterrupt, LinkError, TimeoutError):
        if progress.done or progress.point:
            progress.save()  # the last acknowledged vertex, so a resume carries on from exactly there
            dctx.output.note(f"stopped in stroke {progress.done + 1} of {len(plan.strokes)}; "
                             "to continue, run the same command with --resume (and without --restart)")
        elif first == 0:
            progress.clear()
        raise
    progress.save()  # complete: a --resume now says so instead of drawing over it
    figures = plan.figures()
    dctx.output.result(
        {**what, "strokes": total, "drawn": total - first, "resumed_at": first,
         "elapsed_s": round(elapsed, 2), "estimated_s": round(figures.estimated_seconds, 2)},
        f"drew {total - first} of {total} strokes in {units.duration(elapsed)}",
    )


def _name(what: dict[str, str]) -> str:
    return repr(what["text"]) if "text" in what else "standard input" if what["file"] == STDIN else what["file"]


@click.command("draw")
@click.argument("file", type=click.Path(path_type=Path, dir_okay=False, allow_dash=True))
@placement_options
@SVG_TEXT
@click.option("--dry-run", is_flag=True, help="Plan, preview and estimate only; no device needed.")
@click.option("--preview", "preview", type=click.Path(path_type=Path, dir_okay=False),
              help="Also write a picture of the plan (.svg or .png).")
@click.option("--resume", is_flag=True, help="Continue an interrupted drawing of this file where it stopped.")
@RESTART
@click.option("--state", type=click.Path(path_type=Path, dir_okay=False),
              help="Progress file (default: one per drawing in the user's state directory).")
@PEN_Z
@DPI
@pass_device
def draw(dctx: DeviceContext, file: Path, fit: bool | None, margin: float, rotate: float | None, full_area: bool,
         clip: bool, no_optimize: bool, optimize_time: float, dry_run: bool, preview: Path | None, resume: bool,
         restart: bool, state: Path | None, pen_z: float, dpi: float) -> None:
    """Draw an SVG, SVGZ or Line-us G-code FILE ('-' reads it from standard input)."""
    _one_start(resume, restart)
    options = _options(fit, margin, rotate, clip, no_optimize, optimize_time, full_area)
    drawing = read_drawing(file, svg_text=options.svg_text)
    what = {"file": str(file)}
    choices = plan_choices(options)
    path = progress_path(state, drawing.digest)
    existing = resumable(path, drawing.digest, choices, _name(what)) if resume else None
    plan = _plan_from_state(existing) if existing is not None else plan_drawing(drawing, options)
    if preview is not None:
        write_drawing(preview, plan.strokes, plan.travel(), title=Path(drawing.name).name, hidden=plan.hidden,
                      scale=dpi_scale(dpi))
    if dry_run:
        _report(dctx.output, plan, {"file": str(file)})
        return
    _draw(dctx, plan, existing, path, drawing.digest, choices, what, pen_z, [*plan.notes, _figures(plan, existing)])


@click.command("text")
@click.argument("text")
@click.option("--size", type=FiniteRange(min=0, min_open=True),
              help="Capital height in mm (default: as large as the area allows).")
@click.option("--font", default=DEFAULT_FONT, show_default=True, help="Hershey single-stroke font.")
@placement_options
@click.option("--dry-run", is_flag=True, help="Plan, preview and estimate only; no device needed.")
@click.option("--preview", "preview", type=click.Path(path_type=Path, dir_okay=False),
              help="Also write a picture of the plan (.svg or .png).")
@click.option("--resume", is_flag=True, help="Continue an interrupted drawing of this text where it stopped.")
@RESTART
@click.option("--state", type=click.Path(path_type=Path, dir_okay=False), help="Progress file.")
@PEN_Z
@DPI
@pass_device
def text(dctx: DeviceContext, text: str, size: float | None, font: str, fit: bool | None, margin: float,
         rotate: float | None, full_area: bool, clip: bool, no_optimize: bool, optimize_time: float, dry_run: bool,
         preview: Path | None, resume: bool, restart: bool, state: Path | None, pen_z: float, dpi: float) -> None:
    """Write TEXT in a single-stroke font (\\n starts a new line, \\t moves on to the next tab stop; '-' reads the
    text from standard input). Without --rotate the text runs along the long side of the area when that lets it
    be larger (as --rotate auto)."""
    _one_start(resume, restart)
    if click.get_current_context().get_parameter_source("rotate") is click.core.ParameterSource.DEFAULT:
        rotate = None  # as --rotate auto
    if text == STDIN:
        text = sys.stdin.read(MAX_TEXT + 1).rstrip("\n")
        if len(text) > MAX_TEXT:
            raise InputError(f"the text on standard input is longer than {MAX_TEXT} characters")
    text = text.replace("\\n", "\n").replace("\\t", "\t")
    options = _options(fit, margin, rotate, clip, no_optimize, optimize_time, full_area)
    what = {"text": text}
    digest = hashlib.sha256(text.encode()).hexdigest()
    choices = plan_choices(options, **{"--size": "largest" if size is None else f"{size:g}", "--font": font})
    path = progress_path(state, digest)
    existing = resumable(path, digest, choices, _name(what)) if resume else None
    plan = _plan_from_state(existing) if existing is not None else plan_text(text, options, size_mm=size, font=font)
    if preview is not None:
        write_drawing(preview, plan.strokes, plan.travel(), title=text.splitlines()[0][:60], scale=dpi_scale(dpi))
    if dry_run:
        _report(dctx.output, plan, {"text": text})
        return
    _draw(dctx, plan, existing, path, digest, choices, what, pen_z, [*plan.notes, _figures(plan, existing)])


@click.command("preview")
@click.argument("file", type=click.Path(path_type=Path, dir_okay=False, allow_dash=True))
@click.option("-o", "--output", "outputs", multiple=True, type=click.Path(path_type=Path, dir_okay=False),
              help="File to write: a picture (.svg, .png) or the plan as Line-us G-code (.gcode) for "
                   "`files save` and `draw`; repeat for several.")
@placement_options
@SVG_TEXT
@click.option("--json", "json_output", is_flag=True, help="Print the plan figures as JSON.")
@DPI
@PEN_Z
@pass_app
def preview(app: App, file: Path, outputs: tuple[Path, ...], fit: bool | None, margin: float,
            rotate: float | None, full_area: bool, clip: bool, no_optimize: bool, optimize_time: float,
            json_output: bool, dpi: float, pen_z: float) -> None:
    """Plan FILE ('-' reads standard input) and write a picture of what the pen will do (pen-up travel dashed,
    parts hidden by clip paths faint), or the plan as Line-us G-code; no device needed."""
    from fabwire.lineus.plot.export import GCODE_SUFFIXES, write_gcode

    if json_output:
        app.output.json_mode = True
    for out in outputs:  # every output is checked before the first is written
        if str(file) != "-" and same_file(out, file):
            raise InputError(f"{out} is the drawing being previewed: name another output file")
        if out.suffix.lower() not in (*PICTURE_SUFFIXES, *GCODE_SUFFIXES):
            raise InputError(f"{out}: {picture_suffix_problem(out, ' (or .gcode for the plan)')}")
        if not out.parent.is_dir():
            raise InputError(f"{out}: there is no folder {out.parent}")
    plan = plan_file(file, _options(fit, margin, rotate, clip, no_optimize, optimize_time, full_area))
    for done, out in enumerate(outputs):
        try:
            if out.suffix.lower() in GCODE_SUFFIXES:
                write_gcode(out, plan, pen_z=pen_z)
            else:
                write_drawing(out, plan.strokes, plan.travel(),
                              title="standard input" if str(file) == "-" else file.name, hidden=plan.hidden,
                              scale=dpi_scale(dpi))
        except InputError:
            for path in outputs[:done]:  # what is on disk already is said, so nothing is left unexplained
                app.output.note(f"wrote {path}")
            raise
    _report(app.output, plan, {"file": str(file), "outputs": [str(o) for o in outputs]}, written=outputs)
