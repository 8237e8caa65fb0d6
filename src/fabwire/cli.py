"""The `fabwire` command: mounts each device's group, `sim`, `trace` and `demo`, and maps errors to exit codes."""

from __future__ import annotations

import itertools
import sys
import traceback
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

import click

from fabwire import __version__
from fabwire.cli_support import (
    DEVICE_OPTIONS,
    GLOBAL_OPTIONS,
    LINK_OPTIONS,
    App,
    FiniteRange,
    Lazy,
    LazyGroup,
    check_early_link_options,
    configure_logging,
    pass_app,
    uses_link_options,
)
from fabwire.console import MAX_WIDTH, help_width
from fabwire.devices import KINDS
from fabwire.errors import EXIT_INTERRUPTED, ConfigWarning, FabwireError, InputError, RemoteProtocolError
from fabwire.extras import missing_extra
from fabwire.simoptions import SERVE_OPTIONS

if TYPE_CHECKING:
    from fabwire.transport.tap import TraceRecord

EXIT_LINK = 8
EXIT_TIMEOUT = 9
EXIT_REPLAY_DIFFERS = RemoteProtocolError.exit_code
"""`trace replay`: the device did not answer as the recording says."""


COMMANDS: dict[str, Lazy] = {
    # name: where it lives, and its line in `fabwire --help` and completion (held to the command's own by a test)
    "xyz": Lazy("fabwire.xyz.cli:xyz",
                "XYZprinting da Vinci printers (XYZv3 over USB serial or Wi-Fi): status, print, maintenance."),
    "lineus": Lazy("fabwire.lineus.cli:lineus",
                   "Line-us drawing robot: draw SVGs and text, preview, move the arm, stored drawings, Wi-Fi."),
    "mmu": Lazy("fabwire.mmu.cli:mmu",
                "Prusa MMU3, driven as the printer does: tool changes, buttons, registers, monitor."),
    "demo": Lazy("fabwire.demo:demo", "A tour on simulators: a da Vinci print, a Line-us drawing and MMU3 tool "
                                      "changes with a fault and Retry."),
    "fleet": Lazy("fabwire.mqtt.fleet:fleet",
                  "List every device the fabwire agents on an MQTT broker publish, and the agent that runs each."),
    "serve": Lazy("fabwire.agent.command:serve",
                  "Watch a bench of machines: a live dashboard, an HTTP API with history and jobs, one agent.",
                  "serve"),
    "devices": Lazy("fabwire.devices_cli:devices",
                    "Named devices (devices.toml): -d NAME uses one, and its settings apply to every command."),
    "service": Lazy("fabwire.service:service",
                    "Run the agent (`fabwire serve`) as a systemd service, and give USB machines stable names."),
}
"""The top-level commands that live in their own modules: `fabwire --help` and completion import none of them."""

SIMULATORS: dict[str, Lazy] = {
    "xyz": Lazy("fabwire.xyz.cli:sim_xyz",
                "A da Vinci printer on TCP 9100 and/or a raw pty that real clients cannot tell from the machine."),
    "lineus": Lazy("fabwire.lineus.cli:sim_lineus",
                   "A Line-us on TCP that the official clients cannot tell from the robot."),
    "mmu": Lazy("fabwire.mmu.cli:sim_mmu", "Simulate an MMU3 (no default TCP port: give --listen HOST:PORT or --pty)."),
}
"""`fabwire sim KIND`, as COMMANDS."""


@click.group(
    cls=LazyGroup,
    lazy=COMMANDS,
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": MAX_WIDTH,
                      "terminal_width": help_width()},
)
@click.version_option(__version__, "-V", "--version", prog_name="fabwire")
@click.pass_context
def cli(ctx: click.Context) -> None:
    """Talk to maker machines over their own wire protocols — or simulate them.

    Devices: xyz (XYZprinting da Vinci printers), lineus (Line-us drawing robot), mmu (Prusa MMU3).
    Options such as -d, --json, --trace, --timeout, -v and a device's link options (the MMU's --speed)
    go before or after the subcommand.
    """
    check_early_link_options(ctx, ctx.invoked_subcommand)


cli.params.extend(make() for make in (*GLOBAL_OPTIONS, *DEVICE_OPTIONS, *itertools.chain(*LINK_OPTIONS.values())))
cli.shared = (*GLOBAL_OPTIONS, *DEVICE_OPTIONS)


@cli.group(cls=LazyGroup, lazy=SIMULATORS)
def sim() -> None:
    """Run a faithful simulator of a device on TCP or a raw pty."""


sim.own_options = SERVE_OPTIONS  # type: ignore[attr-defined]


@cli.command()
@click.argument("shell", type=click.Choice(["bash", "zsh", "fish"]))
def completion(shell: str) -> None:
    """Print the completion script for SHELL; it completes commands, options and configured device names.

    \b
    bash: mkdir -p ~/.local/share/bash-completion/completions
          fabwire completion bash > ~/.local/share/bash-completion/completions/fabwire
    zsh:  fabwire completion zsh > "${fpath[1]}/_fabwire"
    fish: mkdir -p ~/.config/fish/completions
          fabwire completion fish > ~/.config/fish/completions/fabwire.fish
    """
    from click.shell_completion import get_completion_class

    complete = get_completion_class(shell)
    assert complete is not None  # the choice above only allows shells click supports
    click.echo(complete(cli, {}, "fabwire", "_FABWIRE_COMPLETE").source())


