"""What every device's CLI shares beyond its options (`fabwire.cli_options`): lazy groups, negative numbers as
arguments, the device context and opening devices, confirmations, running async code."""

from __future__ import annotations

import importlib
import os
import re
import sys
from collections.abc import Awaitable, Callable, Coroutine, Mapping, Sequence
from functools import update_wrapper
from typing import TYPE_CHECKING, Any, NamedTuple, ParamSpec, TypeVar

import click
import msgspec

from fabwire.cli_options import ANY, OptionFactory, SharingGroup, app_of

# the shared options, re-exported: every command imports what it uses from here
from fabwire.cli_options import DEVICE_OPTIONS as DEVICE_OPTIONS
from fabwire.cli_options import GLOBAL_OPTIONS as GLOBAL_OPTIONS
from fabwire.cli_options import LINK_OPTIONS as LINK_OPTIONS
from fabwire.cli_options import App as App
from fabwire.cli_options import FiniteRange as FiniteRange
from fabwire.cli_options import check_early_link_options as check_early_link_options
from fabwire.cli_options import configure_logging as configure_logging
from fabwire.cli_options import pass_app as pass_app
from fabwire.cli_options import uses_link_options as uses_link_options
from fabwire.console import Output
from fabwire.devices import DeviceKind
from fabwire.errors import InputError
from fabwire.extras import first_missing
from fabwire.importing import collection_paused

if TYPE_CHECKING:
    from click.shell_completion import CompletionItem

    from fabwire.config import Target

P = ParamSpec("P")
T = TypeVar("T")


def _needs_extra(name: str, missing: Exception) -> click.Command:
    """Stands in for a command whose extra is not installed: listed in help, and says what to install."""

    def fail(args: tuple[str, ...]) -> None:
        raise missing

    command = click.Command(name, callback=uses_link_options(ANY)(fail), help=f"(not installed: {missing})",
                            params=[click.Argument(["args"], nargs=-1)],
                            context_settings={"ignore_unknown_options": True, "allow_extra_args": True})
    command.short_help = str(missing).split(": ", 1)[-1]
    return command


NEGATIVE_NUMBER = re.compile(r"-(?:\.?\d.*|inf|infinity|nan)", re.IGNORECASE | re.DOTALL)
"""A token such as -5, -0.12mm, -1e3 or -inf: a value for an argument (to be judged as one), never an option."""


class NumberCommand(click.Command):
    """A command whose arguments may be negative numbers (`xyz energy -5`, `zoffset -12`) anywhere on the line.

    click reads every token that starts with `-` as an option (and `-inf` as `-i -n f`). Here the line is sorted
    first: options with their values, then `--`, then the arguments in their order, so a negative number is always
    an argument; any other token that looks like an option and is not one is refused as click would.
    """

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        options = {opt: param for param in self.get_params(ctx) if isinstance(param, click.Option)
                   for opt in (*param.opts, *param.secondary_opts)}

        def flag(name: str) -> bool:
            option = options.get(name)
            return option is not None and (option.is_flag or option.count)

        named: list[str] = []
        positional: list[str] = []
        tokens = iter(args)
        for token in tokens:
            if token == "--":
                positional.extend(tokens)
                break
            if not token.startswith("-") or token == "-" or NEGATIVE_NUMBER.fullmatch(token):
                positional.append(token)
                continue
            named.append(token)
            name = token.partition("=")[0]
            if name in options:
                value = next(tokens, None) if "=" not in token and not flag(name) else None
                if value is not None:
                    named.append(value)  # the option's value, whatever it looks like
                continue
            attached = token[:2] in options and not flag(token[:2])
            if not token.startswith("--") and (attached or all(flag(f"-{c}") for c in token[1:])):
                continue  # a short option with its value attached (-dHOST), or short flags together (-vv)
            ctx.fail(f"No such option: {name}")
        return super().parse_args(ctx, [*named, "--", *positional] if positional else named)


def _shortened(summary: str, limit: int = 45) -> str:
    """`summary` cut to `limit` characters as click cuts a command's help for a listing."""
    return click.Command(None, help=summary).get_short_help_str(limit)


class Lazy(NamedTuple):
    """A subcommand loaded only when it runs: where it lives and the line that stands for it until then.

    `target` is `module:attribute`; `summary` is the command's short help as `--help` lists it and completion
    offers it, so neither imports the module (a test holds every summary to the command's own); `extra` names the
    optional part of the install it needs (`fabwire.extras`), so a listing says what to install when it is missing.
    """

    target: str
    summary: str
    extra: str = ""


