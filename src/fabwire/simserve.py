"""Serving a simulator where real clients can reach it: TCP listeners and raw ptys."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import signal
import sys
from pathlib import Path

from fabwire.errors import InputError
from fabwire.lifeline import watch
from fabwire.simoptions import parse_listen, serve_settings
from fabwire.transport.base import Transport
from fabwire.transport.limits import ConnectionLimits, Farewell, plain_line
from fabwire.transport.registry import DeviceServer
from fabwire.transport.tap import FROM_DEVICE, TO_DEVICE, Direction, TapTransport, TraceWriter, escape_text
from fabwire.transport.tcp import serve_tcp

sim_log = logging.getLogger("fabwire.sim")


def announce(where: str, kind: str, json_mode: bool) -> None:
    """Say where the simulator is, on stdout, one line, flushed: scripts and tests wait for it."""
    if json_mode:
        sys.stdout.write(json.dumps({"simulator": kind, "listening": where}) + "\n")
    else:
        sys.stdout.write(f"{kind} simulator listening on {where}\n")
    sys.stdout.flush()


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
    settings = serve_settings()
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
