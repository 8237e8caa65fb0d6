"""The command line's shared options, defined once, and where they apply.

Shared options (`--json`, `-v`, `--debug`, `-d`, `--trace`, `--timeout` and each device's link options such as the
MMU's `--speed`) are attached to every command below the group that shares them, so `fabwire xyz status -d HOST
--json` and `fabwire --json xyz -d HOST status` mean the same. Each occurrence stores its value on the one `App`; the
last one on the line wins (`-v` adds up).

Link options (`-d`, `--trace`, `--timeout` and a device's own) reach only commands that open a device: those that
take a `DeviceContext` (`pass_device`) or name the ones they use (`uses_link_options`). Any other command refuses
them wherever they were given on the line (exit 2, one line), rather than accepting an option that does nothing.
"""

from __future__ import annotations

import logging
import math
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click
import msgspec

from fabwire.console import Output
from fabwire.errors import excerpt

if TYPE_CHECKING:
    from fabwire.transport.faults import FaultPlan

T = TypeVar("T")

OptionFactory = Callable[[], click.Option]


PLAIN_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[+-]?(?:nan|inf|infinity)",
                          re.IGNORECASE)
"""A number as people type it on a command line (ASCII digits); nan and inf pass here to be refused by name."""


class FiniteRange(click.FloatRange):
    """A FloatRange that also refuses nan and ±inf (nan passes every comparison, inf makes a wait endless)."""

    name = "number"

    def __init__(self, min: float | None = None, max: float | None = None, *, open_ended: bool = False,
                 **kwargs: Any) -> None:
        """`open_ended` also takes +inf, for a factor where it has a documented meaning ("no delay")."""
        super().__init__(min, max, **kwargs)
        self.open_ended = open_ended

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if isinstance(value, str) and not PLAIN_NUMBER.fullmatch(value.strip()):
            # Python's float() also takes "1_000" and other scripts' digits: what a person typed is not read as a
            # number they did not mean
            self.fail(f"{excerpt(str(value), 30)} is not a number (digits 0-9, an optional sign, point and "
                      "exponent).", param, ctx)
        number = click.FLOAT.convert(value, param, ctx)  # the finiteness first: "inf" is no number, not too large
        if not math.isfinite(number) and not (self.open_ended and number == math.inf):
            self.fail(f"{excerpt(str(value), 30)} is not a finite number.", param, ctx)
        return super().convert(number, param, ctx)


class App(msgspec.Struct):
    """Options of the whole command line, filled in wherever they appear on it."""

    output: Output = msgspec.field(default_factory=Output)
    verbose: int = 0
    debug: bool = False
    device: str | None = None
    trace: Path | None = None
    timeout: float | None = None
    faults: FaultPlan | None = None
    link_options: dict[str, Any] = msgspec.field(default_factory=dict)
    """A device's own link options given on the command line (e.g. the MMU's speed), by settings field name."""
    early_link_options: dict[str, str] = msgspec.field(default_factory=dict)
    """Link options given before any subcommand: flag -> the device kind they belong to."""
    given_link_options: dict[str, tuple[str, str]] = msgspec.field(default_factory=dict)
    """Link options typed on the command line at a group's level, by settings name: (option, the group's path);
    the command finally run refuses those it does not use."""
    server_options: dict[str, Any] = msgspec.field(default_factory=dict)
    """A simulator's serving options (connection limit, idle timeout, trace), see `fabwire.simoptions`."""

    @property
    def json(self) -> bool:
        return self.output.json_mode


def configure_logging(verbose: int) -> None:
    """-v: connects, retries and state changes (INFO); -vv: also every byte on the wire (DEBUG). Without -v the
    warnings that still come are `fabwire: …` lines, as every other line fabwire prints; with it, each line has its
    time and logger, as a log does."""
    root = logging.getLogger("fabwire")
    handler = next((h for h in root.handlers if getattr(h, "fabwire_cli", False)), None)
    if handler is None:
        handler = logging.StreamHandler(sys.stderr)
        handler.fabwire_cli = True  # type: ignore[attr-defined]
        root.addHandler(handler)
    handler.setFormatter(logging.Formatter("fabwire: %(message)s" if verbose <= 0
                                           else "%(asctime)s %(name)s: %(message)s"))
    root.setLevel(logging.WARNING if verbose <= 0 else logging.INFO if verbose == 1 else logging.DEBUG)


