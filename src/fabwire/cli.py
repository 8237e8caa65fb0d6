"""The `fabwire` command: mounts each device's group, `sim`, `trace` and `demo`, and maps errors to exit codes."""

from __future__ import annotations

import importlib
import importlib.util
import logging
import sys
import traceback
from pathlib import Path

import click

from fabwire import __version__
from fabwire.cli_support import App
from fabwire.errors import EXIT_INTERRUPTED, FabwireError
from fabwire.transport.tap import read_trace
from fabwire.transport.trace_show import render_trace

EXIT_LINK = 8
EXIT_TIMEOUT = 9


class LazyGroup(click.Group):
    """Loads a subcommand's module only when it runs, so `fabwire xyz status` never imports the SVG stack."""

    def __init__(self, *args: object, lazy: dict[str, str] | None = None, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self._lazy = lazy or {}

    def _available(self, name: str) -> bool:
        module = self._lazy[name].partition(":")[0]
        try:
            return importlib.util.find_spec(module) is not None
        except ModuleNotFoundError:
            return False

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(set(super().list_commands(ctx)) | {n for n in self._lazy if self._available(n)})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name in self._lazy and self._available(cmd_name):
            module_name, _, attr = self._lazy[cmd_name].partition(":")
            command = getattr(importlib.import_module(module_name), attr)
            if not isinstance(command, click.Command):
                raise TypeError(f"{self._lazy[cmd_name]} is not a click command")
            return command
        return super().get_command(ctx, cmd_name)


def _setup_logging(verbose: int) -> None:
    level = logging.WARNING if verbose == 0 else logging.INFO if verbose == 1 else logging.DEBUG
    logging.basicConfig(level=level, stream=sys.stderr, format="%(asctime)s %(name)s: %(message)s")


@click.group(
    cls=LazyGroup,
    lazy={
        "xyz": "fabwire.xyz.cli:xyz",
        "lineus": "fabwire.lineus.cli:lineus",
        "mmu": "fabwire.mmu.cli:mmu",
        "demo": "fabwire.demo:demo",
        "serve": "fabwire.agent.command:serve",
    },
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 110},
)
@click.version_option(__version__, "-V", "--version", prog_name="fabwire")
@click.option("--json", "json_output", is_flag=True, help="Machine-readable results on stdout (text goes to stderr).")
@click.option("-v", "--verbose", count=True, help="Log more; -vv logs every byte on the wire (logger fabwire.wire).")
@click.option("--debug", is_flag=True, help="Show tracebacks on errors.")
@click.pass_context
def cli(ctx: click.Context, json_output: bool, verbose: int, debug: bool) -> None:
    """Talk to maker machines over their own wire protocols — or simulate them.

    Devices: xyz (XYZprinting da Vinci printers), lineus (Line-us drawing robot), mmu (Prusa MMU3).
    """
    app = ctx.ensure_object(App)
    app.output.json_mode = json_output
    app.verbose = verbose
    app.debug = debug or app.debug
    _setup_logging(verbose)


@cli.group(
    cls=LazyGroup,
    lazy={
        "xyz": "fabwire.xyz.cli:sim_xyz",
        "lineus": "fabwire.lineus.cli:sim_lineus",
        "mmu": "fabwire.mmu.cli:sim_mmu",
    },
)
def sim() -> None:
    """Run a faithful simulator of a device on TCP or a raw pty."""


@cli.group()
def trace() -> None:
    """Read wire captures made with --trace."""


@trace.command("show")
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--no-time", is_flag=True, help="Leave out the timestamps.")
@click.pass_obj
def trace_show(app: App, file: Path, no_time: bool) -> None:
    """Print a capture: `>` bytes to the device, `<` bytes from it, hexdump for binary."""
    records = list(read_trace(file))
    if app.json:
        app.output.result(
            [{"t": r.t, "dir": r.direction, "data": r.data, "event": r.event or None} for r in records]
        )
        return
    for line in render_trace(records, timestamps=not no_time):
        click.echo(line)


def _fail(app: App, message: str, code: int) -> int:
    if app.debug:
        traceback.print_exc()
    click.echo(f"fabwire: error: {message}", err=True)
    return code


def main(argv: list[str] | None = None) -> int:
    """Entry point: one line on stderr and a distinct exit code per error kind; a traceback only with --debug."""
    app = App(debug="--debug" in (argv if argv is not None else sys.argv[1:]))
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
