"""One way to open every device, shared by the library, the CLI and the agent.

    async with XYZPrinter.open("office") as printer: ...          # a name from devices.toml
    printer = await LineUs.open("line-us.local", lookahead=True)   # an address; close it yourself
    with MMU.open_sync("sim://mmu", speed=50) as mmu: mmu.load(2)  # plain scripts

The target is an address (`host[:port]`, `tcp://…`, `/dev/tty…`, `serial://…`, `sim://kind?…`), a configured
device name, None (the kind's default device, or $FABWIRE_<KIND>_DEVICE), or an open `Transport`. Options are
`timeout` (seconds to open the link), `trace` (record the wire to a file), `config` (another devices.toml) and the
kind's settings from the config schema (`fabwire.config`); explicit options win over the configured ones.
Closing the client closes the link, including a transport you passed in.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Awaitable, Callable, Coroutine, Generator
from pathlib import Path
from types import TracebackType
from typing import Any, Generic, Protocol, Self, TypeVar

import msgspec

from fabwire.config import AnySettings, Target, resolve_target, validate_settings
from fabwire.devices import DeviceKind
from fabwire.errors import LinkError
from fabwire.sync import LoopThread
from fabwire.transport.base import Transport
from fabwire.transport.faults import FaultPlan, FaultyTransport
from fabwire.transport.tap import TapTransport, TraceWriter
from fabwire.transport.urls import Endpoint

log = logging.getLogger("fabwire.link")

T = TypeVar("T")


class Closable(Protocol):
    async def close(self) -> None: ...


C = TypeVar("C", bound=Closable)
DeviceTarget = str | Endpoint | Transport | None


class DeviceLink(msgspec.Struct):
    """What a client needs to (re)open its link: the resolved address, its settings and the wrappers."""

    kind: DeviceKind
    settings: AnySettings
    endpoint: Endpoint | None = None
    """None when the caller handed over an open transport (nothing to reconnect to)."""
    name: str = ""
    trace: Path | None = None
    faults: FaultPlan | None = None
    _writer: TraceWriter | None = None

    @property
    def timeout(self) -> float:
        return self.settings.timeout

    @property
    def address(self) -> str | None:
        return self.endpoint.url if self.endpoint is not None else None

    async def connect(self) -> Transport:
        """Open the link to the endpoint, wrapped in the fault injector and trace tap when asked for."""
        from fabwire.transport import open_transport

        if self.endpoint is None:
            raise LinkError(f"no address to reconnect the {self.kind.title} to")
        where = self.endpoint.url + (f" ({self.name})" if self.name else "")
        log.info("connecting to %s", where)
        began = time.monotonic()
        transport = await open_transport(self.endpoint, self.kind, connect_timeout=self.timeout)
        log.info("connected to %s in %.0f ms", where, (time.monotonic() - began) * 1000)
        return self.wrap(transport)

    reopen = connect
    """A client that loses its link (the da Vinci 1.1 Plus hangs up after every reply) calls this."""

    def wrap(self, transport: Transport) -> Transport:
        if self.faults is not None:
            transport = FaultyTransport(transport, self.faults)
        if self.trace is not None or logging.getLogger("fabwire.wire").isEnabledFor(logging.DEBUG):
            if self.trace is not None and self._writer is None:
                self._writer = TraceWriter.to_file(self.trace, url=transport.url, peer=transport.peer,
                                                   device=self.kind.name)
            transport = TapTransport(transport, self._writer)
        return transport


def plan_link(kind: DeviceKind, target: DeviceTarget, options: dict[str, Any]) -> DeviceLink:
    """Resolve the target (config names, the default device) and merge configured and explicit settings."""
    options = {k: v for k, v in options.items() if v is not None}
    trace = options.pop("trace", None)
    faults = options.pop("faults", None)
    config = options.pop("config", None)
    name = ""
    endpoint: Endpoint | None = None
    configured: dict[str, Any] = {}
    if isinstance(target, Endpoint):
        endpoint = target
    elif not isinstance(target, Transport):
        wanted = target if target is not None else os.environ.get(f"FABWIRE_{kind.name.upper()}_DEVICE")
        found: Target = resolve_target(wanted, kind, Path(config) if config is not None else None)
        endpoint, name, configured = found.endpoint, found.name, dict(found.options)
    settings = validate_settings(kind, {**configured, **options})
    return DeviceLink(kind, settings, endpoint, name, Path(trace) if trace is not None else None, faults)


Builder = Callable[[Transport, DeviceLink], Awaitable[C]]


class Opening(Generic[C]):
    """What `X.open(...)` returns: await it for the client, or use it as `async with` to close it afterwards."""

    def __init__(self, kind: DeviceKind, target: DeviceTarget, options: dict[str, Any], build: Builder[C]) -> None:
        self._kind = kind
        self._target = target
        self._options = options
        self._build = build
        self._client: C | None = None

    async def open(self) -> C:
        link = plan_link(self._kind, self._target, self._options)
        if isinstance(self._target, Transport):
            transport = link.wrap(self._target)
        else:
            transport = await link.connect()
        try:
            return await self._build(transport, link)
        except BaseException:
            await transport.close()
            raise

    def __await__(self) -> Generator[Any, None, C]:
        return self.open().__await__()

    async def __aenter__(self) -> C:
        self._client = await self.open()
        return self._client

    async def __aexit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                        tb: TracebackType | None) -> None:
        client, self._client = self._client, None
        if client is not None:
            await client.close()


class SyncClient(Generic[C]):
    """Base of the blocking facades: the async client runs on a private event-loop thread.

    Subclasses spell out each operation with its real signature, so editors complete them and mypy checks them.
    """

    def __init__(self, opening: Opening[C], *, thread_name: str = "fabwire") -> None:
        self._loop = LoopThread(thread_name)
        try:
            self.client: C = self._loop.call(opening.open())
        except BaseException:
            self._loop.close()
            raise

    def _call(self, coro: Coroutine[Any, Any, T], timeout: float | None = None) -> T:
        return self._loop.call(coro, timeout)

    def close(self) -> None:
        try:
            self._loop.call(self.client.close(), timeout=10)
        finally:
            self._loop.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