@cli.command()
@click.argument("directory", type=click.Path(file_okay=False, path_type=Path), default=".")
@click.option("--force", is_flag=True, help="Replace files of the same name.")
@pass_app
def samples(app: App, directory: Path, force: bool) -> None:
    """Write the sample print and drawing the README's tour uses into DIRECTORY (default: here)."""
    from fabwire.samples import write_samples

    written = write_samples(directory, overwrite=force)
    app.output.result([str(p) for p in written], "\n".join(f"wrote {p}" for p in written))


@cli.group()
def trace() -> None:
    """Read wire captures made with --trace."""


@trace.command("show")
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--no-time", is_flag=True, help="Leave out the timestamps.")
@pass_app
def trace_show(app: App, file: Path, no_time: bool) -> None:
    """Print a capture: `>` bytes to the device, `<` bytes from it, hexdump for binary (--json: one record a line)."""
    from fabwire.transport.trace_show import render_trace

    if app.json:
        for r in _records(file, app.output.note):
            app.output.event({"t": r.t, "dir": r.direction, "data": r.data, "event": r.event or None}, "")
        return
    for line in render_trace(_records(file, app.output.note), timestamps=not no_time):
        click.echo(line)


def _records(file: Path, note: Callable[[str], None]) -> Iterator[TraceRecord]:
    """The capture's records, streamed; a file with none is refused (InputError, exit 4) rather than shown empty,
    a last record cut off is a note."""
    from fabwire.transport.tap import read_trace

    empty = True
    for record in read_trace(file, on_cut=note):
        empty = False
        yield record
    if empty:
        raise InputError(f"{file} holds no trace records")


@trace.command("replay")
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--to", "address", required=True, metavar="ADDRESS",
              help="Where to send: host:port, tcp://…, /dev/tty…, or sim://KIND.")
@click.option("--quiet", type=FiniteRange(min=0.01), default=2.0, show_default=True,
              help="Seconds of silence that end a reply shorter than the recorded one.")
@click.option("--strict", is_flag=True,
              help="Compare every byte, the values that vary by nature (uptime, clocks, temperatures) too.")
@click.option("--protocol", type=click.Choice(sorted(KINDS)),
              help="The capture's protocol, for a capture that does not name it (default: from the capture).")
@uses_link_options("timeout")
@pass_app
def trace_replay(app: App, file: Path, address: str, quiet: float, strict: bool, protocol: str | None) -> int:
    """Send the host side of a capture to ADDRESS and report each reply that differs from the recording.

    Values that vary by nature (an XYZ printer's power-on minutes and temperatures, a Line-us's clock, an MMU's
    progress) are not compared, and are listed as ignored when they differed; --strict compares them too.
    """
    import asyncio

    from fabwire.transport import open_transport
    from fabwire.transport.replay import ReplayReport, replay, report_json, report_lines
    from fabwire.transport.tap import trace_device
    from fabwire.transport.volatile import GRAMMARS

    records = _records(file, app.output.note)
    first = next(records)  # an empty or unreadable capture is refused before connecting
    records = itertools.chain([first], records)
    grammar = GRAMMARS.get(protocol or trace_device(file) or "")

    async def main() -> ReplayReport:
        link = await open_transport(address, connect_timeout=app.timeout or 5.0)
        try:
            return await replay(link, records, quiet=quiet, grammar=grammar, strict=strict)
        finally:
            await link.close()

    report = asyncio.run(main())

    def human() -> None:
        for line in report_lines(report, quiet):
            click.echo(line)

    app.output.result(report_json(report), human)
    return 0 if not report.differences else EXIT_REPLAY_DIFFERS


def _fail(app: App, message: str, code: int) -> int:
    if app.debug:
        traceback.print_exc()
    click.echo(f"fabwire: error: {message}", err=True)
    return code


def _show_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                  file: TextIO | None = None, line: str | None = None) -> None:
    """fabwire's own warnings as one line on stderr, as its errors are; others as Python shows them."""
    if issubclass(category, ConfigWarning):
        click.echo(f"fabwire: warning: {message}", err=True)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def main(argv: list[str] | None = None) -> int:
    """Entry point: one line on stderr and a distinct exit code per error kind; a traceback only with --debug."""
    with warnings.catch_warnings():
        warnings.showwarning = _show_warning
        return _main(argv)


def _main(argv: list[str] | None) -> int:
    app = App(debug="--debug" in (argv if argv is not None else sys.argv[1:]))
    configure_logging(0)
    try:
        result = cli.main(args=argv, prog_name="fabwire", obj=app, standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("fabwire: interrupted", err=True)
        return EXIT_INTERRUPTED
    except click.ClickException as exc:
        exc.show()
        return exc.exit_code
    except KeyboardInterrupt:
        click.echo("fabwire: interrupted", err=True)
        return EXIT_INTERRUPTED
    except FabwireError as exc:
        return _fail(app, str(exc), exc.exit_code)
    except ImportError as exc:
        extra = missing_extra(exc)
        if extra is None:
            return _fail(app, f"internal error: {exc!r} (run with --debug for the traceback)", 1)
        return _fail(app, str(extra), extra.exit_code)
    except TimeoutError as exc:
        return _fail(app, f"timed out: {exc or 'the device did not answer'}", EXIT_TIMEOUT)
    except ConnectionError as exc:
        return _fail(app, f"link failed: {exc}", EXIT_LINK)
    except BrokenPipeError:
        return 0
    except Exception as exc:
        return _fail(app, f"internal error: {exc!r} (run with --debug for the traceback)", 1)
    return result if isinstance(result, int) else 0


if __name__ == "__main__":
    sys.exit(main())
