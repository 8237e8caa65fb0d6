"""Serving a simulator where real clients can reach it: TCP listeners and raw ptys."""

from __future__ import annotations

import asyncio
import contextlib
import json
import signal
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click

from fabwire.errors import InputError
from fabwire.transport.registry import DeviceServer
from fabwire.transport.tcp import serve_tcp


@dataclass(frozen=True, slots=True)
class ListenAddress:
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
    if not port_text.isdigit() or int(port_text) > 65535:
        raise InputError(f"bad listen address {text!r}: port must be a number from 0 to 65535")
    return ListenAddress(host, int(port_text))


def server_options(default_port: int | None) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """--listen/--pty/--link, shared by every `fabwire sim DEVICE` command."""

    def decorate(func: Callable[..., Any]) -> Callable[..., Any]:
        hint = f" (default port {default_port})" if default_port else ""
        func = click.option("--link", type=click.Path(dir_okay=False, path_type=Path),
                            help="With --pty: also make a symlink at PATH to the pty.")(func)
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


async def serve(
    kind: str,
    handler: DeviceServer,
    *,
    listen: tuple[str, ...],
    use_pty: bool,
    link: Path | None,
    default_port: int | None,
    json_mode: bool = False,
) -> None:
    """Serve until SIGINT/SIGTERM. Each TCP connection and the pty each get their own `handler` call."""
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
    servers: list[asyncio.Server] = []
    tasks: list[asyncio.Future[None]] = []
    pty_device = None
    try:
        for text in listen:
            address = parse_listen(text, default_port or 0)
            server = await serve_tcp(handler, address.host, address.port)
            servers.append(server)
            host, port = server.sockets[0].getsockname()[:2]
            shown = f"[{host}]" if ":" in host else host
            announce(f"tcp://{shown}:{port}", kind, json_mode)
        if use_pty:
            from fabwire.transport.pty import open_pty  # POSIX only: imported when a pty is asked for

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
