"""The Line-us part: the bundled SVG and a line of text drawn on the simulated arm, plus the planned preview."""

from __future__ import annotations

from collections.abc import Callable

from rich.markup import escape
from rich.progress import BarColumn, Progress, TaskID, TextColumn

from fabwire.demo.context import DemoContext
from fabwire.lineus.client import LineUs
from fabwire.lineus.draw_cli import figures_text, send_plan
from fabwire.lineus.plot import Plan, PlanOptions, load_drawing, plan_lines, text_lines
from fabwire.lineus.plot.fit import fit_into_area
from fabwire.lineus.plot.geometry import affine, bbox, scale_translate
from fabwire.lineus.render import write_drawing
from fabwire.samples import SAMPLE_SVG, sample_path

TEXT = "fabwire"


def plan_page() -> list[tuple[str, Plan]]:
    """The logo on top and the text under it, fitted together into the area, each planned on its own."""
    logo, _, _ = load_drawing(sample_path(SAMPLE_SVG))
    words = text_lines(TEXT)
    lx0, ly0, lx1, ly1 = bbox(logo)
    wx0, wy0, wx1, wy1 = bbox(words)
    scale = 0.3 * (ly1 - ly0) / max(wy1 - wy0, 1e-6)
    gap = 0.15 * (ly1 - ly0)
    m = scale_translate(scale, (lx0 + lx1) / 2 - (wx0 + wx1) / 2 * scale, ly0 - gap - wy1 * scale)
    placed_words = affine(words, m)
    both, _ = fit_into_area(list(logo) + list(placed_words), margin=4.0 * 10)
    options = PlanOptions(fit=False, time_budget=0.3)
    return [("SVG " + SAMPLE_SVG, plan_lines(both[: len(logo)], options, fit_default=False)),
            (f"text {TEXT!r}", plan_lines(both[len(logo):], options, fit_default=False))]


async def showcase(ctx: DemoContext, url: str) -> None:
    ctx.heading("Line-us drawing robot (G-code over TCP)")
    plans = plan_page()
    preview = ctx.out_dir / "lineus-preview.png"
    with ctx.summary.step("lineus", "plan + preview") as step:
        strokes = [s for _, plan in plans for s in plan.strokes]
        travel = [t for _, plan in plans for t in plan.travel()]
        write_drawing(preview, strokes, travel, title=f"{SAMPLE_SVG} + {TEXT!r} (planned, pen-up travel dashed)")
        step.files.append(preview)
        step.detail = f"{len(strokes)} strokes"
        ctx.say(f"planned preview with pen-up travel: {preview}")
    arm = await LineUs.open(url)
    try:
        for name, plan in plans:
            with ctx.summary.step("lineus", f"draw {name}") as step:
                ctx.say(f"[bold]{escape(name)}[/bold]: " + escape(figures_text(plan).replace("\n", "; ")), markup=True)
                with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                              console=ctx.err, disable=ctx.quiet_bars) as bar:
                    total = len(plan.strokes)
                    task = bar.add_task(f"drawing {name}", total=total)
                    await send_plan(arm, plan, on_stroke=_stroke_done(bar, task, name, total))
                await arm.home()
                step.detail = f"{total} strokes"
                ctx.say(f"drew {name}: {total} strokes")
    finally:
        await arm.close()



def _stroke_done(bar: Progress, task: TaskID, name: str, total: int) -> Callable[[int], None]:
    def done(index: int) -> None:
        bar.update(task, completed=index + 1, description=f"{name}: stroke {index + 1}/{total}")

    return done