def app_of(ctx: click.Context) -> App:
    """The one App of this command line (made on first use)."""
    app = ctx.find_object(App)
    if app is None:
        app = ctx.ensure_object(App)
    return app


def _given(ctx: click.Context, param: click.Parameter) -> bool:
    source = ctx.get_parameter_source(param.name or "")
    return source not in (None, click.core.ParameterSource.DEFAULT)


def _setter(apply: Callable[[App, Any], None]) -> Callable[[click.Context, click.Parameter, Any], None]:
    def callback(ctx: click.Context, param: click.Parameter, value: Any) -> None:
        if _given(ctx, param):
            apply(app_of(ctx), value)

    return callback


def _typed(ctx: click.Context, param: click.Parameter) -> bool:
    """The option was typed on the command line (not an environment default)."""
    return ctx.get_parameter_source(param.name or "") is click.core.ParameterSource.COMMANDLINE


def _flag(param: click.Parameter) -> str:
    return "/".join(param.opts)


def _remember(ctx: click.Context, param: click.Parameter) -> None:
    """Note a link option typed at a group's level, for the command that finally runs to judge."""
    if _typed(ctx, param) and param.name:
        app_of(ctx).given_link_options[param.name] = (_flag(param), ctx.command_path)


def link_setter(apply: Callable[[App, Any], None]) -> Callable[[click.Context, click.Parameter, Any], None]:
    """A link option's callback: store the value like `_setter`, and remember where it was typed."""
    store = _setter(apply)

    def callback(ctx: click.Context, param: click.Parameter, value: Any) -> None:
        store(ctx, param, value)
        _remember(ctx, param)

    return callback


def _set_json(app: App, value: bool) -> None:
    app.output.json_mode = app.output.json_mode or value


def _add_verbose(app: App, value: int) -> None:
    app.verbose += value
    configure_logging(app.verbose)


def _set_faults(app: App, value: str) -> None:
    from fabwire.transport.faults import FaultPlan  # the transports load only for commands that open a device

    app.faults = FaultPlan.parse(value)


def device_names(ctx: click.Context, param: click.Parameter, incomplete: str) -> list[str]:
    """Completion of a device name (-d, `devices show|remove NAME`): the configured names (of the command's
    device kind, when known), each as one shell word: a name written by hand with a space in it comes quoted
    (`devices add` takes only names that need no quotes)."""
    import shlex

    from fabwire.config import load_devices
    from fabwire.errors import FabwireError

    try:
        devices = load_devices()
    except FabwireError:
        return []
    kinds = set()
    current: click.Context | None = ctx
    while current is not None:
        kinds.add(current.info_name)
        current = current.parent
    wanted = kinds & {"xyz", "lineus", "mmu"}
    return sorted(shlex.quote(name) for name, device in devices.items()
                  if name.startswith(incomplete) and (not wanted or device.kind.name in wanted))


GLOBAL_OPTIONS: tuple[OptionFactory, ...] = (
    lambda: click.Option(["--json", "shared_json"], is_flag=True, expose_value=False,
                         callback=_setter(_set_json),
                         help="Machine-readable results on stdout (text goes to stderr)."),
    lambda: click.Option(["-v", "--verbose", "shared_verbose"], count=True, expose_value=False,
                         callback=_setter(_add_verbose),
                         help="Log connects, retries and state changes; -vv also every byte on the wire."),
    lambda: click.Option(["--debug", "shared_debug"], is_flag=True, expose_value=False,
                         callback=_setter(lambda app, v: setattr(app, "debug", app.debug or v)),
                         help="Show tracebacks on errors."),
)

def device_option(setting: str, *decls: str, apply: Callable[[App, Any], None], **attrs: Any) -> OptionFactory:
    """An option every command that opens a device takes, stored on the App as `shared_<setting>`."""
    factory: OptionFactory = lambda: click.Option(  # noqa: E731
        [*decls, f"shared_{setting}"], expose_value=False, callback=link_setter(apply), **attrs)
    factory.setting = f"shared_{setting}"  # type: ignore[attr-defined]
    return factory