class LazyGroup(SharingGroup):
    """Loads a subcommand's module only when it runs, so `fabwire xyz status` never imports the SVG stack.

    `lazy` maps a subcommand's name to a `Lazy` (listed in help and completion without loading) or to a bare
    `module:attribute` (loaded to be listed).
    """

    command_class = NumberCommand

    def __init__(self, *args: object, lazy: Mapping[str, Lazy | str] | None = None, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self._lazy = {name: entry if isinstance(entry, Lazy) else Lazy(entry, "") for name, entry in
                      (lazy or {}).items()}

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(set(super().list_commands(ctx)) | set(self._lazy))

    def summary(self, ctx: click.Context, name: str) -> str | None:
        """A subcommand's short help in full, from the table while it is not loaded; None for a hidden one."""
        entry = self._lazy.get(name)
        if entry is not None and entry.summary and name not in self.commands:
            missing = first_missing(entry.extra) if entry.extra else None
            return entry.summary if missing is None else _needs_extra(name, missing).get_short_help_str(1 << 16)
        command = self.get_command(ctx, name)
        return None if command is None or command.hidden else command.get_short_help_str(limit=1 << 16)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, summary) for name in self.list_commands(ctx)
                if (summary := self.summary(ctx, name)) is not None]
        if rows:
            limit = formatter.width - 6 - max(len(name) for name, _ in rows)
            with formatter.section("Commands"):
                formatter.write_dl([(name, _shortened(text, limit)) for name, text in rows])

    def shell_complete(self, ctx: click.Context, incomplete: str) -> list[CompletionItem]:
        from click.shell_completion import CompletionItem  # loaded when completing, not to run a command

        items = [CompletionItem(name, help=_shortened(summary)) for name in self.list_commands(ctx)
                 if name.startswith(incomplete) and (summary := self.summary(ctx, name)) is not None]
        return [*items, *click.Command.shell_complete(self, ctx, incomplete)]

    def resolve_command(self, ctx: click.Context,
                        args: list[str]) -> tuple[str | None, click.Command | None, list[str]]:
        try:
            return super().resolve_command(ctx, args)
        except click.exceptions.NoSuchCommand as exc:  # click suggests from loaded commands only: add the lazy ones
            # the closest one only (`sevre` is `serve`, not also `service`), as a misspelt config key is answered
            import difflib  # only to suggest a command for a mistyped one

            closest = difflib.get_close_matches(exc.command_name, self.list_commands(ctx), n=1)
            raise click.exceptions.NoSuchCommand(exc.command_name, possibilities=closest, ctx=ctx) from None

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        entry = self._lazy.get(cmd_name)
        if entry is None or cmd_name in self.commands:
            return super().get_command(ctx, cmd_name)
        module_name, _, attr = entry.target.partition(":")
        try:
            with collection_paused():
                command = getattr(importlib.import_module(module_name), attr)
        except ImportError as exc:
            from fabwire.extras import missing_extra

            missing = missing_extra(exc)
            if missing is None:
                raise
            return _needs_extra(cmd_name, missing)
        if not isinstance(command, click.Command):
            raise TypeError(f"{entry.target} is not a click command")
        return self.share(command)


class DeviceContext(msgspec.Struct):
    """A device group's view of the command line, read by its subcommands."""

    app: App
    kind: DeviceKind

    @property
    def output(self) -> Output:
        return self.app.output

    @property
    def device(self) -> str | None:
        return self.app.device

    @property
    def timeout(self) -> float:
        return self.app.timeout or 5.0

    def target(self) -> Target:
        """Where the command goes (checks a device name against the config before any work starts)."""
        from fabwire.config import resolve_target

        return resolve_target(self.app.device or os.environ.get(f"FABWIRE_{self.kind.name.upper()}_DEVICE"),
                              self.kind)

    def open_options(self, **options: Any) -> dict[str, Any]:
        """The command line's link options, ready for `X.open` (unset ones leave the config's in force)."""
        return {"timeout": self.app.timeout, "trace": self.app.trace, "faults": self.app.faults,
                **self.app.link_options, **options}

    def open(self, client: Any, **options: Any) -> Any:
        """`async with dctx.open(XYZPrinter) as printer`: the library's one way to open, with the CLI's options."""
        return client.open(self.app.device, **self.open_options(**options))


def device_group(kind: DeviceKind, help_text: str, link_options: Sequence[OptionFactory] = (),
                 lazy: Mapping[str, Lazy | str] | None = None) -> Callable[[Callable[..., None]], click.Group]:
    """A click group for one device kind; the shared device options and `link_options` work at every level.

    `lazy` maps subcommand names to where they live (see `LazyGroup`), imported only when that subcommand runs.
    """

    def decorate(func: Callable[..., None]) -> click.Group:
        @click.group(name=kind.name, help=help_text, cls=LazyGroup, lazy=lazy or {})
        @uses_link_options(ANY)
        @click.pass_context
        def group(ctx: click.Context) -> None:
            ctx.obj = DeviceContext(app_of(ctx), kind)
            func()

        group.own_options = (*DEVICE_OPTIONS, *link_options)  # type: ignore[attr-defined]
        group.__doc__ = help_text
        return group

    return decorate


def on_terminal() -> bool:
    """A person can answer: standard input and standard error are both a terminal."""
    return sys.stdin.isatty() and sys.stderr.isatty()


def confirm(action: str, yes: bool) -> None:
    """Go ahead with a step that cannot be undone only when confirmed: `--yes`, or "y" typed on a terminal.

    `action` says what the step does ("cancel the running print"). Raises InputError when nobody confirmed.
    """
    if yes:
        return
    if not on_terminal():
        raise InputError(f"this would {action}: add --yes to confirm")
    try:
        agreed = click.confirm(f"{action[:1].upper()}{action[1:]}?", default=False, err=True)
    except click.Abort:
        agreed = False
    if not agreed:
        raise InputError(f"not confirmed; did not {action}")


def run(coro: Coroutine[Any, Any, T]) -> T:
    """Run a command's coroutine to completion on a fresh event loop (asyncio is imported here: a command that
    only reads and writes files, such as `xyz convert`, starts without it)."""
    import asyncio

    return asyncio.run(coro)


def async_command(func: Callable[P, Awaitable[T]]) -> Callable[P, T]:
    """Let a click command be written as `async def`."""

    def wrapper(*args: P.args, **kwargs: P.kwargs) -> T:
        async def main() -> T:
            return await func(*args, **kwargs)

        return run(main())

    return update_wrapper(wrapper, func)


_pass_device_context = click.make_pass_decorator(DeviceContext)


def pass_device(func: Callable[..., T]) -> Callable[..., T]:
    """Hand a command its `DeviceContext`; such a command opens a device, so it takes every link option."""
    return uses_link_options(ANY)(_pass_device_context(func))

