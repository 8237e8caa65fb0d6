"""The vpype commands (global processors; vpype loads them from the `vpype.plugins` entry points):

    vpype read art.svg linemerge lineus-fit lineus-stat lineus-draw -d 192.168.4.1

Every command leaves the document as it found it except `lineus-fit`, which places it on the Line-us page. Errors
leave vpype as one line and fabwire's exit code (4 bad input, 8 link lost, 9 timeout).

vpype imports every plugin each time it starts, whatever the pipeline: what only drawing, previews and the text
figures need (the link, progress bars, pictures) is imported by the commands that use it.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import click
import vpype_cli

from fabwire import units
from fabwire.errors import FabwireError, InputError
from fabwire.lineus.draw_options import PEN_Z
from fabwire.lineus.kinematics import UNITS_PER_MM
from fabwire.lineus.plot import PlanOptions
from fabwire.lineus.plot.optimize import MAX_TIME_BUDGET_S
from fabwire.vpype.passes import (
    PassPlan,
    document_passes,
    fit_document,
    passes_key,
    plan_gcode,
    plan_passes,
    total_figures,
)

F = TypeVar("F", bound=Callable[..., Any])
HELP_GROUP = "Line-us (fabwire)"
EXIT_LINK = 8
EXIT_TIMEOUT = 9


class FabwireFailure(click.ClickException):
    """A fabwire error inside a vpype pipeline: one line, and fabwire's own exit code."""

    def __init__(self, message: str, exit_code: int) -> None:
        super().__init__(message)
        self.exit_code = exit_code  # type: ignore[misc]  # click reads it per instance


@contextlib.contextmanager
def fabwire_errors() -> Iterator[None]:
    """Turn fabwire's errors into click's, which vpype prints as one line and exits with."""
    try:
        yield
    except FabwireError as exc:
        raise FabwireFailure(str(exc), exc.exit_code) from None
    except TimeoutError as exc:
        raise FabwireFailure(f"timed out: {exc or 'the device did not answer'}", EXIT_TIMEOUT) from None
    except ConnectionError as exc:
        raise FabwireFailure(f"link failed: {exc}", EXIT_LINK) from None


def processor(name: str) -> Callable[[Callable[..., Any]], click.Command]:
    """Make a function taking and returning a vpype Document into the vpype command `name`."""

    def decorate(func: Callable[..., Any]) -> click.Command:
        command = click.command(name=name)(vpype_cli.global_processor(func))
        command.help_group = HELP_GROUP  # type: ignore[attr-defined]
        return command

    return decorate


def _layer_option(func: F) -> F:
    option = click.option("-l", "--layer", type=vpype_cli.LayerType(accept_multiple=True), default="all",
                          help="Layer(s) to plan (default: all), each a drawing pass.")
    return option(func)


def plan_options(func: F) -> F:
    """Options shared by every command that plans the document as placed."""
    options = [
        click.option("--clip", is_flag=True, help="Leave out lines outside the area instead of refusing them."),
        click.option("--no-optimize", "no_optimize", is_flag=True,
                     help="Keep vpype's line order and directions (as after linesort)."),
        click.option("--optimize-time", type=click.FloatRange(0.0, MAX_TIME_BUDGET_S), default=None,
                     help="Work per layer the ordering may spend improving pen-up travel, in nominal CPU seconds "
                          "(counted, not timed: the same plan on any machine). Default: in proportion to the "
                          "number of lines, about what linesort costs."),
        _layer_option,
    ]
    for option in reversed(options):
        func = option(func)
    return func


def _plan_options(clip: bool, no_optimize: bool, optimize_time: float | None) -> PlanOptions:
    return PlanOptions(fit=False, clip=clip, optimize=not no_optimize, time_budget=optimize_time)


def _plans(document: Any, layer: Any, options: PlanOptions) -> list[PassPlan]:
    layer_ids = vpype_cli.multiple_to_layer_ids(layer, document)
    return plan_passes(document_passes(document, layer_ids), options)


def _figures(plans: list[PassPlan]) -> dict[str, Any]:
    return {**total_figures(plans).as_dict(),
            "layers": [{"layer": one.layer.layer_id, "name": one.layer.name, **one.plan.figures().as_dict()}
                       for one in plans]}


def _print_figures(plans: list[PassPlan], as_json: bool) -> None:
    if as_json:
        click.echo(json.dumps(_figures(plans)))
        return
    from fabwire.lineus.draw_cli import figures_text

    for one in plans:
        click.echo(f"{one.layer.label}:")
        click.echo("  " + figures_text(one.plan).replace("\n", "\n  "))
    if len(plans) > 1:
        f = total_figures(plans)
        click.echo(f"all {len(plans)} layers: pen down {f.pen_down_length / UNITS_PER_MM:.0f} mm, pen-up travel "
                   f"{f.pen_up_travel / UNITS_PER_MM:.0f} mm, {f.pen_lifts} pen lifts, {len(plans) - 1} pen "
                   f"change(s), estimated {units.duration(f.estimated_seconds)}")


@processor("lineus-fit")
@click.option("--margin", type=click.FloatRange(min=0.0), default=2.0, show_default=True,
              help="Empty border around the drawing, mm.")
@click.option("--full-area", is_flag=True, help="Fit into the whole reachable area, not the official app's drawing "
                                                "area.")
@click.option("--no-scale", is_flag=True, help="Keep the document's size and place: only check that it can be "
                                               "reached (or, with --clip, cut away what cannot).")
