"""`fabwire demo`: three simulators as real processes on loopback TCP, a guided tour of each, a closing table."""

from __future__ import annotations

import asyncio
import signal
import threading
from collections.abc import Awaitable, Callable
from pathlib import Path
from types import FrameType

import click

from fabwire.cli_support import App, FiniteRange, pass_app
from fabwire.demo.context import DemoContext
from fabwire.demo.runner import SimulatorProcess, start_simulators, stop_all
from fabwire.demo.summary import Summary
from fabwire.errors import FabwireError, InputError, LinkTimeout
from fabwire.extras import first_missing

DEVICES = ("xyz", "lineus", "mmu")
DEFAULT_SPEED = 30.0
MAX_SPEED = 100.0
"""The fastest tour that still finishes on a busy machine: above it the MMU's link timeouts (2 s scaled down) fall
under what a loaded scheduler delays a process by, and the tour fails for no fault of its own."""
EXAMPLES = {
    "xyz": "fabwire xyz -d {url} status",
    "lineus": "fabwire lineus -d {url} text hello",
    "mmu": "fabwire mmu -d {url} tool-change 3 --speed {speed:g}",
}


def _sim_args(device: str, speed: float, out_dir: Path, record: Path | None) -> list[str]:
    args = ["--speed", f"{speed:g}"]
    if device == "lineus" and record is not None:
        args += ["--record", str(record)]
    if device == "mmu":
        from fabwire.demo.mmu_show import FAULT

        args += ["--fault", FAULT]
    return args


def _showcase(device: str) -> Callable[[DemoContext, str], Awaitable[None]]:
    if device == "xyz":
        from fabwire.demo.xyz_show import showcase
    elif device == "lineus":
        from fabwire.demo.lineus_show import showcase
    else:
        from fabwire.demo.mmu_show import showcase
    return showcase


async def _tour(ctx: DemoContext, sims: dict[str, SimulatorProcess], devices: list[str]) -> None:
    limit = 60.0 + 1200.0 / ctx.speed
    for device in devices:
        try:
            async with asyncio.timeout(limit):
                await _showcase(device)(ctx, sims[device].url)
        except TimeoutError:
            raise LinkTimeout(f"the {device} showcase did not finish within {limit:g} s") from None