DEVICE_OPTIONS: tuple[OptionFactory, ...] = (
    device_option("device", "-d", "--device", metavar="DEVICE", apply=lambda app, v: setattr(app, "device", v),
                  shell_complete=device_names,
                  help="Address (host[:port], tcp://…, /dev/tty…, sim://KIND) or a configured device name."),
    device_option("trace", "--trace", type=click.Path(dir_okay=False, path_type=Path),
                  apply=lambda app, v: setattr(app, "trace", v), help="Record the wire to FILE."),
    device_option("timeout", "--timeout", type=FiniteRange(min=0.1), apply=lambda app, v: setattr(app, "timeout", v),
                  help="Seconds to wait for the link to open [default: 5, or the device's setting]."),
    device_option("inject", "--inject", metavar="FAULTS", hidden=True, apply=_set_faults,
                  help="Test aid: fault plan such as chunk=1,drop=0.01,seed=3."),
)


def link_option(kind: str, setting: str, *decls: str, **attrs: Any) -> OptionFactory:
    """Device `kind`'s own link option, stored under the name of its settings field (see `fabwire.config`).

    Given before the device's group (`fabwire --speed 20 mmu …`) it is remembered, so that a command line
    where it would reach another device or a simulator is refused instead of silently ignored.
    """

    def store(ctx: click.Context, param: click.Parameter, value: Any) -> None:
        source = ctx.get_parameter_source(param.name or "")
        if ctx.parent is None:
            if source is not click.core.ParameterSource.COMMANDLINE:
                return  # an environment default at the root would reach every device
            app_of(ctx).early_link_options[param.opts[0]] = kind
        elif not _given(ctx, param):
            return
        app_of(ctx).link_options[setting] = list(value) if isinstance(value, tuple) else value
        _remember(ctx, param)

    factory: OptionFactory = lambda: click.Option(  # noqa: E731
        [*decls, f"shared_{setting}"], expose_value=False, callback=store, **attrs)
    factory.device_kind = kind  # type: ignore[attr-defined]
    factory.setting = f"shared_{setting}"  # type: ignore[attr-defined]
    return factory


LINK_OPTIONS: dict[str, tuple[OptionFactory, ...]] = {
    "mmu": (
        link_option("mmu", "speed", "--speed", type=FiniteRange(min=0.01), envvar="FABWIRE_MMU_SPEED",
                    help="The MMU runs this many times faster than real time (a simulator's --speed); "
                         "the heartbeat and timeouts shrink to match [default: 1, or the device's setting]."),
        link_option("mmu", "accept", "--accept", multiple=True, metavar="X.Y.Z",
                    help="MMU firmware versions to accept (repeatable; default 3.0.2, 3.0.3, 3.0.4)."),
    ),
}
"""Each device kind's own link options, accepted anywhere on the line: before its group, on it, or after."""


class OptionNotUsed(click.UsageError):
    """A link option given to a command that does not use it: one line, exit 2."""

    def show(self, file: Any = None) -> None:
        click.echo(f"fabwire: error: {self.format_message()}", err=True, file=file)


def check_early_link_options(ctx: click.Context, subcommand: str | None) -> None:
    """Refuse a device's link option given before a command that is not that device's group."""
    for flag, kind in app_of(ctx).early_link_options.items():
        if subcommand == kind:
            continue
        if subcommand == "sim":
            raise OptionNotUsed(f"{flag} before `sim` is a link option of `fabwire {kind}`; a simulator's "
                               f"own options go after its name (see `fabwire sim {kind} --help`)")
        raise OptionNotUsed(f"{flag} is a link option of `fabwire {kind}`; it does not apply to "
                           f"`fabwire {subcommand}`")


USES_LINK_OPTIONS = "fabwire_link_options"
"""Attribute of a command's callback: the link options (settings names, or ANY) the command uses."""
ANY = "*"


def uses_link_options(*settings: str) -> Callable[[T], T]:
    """Mark a command's callback as using these link options (`"timeout"`, …; ANY: every one it is given)."""

    def mark(func: T) -> T:
        setattr(func, USES_LINK_OPTIONS, frozenset(f"shared_{s}" if s != ANY else ANY for s in settings))
        return func

    return mark


def _uses(command: click.Command, setting: str) -> bool:
    """Whether `command` (or, for a plain group, a command under it) uses the link option `setting`."""
    marks: frozenset[str] = getattr(command.callback, USES_LINK_OPTIONS, frozenset())
    if ANY in marks or setting in marks:
        return True
    if isinstance(command, click.Group) and not isinstance(command, SharingGroup):
        return any(_uses(sub, setting) for sub in command.commands.values())
    return False


