"""Serving a simulator where real clients can reach it: TCP listeners and raw ptys."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import re
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click
import msgspec

from fabwire.cli_support import App, FiniteRange
from fabwire.errors import InputError, excerpt
from fabwire.lifeline import watch
from fabwire.transport.base import Transport
from fabwire.transport.limits import (
    DEFAULT_IDLE_TIMEOUT,
    DEFAULT_MAX_CONNECTIONS,
    ConnectionLimits,
    Farewell,
    plain_line,
)
from fabwire.transport.registry import DeviceServer
from fabwire.transport.tap import FROM_DEVICE, TO_DEVICE, Direction, TapTransport, TraceWriter, escape_text
from fabwire.transport.tcp import serve_tcp

sim_log = logging.getLogger("fabwire.sim")


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


def announce(where: str, kind: str, json_mode: bool) -> None:
    """Say where the simulator is, on stdout, one line, flushed: scripts and tests wait for it."""
    if json_mode:
        sys.stdout.write(json.dumps({"simulator": kind, "listening": where}) + "\n")
    else:
        sys.stdout.write(f"{kind} simulator listening on {where}\n")
    sys.stdout.flush()


class ServeSettings(msgspec.Struct):
    """The simulator command line's shared options (`fabwire sim KIND --max-connections … --trace …`)."""

    max_connections: int = DEFAULT_MAX_CONNECTIONS
    idle_timeout: float | None = DEFAULT_IDLE_TIMEOUT
    trace: Path | None = None


def _settings() -> ServeSettings:
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


class _SimTap(TapTransport):
    """The tap on the device's end: what it reads went to the device (`>`); with -v, one log line per chunk."""

    def _record(self, direction: Direction, data: bytes) -> None:
        direction = FROM_DEVICE if direction == TO_DEVICE else TO_DEVICE
        super()._record(direction, data)
        if direction == TO_DEVICE and sim_log.isEnabledFor(logging.INFO):
            shown = escape_text(data[:120]) + (f"… ({len(data)} bytes)" if len(data) > 120 else "")
            sim_log.info("%s > %s", self.peer, shown)


def observed(handler: DeviceServer, writer: TraceWriter | None) -> DeviceServer:
    """`handler` with each connection logged (-v) and recorded (--trace), when asked for."""
    if writer is None and not sim_log.isEnabledFor(logging.INFO):
        return handler

    async def run(link: Transport) -> None:
        sim_log.info("client %s connected", link.peer or link.url)
        if writer is not None:
            writer.event("connect", link.peer or link.url)
        try:
            await handler(_SimTap(link, writer, log=False))
        finally:
            sim_log.info("client %s gone", link.peer or link.url)

    return run


async def serve(
    kind: str,
    handler: DeviceServer,
    *,
    listen: tuple[str, ...],
    use_pty: bool,
    link: Path | None,
    default_port: int | None,
    json_mode: bool = False,
    farewell: Farewell = plain_line,
) -> None:
    """Serve until SIGINT/SIGTERM, or until the parent that started this process ends (`fabwire.lifeline`).
    Each TCP connection and the pty each get their own `handler` call.

    The connection limit, idle timeout and trace file come from the `fabwire sim` command line (SERVE_OPTIONS);
    `farewell` words, in the device's protocol, why the limit closes a client (`fabwire.transport.limits`).
    """
    from fabwire.logsink import log_in_background  # only serving needs the writer thread

    log_in_background()  # a stderr nobody reads must not freeze the simulator
    settings = _settings()
    limits = ConnectionLimits(settings.max_connections, settings.idle_timeout)
    writer = (TraceWriter.to_file(settings.trace, url=f"sim://{kind}", peer="clients", device=kind)
              if settings.trace else None)
    handler = observed(handler, writer)
    if not listen and not use_pty:
        if default_port is None:
            raise InputError("say where to serve: --pty, or --listen HOST:PORT")
        listen = (f"127.0.0.1:{default_port}",)
    if link is not None and not use_pty:
        raise InputError("--link goes with --pty")
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    watch(lambda: loop.call_soon_threadsafe(stop.set))  # a parent that started us as its child: stop with it
    servers: list[asyncio.Server] = []
    tasks: list[asyncio.Future[None]] = []
    pty_device = None
    try:
        for text in listen:
            address = parse_listen(text, default_port or 0)
            server = await serve_tcp(handler, address.host, address.port, limits=limits, what=f"{kind} simulator",
                                    farewell=farewell)
            servers.append(server)
            host, port = server.sockets[0].getsockname()[:2]
            shown = f"[{host}]" if ":" in host else host
            announce(f"tcp://{shown}:{port}", kind, json_mode)
        if use_pty:
            try:
                from fabwire.transport.pty import open_pty  # POSIX only: imported when a pty is asked for
            except ImportError:
                raise InputError("--pty needs a POSIX system (Linux, macOS): serve on TCP with --listen") from None

            pty_device = open_pty(link)
            tasks.append(asyncio.ensure_future(handler(pty_device.transport)))
            where = f"{pty_device.path}" + (f" (link {link})" if link else "")
            announce(where, kind, json_mode)
        await stop.wait()
    finally:
        for server in servers:
            server.close()
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(BaseException):
                await task
        if pty_device is not None:
            await pty_device.close()
        for server in servers:
            with contextlib.suppress(Exception):
                async with asyncio.timeout(1):
                    await server.wait_closed()
        if writer is not None:
            writer.close()