def _terminate(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


@click.command("demo")
@click.option("--speed", type=FiniteRange(0.5, MAX_SPEED), default=DEFAULT_SPEED, show_default=True,
              help="Simulated time runs this many times faster than real time.")
@click.option("--only", "only", multiple=True, type=click.Choice(DEVICES),
              help="Show only this device (repeatable).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              default=Path("fabwire-demo-output"), show_default=True, help="Where the output files go.")
@click.option("--keep-running", is_flag=True,
              help="Leave the simulators up afterwards for your own commands, until Ctrl-C.")
@pass_app
def demo(app: App, speed: float, only: tuple[str, ...], out_dir: Path, keep_running: bool) -> None:
    """A tour on simulators: a da Vinci print, a Line-us drawing and MMU3 tool changes with a fault and Retry."""
    devices = [d for d in DEVICES if not only or d in only]
    if "lineus" in devices and (missing := first_missing("lineus")) is not None:
        if only:
            raise missing
        devices.remove("lineus")  # the base install: show what it drives
        app.output.note(f"leaving out the Line-us: {missing}")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the output directory {out_dir}: {exc.strerror or exc}") from None
    out_dir = out_dir.resolve()
    err = app.output.err
    summary = Summary(speed, out_dir)
    ctx = DemoContext(out_dir, speed, err, summary, quiet_bars=app.json)
    record = out_dir / "lineus-drawn.png" if "lineus" in devices else None
    if record is not None:
        record.unlink(missing_ok=True)
    previous = signal.signal(signal.SIGTERM, _terminate)
    sims: dict[str, SimulatorProcess] = {}
    failure: BaseException | None = None
    reported = False
    try:
        err.print(f"starting {len(devices)} simulator(s) on 127.0.0.1 at speed ×{speed:g} …")
        with summary.step("all", "start simulators") as step:
            started = start_simulators([(d, _sim_args(d, speed, out_dir, record)) for d in devices])
            sims = {s.device: s for s in started}
            step.detail = f"{len(started)} on 127.0.0.1"
        summary.simulators = [{"device": s.device, "url": s.url, "pid": s.pid} for s in started]
        for s in started:
            err.print(f"  {s.device} simulator (pid {s.pid}) on {s.url}")
        asyncio.run(_tour(ctx, sims, devices))
        if "lineus" in sims and record is not None:
            _collect_record(ctx, sims, record, speed)
        if keep_running:  # the tour's table now, not after the time the simulators are left up
            try:
                summary.finish()
                reported = True  # before: a Ctrl-C as soon as the table shows must not show it again
                _report(app, summary)
                _keep_running(ctx, sims, speed)
            except KeyboardInterrupt:  # the way to end it, once the tour is done
                ctx.say("stopping the simulators …")
    except BaseException as exc:
        failure = exc
        raise
    finally:
        problems = stop_all(list(sims.values()))
        session = out_dir / "lineus-session.png"
        if keep_running and "lineus" in sims and session.exists():
            err.print(f"what the arm drew in your session: {session}")
        signal.signal(signal.SIGTERM, previous)
        if failure is None and problems:
            failure = problems[0]
        if failure is not None:
            summary.error = str(failure) or type(failure).__name__
        if not reported:
            summary.finish()
            _report(app, summary)
    if problems:
        raise problems[0]


def _collect_record(ctx: DemoContext, sims: dict[str, SimulatorProcess], record: Path, speed: float) -> None:
    """The Line-us simulator writes what it drew when it stops; with --keep-running a fresh one takes its place."""
    with ctx.summary.step("lineus", "record of the arm") as step:
        sim = sims["lineus"]
        code = sim.stop()
        if not record.exists():
            raise FabwireError(f"the Line-us simulator (exit code {code}) wrote no drawing to {record}: "
                               f"{sim.stderr_tail() or 'no message'}")
        step.files.append(record)
        ctx.say(f"what the simulated arm drew: {record}")
    sims["lineus-drawn"] = sims.pop("lineus")


def _keep_running(ctx: DemoContext, sims: dict[str, SimulatorProcess], speed: float) -> None:
    if "lineus-drawn" in sims:
        session = ctx.out_dir / "lineus-session.png"
        session.unlink(missing_ok=True)  # only this session's drawing is named at the end
        sims["lineus"] = start_simulators([("lineus", _sim_args("lineus", speed, ctx.out_dir, session))])[0]
        ctx.say(f"(a fresh Line-us simulator records your session to {session} when it stops)")
    ctx.say("\n[bold]The simulators are still running.[/bold] Try, in another terminal:", markup=True)
    for device in DEVICES:
        if device in sims:
            ctx.say("  " + EXAMPLES[device].format(url=sims[device].url, speed=speed))
    stop = threading.Event()  # a flag, not KeyboardInterrupt: a Ctrl-C must not cut a line being printed

    def asked(signum: int, frame: FrameType | None) -> None:
        stop.set()

    previous = {sig: signal.signal(sig, asked) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        ctx.say("Press Ctrl-C to stop them.")
        while all(s.running() for name, s in sims.items() if name in DEVICES):
            if stop.wait(0.5):
                ctx.say("stopping the simulators …")
                return
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    stopped = [name for name, s in sims.items() if name in DEVICES and not s.running()]
    raise FabwireError(f"the {stopped[0]} simulator stopped on its own")


def _report(app: App, summary: Summary) -> None:
    if app.json:
        app.output.result(summary.to_dict())
        return
    app.output.err.print(summary.table())
    if summary.files:
        app.output.err.print(f"output files are in {summary.out_dir}")
