"""`sim://` simulators registered by device packages, run in-process over a memory pair."""

from __future__ import annotations

import asyncio
import contextlib
import importlib
from collections.abc import Awaitable, Callable

from fabwire.checks import refuse
from fabwire.devices import KINDS
from fabwire.errors import LinkClosed, excerpt
from fabwire.transport.base import DEFAULT_READ_SIZE, Transport
from fabwire.transport.memory import memory_pair
from fabwire.transport.simaddress import SimOption, register_options

SimulatorFactory = Callable[[dict[str, str]], Awaitable[Transport]]
"""Given the URL's options, start a simulator and return the host's end of the link to it."""

DeviceServer = Callable[[Transport], Awaitable[None]]

_FACTORIES: dict[str, SimulatorFactory] = {}


def register_simulator(name: str, factory: SimulatorFactory, options: dict[str, SimOption] | None = None) -> None:
    """Make `sim://name` start `factory`; `options` is its table of options (`fabwire.transport.simaddress`), which
    every address naming it is checked against (None: any options are passed on unchecked)."""
    _FACTORIES[name] = factory
    register_options(name, options)


async def open_simulator(name: str, options: dict[str, str]) -> Transport:
    if name not in _FACTORIES and name in KINDS:
        importlib.import_module(KINDS[name].sim_module)
    factory = _FACTORIES.get(name)
    if factory is None:
        raise refuse("sim-unknown", name=excerpt(name, 20), known=", ".join(sorted(set(_FACTORIES) | set(KINDS))))
    return await factory(options)


class _HostEnd(Transport):
    """The host's end of an in-process simulator: closing it also stops the simulator task."""

    def __init__(self, inner: Transport, task: asyncio.Task[None], name: str) -> None:
        self._inner = inner
        self._task = task
        self.url = f"sim://{name}"
        self.peer = f"{name} simulator (in-process)"

    @property
    def closed(self) -> bool:
        return self._inner.closed

    async def read(self, max_bytes: int = DEFAULT_READ_SIZE) -> bytes:
        try:
            return await self._inner.read(max_bytes)
        except LinkClosed:
            self._reraise_crash()
            raise

    async def write(self, data: bytes) -> None:
        try:
            await self._inner.write(data)
        except LinkClosed:
            self._reraise_crash()
            raise

    def _reraise_crash(self) -> None:
        if self._task.done() and not self._task.cancelled() and self._task.exception() is not None:
            raise LinkClosed(f"the {self.peer} stopped: {self._task.exception()!r}")

    async def close(self) -> None:
        await self._inner.close()
        if not self._task.done():
            try:
                async with asyncio.timeout(1.0):
                    await asyncio.shield(self._task)
            except TimeoutError:
                self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError, LinkClosed):
            await self._task


async def spawn_in_process(name: str, serve: DeviceServer,
                           close: Callable[[], Awaitable[None]] | None = None) -> Transport:
    """Run `serve` on the device end of a memory pair; return the host end. `close` (the simulator's own, for one
    with tasks of its own such as a moving arm) runs when the link ends: an in-process simulator serves one link,
    and its tasks must not outlive the loop they run on."""
    host, device = memory_pair(name)

    async def run() -> None:
        try:
            await serve(device)
        except LinkClosed:
            pass
        finally:
            await device.close()
            if close is not None:
                await close()

    task = asyncio.create_task(run(), name=f"sim:{name}")
    return _HostEnd(host, task, name)
