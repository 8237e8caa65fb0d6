"""The simulator command line's options: where to serve (--listen/--pty/--link) and the limits every
`fabwire sim KIND` shares (--max-connections/--idle-timeout/--trace).

Declaring them needs no event loop: the command line imports this module at every start, `fabwire.simserve` (which
serves) only when a simulator runs.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click
import msgspec

from fabwire.cli_options import App, FiniteRange
from fabwire.errors import InputError, excerpt

DEFAULT_MAX_CONNECTIONS = 32
"""Clients a simulator serves at once (`fabwire.transport.limits.ConnectionLimits`)."""
DEFAULT_IDLE_TIMEOUT = 600.0
"""Seconds without traffic before a simulator closes a connection (`fabwire.transport.limits.ConnectionLimits`)."""


class ListenAddress(msgspec.Struct, frozen=True):
    host: str
    port: int


def parse_listen(text: str, default_port: int) -> ListenAddress:
    """`HOST:PORT`, `HOST`, `:PORT` or `[v6]:PORT`; port 0 picks a free port."""
    host, port_text = text, ""
    if text.startswith("["):
        host, _, rest = text[1:].partition("]")
        port_text = rest.removeprefix(":")
    elif text.count(":") == 1:
        host, port_text = text.split(":")
    host = host or "127.0.0.1"
    if not port_text:
        return ListenAddress(host, default_port)
    if not re.fullmatch(r"[0-9]{1,5}", port_text) or int(port_text) > 65535:  # few ASCII digits: int() refuses 4,300
        raise InputError(f"bad listen address {excerpt(text, 60)}: port must be a number from 0 to 65535")
    return ListenAddress(host, int(port_text))


def server_options(default_port: int | None) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """--listen/--pty/--link, shared by every `fabwire sim DEVICE` command."""

    def decorate(func: Callable[..., Any]) -> Callable[..., Any]:
        hint = f" (default port {default_port})" if default_port else ""
        func = click.option("--link", type=click.Path(dir_okay=False, path_type=Path),
                            help="With --pty: also make a symlink FILE that points to the pty.")(func)
        func = click.option("--pty", "use_pty", is_flag=True, help="Serve on a raw pseudo-terminal.")(func)
        return click.option("--listen", "listen", multiple=True, metavar="HOST:PORT",
                            help=f"Serve on TCP{hint}; repeat for several addresses.")(func)

    return decorate


class ServeSettings(msgspec.Struct):
    """The simulator command line's shared options (`fabwire sim KIND --max-connections … --trace …`)."""

    max_connections: int = DEFAULT_MAX_CONNECTIONS
    idle_timeout: float | None = DEFAULT_IDLE_TIMEOUT
    trace: Path | None = None


def serve_settings() -> ServeSettings:
    """The shared options the running `fabwire sim` command was given; the defaults outside a command."""
    ctx = click.get_current_context(silent=True)
    app = ctx.find_object(App) if ctx is not None else None
    return ServeSettings(**app.server_options) if app is not None else ServeSettings()


def _store(name: str) -> Callable[[click.Context, click.Parameter, Any], None]:
    def callback(ctx: click.Context, param: click.Parameter, value: Any) -> None:
        app = ctx.find_object(App)
        if app is not None and ctx.get_parameter_source(param.name or "") not in (
                None, click.core.ParameterSource.DEFAULT):
            app.server_options[name] = None if name == "idle_timeout" and value == 0 else value

    return callback


SERVE_OPTIONS = (
    lambda: click.Option(["--max-connections", "shared_max_connections"], type=click.IntRange(1, 10_000),
                         expose_value=False, callback=_store("max_connections"),
                         help=f"Clients served at once; at the limit a new one replaces the quietest "
                              f"[default: {DEFAULT_MAX_CONNECTIONS}]."),
    lambda: click.Option(["--idle-timeout", "shared_idle_timeout"], type=FiniteRange(min=0), expose_value=False,
                         callback=_store("idle_timeout"),
                         help=f"Close a connection after this many seconds without traffic; 0 never "
                              f"[default: {DEFAULT_IDLE_TIMEOUT:g}]."),
    lambda: click.Option(["--trace", "shared_sim_trace"], type=click.Path(dir_okay=False, path_type=Path),
                         expose_value=False, callback=_store("trace"),
                         help="Record every connection's bytes to FILE (`>` received, `<` sent)."),
)
"""Options every `fabwire sim KIND` takes, before or after KIND."""