@click.option("--clip", is_flag=True, help="With --no-scale: leave out lines outside the area instead of refusing.")
def lineus_fit(document: Any, margin: float, full_area: bool, no_scale: bool, clip: bool) -> Any:
    """Scale and centre the document into the Line-us drawing area.

    The official app's area by default (it becomes the page), or with --full-area the whole reachable area. All
    layers move together, keeping their proportions. The result is in Line-us page coordinates: after it,
    lineus-stat, lineus-preview, lineus-draw and lineus-gcode take the document as placed.
    """
    with fabwire_errors():
        try:
            options = PlanOptions(fit=not no_scale, margin_mm=margin, full_area=full_area, clip=clip)
            return fit_document(document, options)
        except InputError as exc:
            if not no_scale:
                raise
            raise InputError(f"{exc} (lineus-fit without --no-scale scales the document into the area)") from None


@processor("lineus-stat")
@plan_options
@click.option("--json", "as_json", is_flag=True, help="Print the figures as JSON.")
def lineus_stat(document: Any, clip: bool, no_optimize: bool, optimize_time: float | None, layer: Any,
                as_json: bool) -> Any:
    """Print the Line-us plan's figures per layer: pen-down length, pen-up travel, lifts, estimated time."""
    with fabwire_errors():
        _print_figures(_plans(document, layer, _plan_options(clip, no_optimize, optimize_time)), as_json)
    return document


@processor("lineus-preview")
@click.option("-o", "--output", "outputs", multiple=True, required=True,
              type=vpype_cli.PathType(path_type=Path, dir_okay=False),
              help="Picture to write: .svg or .png (repeat for both).")
@plan_options
@click.option("--json", "as_json", is_flag=True, help="Print the figures as JSON.")
def lineus_preview(document: Any, outputs: tuple[Path, ...], clip: bool, no_optimize: bool, optimize_time: float | None,
                   layer: Any, as_json: bool) -> Any:
    """Write a picture of what the Line-us pen will do (pen-up travel dashed) and print the plan's figures."""
    from fabwire.lineus.render import write_drawing

    with fabwire_errors():
        plans = _plans(document, layer, _plan_options(clip, no_optimize, optimize_time))
        strokes = [stroke for one in plans for stroke in one.plan.strokes]
        travel = [hop for one in plans for hop in one.plan.travel()]
        for out in outputs:
            write_drawing(out, strokes, travel, title="vpype document")
        _print_figures(plans, as_json)
    return document


@processor("lineus-draw")
@click.option("-d", "--device", metavar="ADDRESS", envvar="FABWIRE_LINEUS_DEVICE", type=vpype_cli.TextType(),
              help="Line-us address (host[:port], tcp://…) or a configured device name.")
@click.option("--timeout", type=click.FloatRange(min=0.1), default=5.0, show_default=True,
              help="Seconds to wait for the link to open.")
@plan_options
@click.option("--no-pause", is_flag=True, help="Draw every layer with one pen: no pen-change stop between layers.")
@click.option("--resume", is_flag=True, help="Continue an interrupted drawing of this document where it stopped.")
@click.option("--state", type=vpype_cli.PathType(path_type=Path, dir_okay=False),
              help="Progress file (default: one per drawing in the user's state directory).")
@PEN_Z
def lineus_draw(document: Any, device: str | None, timeout: float, clip: bool, no_optimize: bool,
                optimize_time: float | None, layer: Any, no_pause: bool, resume: bool, state: Path | None,
                pen_z: float) -> Any:
    """Draw the document on a Line-us, one layer after another.

    Between layers the arm parks at home and waits for Enter on standard input while you change the pen. Progress
    is saved after every stroke: after a lost link, run the same pipeline with --resume.
    """
    from fabwire.cli_support import App, DeviceContext
    from fabwire.devices import LINEUS
    from fabwire.vpype.drawing import ask_on_stdin, draw_passes

    with fabwire_errors():
        app = App(device=device, timeout=timeout)
        dctx = DeviceContext(app, LINEUS)
        dctx.target()  # an unknown device name fails before any planning
        options = _plan_options(clip, no_optimize, optimize_time)
        layer_ids = vpype_cli.multiple_to_layer_ids(layer, document)
        passes = document_passes(document, layer_ids)
        key = passes_key(passes, options)
        plans = plan_passes(passes, options)
        app.output.note(figures_text_all(plans))
        result = draw_passes(dctx, plans, key, state=state, resume=resume, pen_z=pen_z,
                             pen_change=None if no_pause else ask_on_stdin)
        app.output.note(f"drew {result.drawn} of {result.strokes} strokes in {units.duration(result.elapsed_seconds)}")
    return document


def figures_text_all(plans: list[PassPlan]) -> str:
    f = total_figures(plans)
    return (f"{len(plans)} layer(s), {f.strokes} strokes, pen down {f.pen_down_length / UNITS_PER_MM:.0f} mm, "
            f"pen-up travel {f.pen_up_travel / UNITS_PER_MM:.0f} mm, estimated {units.duration(f.estimated_seconds)}")


@processor("lineus-gcode")
@click.argument("file", type=vpype_cli.PathType(path_type=Path, dir_okay=False))
@plan_options
@PEN_Z
def lineus_gcode(document: Any, file: Path, clip: bool, no_optimize: bool, optimize_time: float | None, layer: Any,
                 pen_z: float) -> Any:
    """Write the document as Line-us G-code FILE (for `fabwire lineus files save`).

    Layers follow one another with the same pen; for one file per layer use vpype's
    `forlayer lineus-gcode "out-%_lid%.gcode" end`.
    """
    with fabwire_errors():
        plans = _plans(document, layer, _plan_options(clip, no_optimize, optimize_time))
        lines = plan_gcode(plans, pen_z=pen_z)
        try:
            file.write_text("".join(line + "\n" for line in lines), encoding="ascii")
        except OSError as exc:
            raise InputError(f"{file}: cannot write ({exc.strerror or exc})") from None
        click.echo(f"wrote {len(lines)} G-code lines to {file}", err=True)
    return document
