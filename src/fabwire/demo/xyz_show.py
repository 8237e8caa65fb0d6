"""The da Vinci part: status panel, G-code → .3w, upload with a bar, the print followed to its end."""

from __future__ import annotations

import time

from rich.progress import BarColumn, Progress, TaskID, TextColumn

from fabwire.demo.context import DemoContext
from fabwire.errors import DeviceError
from fabwire.samples import SAMPLE_GCODE, sample_path
from fabwire.xyz.cli import render_status
from fabwire.xyz.client import XYZPrinter
from fabwire.xyz.live import job_line
from fabwire.xyz.status import PRINT_DONE, Status
from fabwire.xyz.threew import convert_gcode_file
from fabwire.xyz.threew_cli import metadata_summary


async def showcase(ctx: DemoContext, url: str) -> None:
    ctx.heading("XYZprinting da Vinci (XYZv3 over TCP)")
    summary = ctx.summary
    printer = await XYZPrinter.connect(url, timeout=5.0)
    try:
        with summary.step("xyz", "status") as step:
            status = await printer.status()
            ctx.err.print(render_status(status))
            model = status.model
            if model is None:
                raise DeviceError("model", f"the simulator reports an unknown model {status.model_number!r}")
            step.detail = model.name
        with summary.step("xyz", "convert G-code to .3w") as step:
            source = sample_path(SAMPLE_GCODE)
            target = ctx.out_dir / (source.stem + ".3w")
            info = convert_gcode_file(source, target, model)
            ctx.say(f"converted {source.name} → {target} for {model.name} ({info.variant}); {metadata_summary(info)}")
            step.detail = info.variant
            step.files.append(target)
        await _print(ctx, printer, target)
    finally:
        await printer.close()


async def _print(ctx: DemoContext, printer: XYZPrinter, target: object) -> None:
    from pathlib import Path

    assert isinstance(target, Path)
    began = time.monotonic()
    upload_done: list[float] = []
    states: list[str] = []
    columns = (TextColumn("{task.description}"), BarColumn(), TextColumn("{task.fields[amount]}"))
    with Progress(*columns, console=ctx.err, disable=ctx.quiet_bars) as bar:
        tasks: dict[str, TaskID] = {}

        def uploaded(done: int, total: int) -> None:
            if "upload" not in tasks:
                tasks["upload"] = bar.add_task(f"upload {target.name}", total=total, amount="")
            bar.update(tasks["upload"], completed=done, total=total, amount=f"{done / 1000:.1f}/{total / 1000:.1f} kB")
            if done >= total and not upload_done:
                upload_done.append(time.monotonic())

        def job(st: Status) -> None:
            if not upload_done:
                upload_done.append(time.monotonic())
            if st.state_name not in states:
                states.append(st.state_name)
                bar.console.print(job_line(st))
            if "job" not in tasks:
                tasks["job"] = bar.add_task("print", total=100, amount="")
            percent = 100 if st.state_code == PRINT_DONE else st.progress.percent if st.progress else 0
            bar.update(tasks["job"], completed=percent, description=job_line(st), amount=f"{percent} %")

        final = await printer.print_file(target, progress=uploaded, on_status=job)
    end = time.monotonic()
    upload_at = upload_done[0] if upload_done else end
    ctx.summary.record("xyz", "upload", upload_at - began, f"{target.stat().st_size:,} bytes")
    ctx.summary.record("xyz", "print to completion", end - upload_at, final.state_name)
    ctx.say(f"{target.name}: {final.state_name}")
