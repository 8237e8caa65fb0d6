"""What every device's CLI shares: the app state, -d/--trace options, opening the link, running async code."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine
from dataclasses import dataclass, field
from functools import update_wrapper
from pathlib import Path
from typing import Any, ParamSpec, TypeVar

import click

from fabwire.config import Target, resolve_target
from fabwire.console import Output
from fabwire.devices import DeviceKind
from fabwire.transport import Transport, open_transport
from fabwire.transport.faults import FaultPlan, FaultyTransport
from fabwire.transport.tap import TapTransport, TraceWriter

P = ParamSpec("P")
T = TypeVar("T")


@dataclass
class App:
    """Global options, filled in by the root group."""

    output: Output = field(default_factory=Output)
    verbose: int = 0
    debug: bool = False

    @property
    def json(self) -> bool:
        return self.output.json_mode


@dataclass
class DeviceContext:
    """A device group's options, read by its subcommands."""

    app: App
    kind: DeviceKind
    device: str | None
    trace: Path | None
    timeout: float
    faults: FaultPlan | None = None

    @property
    def output(self) -> Output:
        return self.app.output

    def target(self) -> Target:
        return resolve_target(self.device, self.kind)

    @contextlib.asynccontextmanager
    async def link(self, target: Target | None = None) -> AsyncIterator[Transport]:
        """Open the device's link, wrapped in the trace tap when --trace or -vv asks for it."""
        target = target or self.target()
        transport: Transport = await open_transport(target.endpoint, self.kind, connect_timeout=self.timeout)
        if self.faults is not None:
            transport = FaultyTransport(transport, self.faults)
        if self.trace is not None or logging.getLogger("fabwire.wire").isEnabledFor(logging.DEBUG):
            writer = None
            if self.trace is not None:
                try:
                    writer = TraceWriter.to_file(self.trace, url=transport.url, peer=transport.peer)
                except Exception:
                    await transport.close()
                    raise
            transport = TapTransport(transport, writer)
        try:
            yield transport
        finally:
            await transport.close()


def device_group(kind: DeviceKind, help_text: str) -> Callable[[Callable[..., None]], click.Group]:
    """A click group for one device kind with the shared -d/--trace/--timeout options."""

    def decorate(func: Callable[..., None]) -> click.Group:
        @click.group(name=kind.name, help=help_text)
        @click.option(
            "-d",
            "--device",
            metavar="DEVICE",
            envvar=f"FABWIRE_{kind.name.upper()}_DEVICE",
            help=f"Address (host[:port], tcp://…, /dev/tty…, sim://{kind.name}) or a configured device name.",
        )
        @click.option("--trace", type=click.Path(dir_okay=False, path_type=Path), help="Record the wire to FILE.")
        @click.option("--timeout", type=click.FloatRange(min=0.1), default=5.0, show_default=True,
                      help="Seconds to wait for the link to open.")
        @click.option("--inject", "inject", metavar="FAULTS", hidden=True,
                      help="Test aid: fault plan such as chunk=1,drop=0.01,seed=3.")
        @click.pass_context
        def group(
            ctx: click.Context, device: str | None, trace: Path | None, timeout: float, inject: str | None
        ) -> None:
            app = ctx.find_object(App) or App()
            faults = FaultPlan.parse(inject) if inject else None
            ctx.obj = DeviceContext(app, kind, device, trace, timeout, faults)
            func()

        group.__doc__ = help_text
        return group

    return decorate


def run(coro: Coroutine[Any, Any, T]) -> T:
    """Run a command's coroutine to completion on a fresh event loop."""
    return asyncio.run(coro)


def async_command(func: Callable[P, Awaitable[T]]) -> Callable[P, T]:
    """Let a click command be written as `async def`."""

    def wrapper(*args: P.args, **kwargs: P.kwargs) -> T:
        async def main() -> T:
            return await func(*args, **kwargs)

        return asyncio.run(main())

    return update_wrapper(wrapper, func)


pass_device = click.make_pass_decorator(DeviceContext)
pass_app = click.make_pass_decorator(App, ensure=True)