def _takes(command: click.Command, setting: str | None = None) -> list[click.Option]:
    """The link options `command` uses (only `setting`'s, when given)."""
    return [p for p in command.params if isinstance(p, click.Option) and getattr(p, "fabwire_setting", None)
            and setting in (None, p.fabwire_setting)]  # type: ignore[attr-defined]


def _not_here(flag: str, command: click.Command, path: str, where: str | None = None) -> OptionNotUsed:
    """The refusal of link option `flag` ("-d/--device") by the command at `path`, typed at the group `where`
    (None: typed after the command itself)."""
    own = next((p for p in command.params if isinstance(p, click.Option) and not p.hidden
                and set(p.opts) & set(flag.split("/"))), None)
    if own is not None:
        if where is not None:
            return OptionNotUsed(f"{flag} given to `{where}` does not reach `{path}`: its own "
                                 f"{_flag(own)} goes after `{path}`")
        return OptionNotUsed(f"{flag}: `{path}` does not take it; its own {_flag(own)} is another option "
                             f"(see `{path} --help`)")
    takes = [_flag(p) for p in _takes(command) if not p.hidden]
    if takes:
        return OptionNotUsed(f"{flag}: `{path}` does not use it (of the link options it takes {', '.join(takes)})")
    if any(set(p.opts) & {"-d", "--device"} for p in command.params if isinstance(p, click.Option) and not p.hidden):
        return OptionNotUsed(f"{flag}: `{path}` does not use it (see `{path} --help`)")  # devices of its own
    return OptionNotUsed(f"{flag}: `{path}` opens no device, so the option would do nothing")


def _refusing(option: click.Option, command: click.Command, free: list[str]) -> click.Option:
    """`option` on a command that does not use it, under the names `free` of the command's own: hidden, and
    refused when typed here; the first one processed also refuses link options typed at a group above that the
    command does not use."""
    flag = _flag(option)

    def refuse(ctx: click.Context, param: click.Parameter, value: Any) -> None:
        if _typed(ctx, param):
            raise _not_here(flag, command, ctx.command_path)
        for name, (given, where) in app_of(ctx).given_link_options.items():
            if not _takes(command, name):
                raise _not_here(given, command, ctx.command_path, where)

    option.opts = free
    option.hidden = True
    option.is_eager = True  # judged before the command's arguments, so the refusal is the first thing said
    option.callback = refuse
    return option


def share_options(command: click.Command, factories: Sequence[OptionFactory]) -> None:
    """Attach shared options to `command` and everything under it, skipping names a command already uses.

    A link option goes to a command that does not use it hidden: a group records it for the command below,
    any other command refuses it (see `_refusing`), also under those of its names the command has left free.
    """
    taken = {opt for param in command.params for opt in param.opts + param.secondary_opts}
    group = isinstance(command, click.Group)
    for make in factories:
        option = make()
        setting = getattr(make, "setting", None)
        free = [opt for opt in option.opts if opt not in taken]
        if len(free) < len(option.opts):
            if not free or group or setting is None:
                continue
            option = _refusing(option, command, free)  # e.g. -d of a command with its own --device
        elif setting is not None and not _uses(command, setting):
            if group:
                option.hidden = True  # recorded for the command below, which judges it
            else:
                option = _refusing(option, command, free)
        elif setting is not None:
            option.fabwire_setting = setting  # type: ignore[attr-defined]
        command.params.append(option)
        taken.update(option.opts)
    if isinstance(command, SharingGroup):
        command.shared = tuple(dict.fromkeys((*command.shared, *factories)))
    elif group:
        for sub in command.commands.values():  # type: ignore[attr-defined]
            share_options(sub, factories)


class SharingGroup(click.Group):
    """A group that hands its shared options (and a child group's own ones) to every command it resolves."""

    shared: tuple[OptionFactory, ...] = ()

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        return self.share(super().get_command(ctx, cmd_name))

    def share(self, command: click.Command | None) -> click.Command | None:
        """Give a resolved child the shared options, once."""
        if command is not None and not getattr(command, "_fabwire_shared", False):
            # a command's own options first: they win over shared ones of the same name (a simulator's --trace)
            share_options(command, (*getattr(command, "own_options", ()), *self.shared))
            command._fabwire_shared = True  # type: ignore[attr-defined]
        return command


pass_app = click.make_pass_decorator(App, ensure=True)
