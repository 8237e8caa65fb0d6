"""mDNS for Line-us: browse for `_lineus._tcp.local.` as the official module does, and advertise a simulator
the way the robot advertises itself."""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from zeroconf import ServiceInfo
    from zeroconf.asyncio import AsyncZeroconf

SERVICE_TYPE = "_lineus._tcp.local."


@dataclass(frozen=True, slots=True)
class Found:
    name: str
    """The machine name (the SRV target without `.local.`)."""
    host: str
    """The SRV target, e.g. `line-us.local.`."""
    address: str
    port: int

    @property
    def endpoint(self) -> str:
        return f"{self.address}:{self.port}"


async def discover(timeout: float = 3.0, *, interfaces: Sequence[str] | None = None) -> list[Found]:
    """Browse for `timeout` seconds and return every machine that answered, sorted by name.

    `interfaces` limits the multicast sockets (e.g. ["127.0.0.1"]); default: all interfaces.
    """
    found = await _browse(timeout, interfaces, lambda _: False)
    return sorted(found, key=lambda f: (f.name, f.address, f.port))


async def resolve(host: str, timeout: float = 3.0, *, interfaces: Sequence[str] | None = None) -> Found | None:
    """The machine advertising itself as `host` (`name.local`, SRV target or instance name), by mDNS alone, so
    `.local` names work on hosts without a system mDNS resolver; None if none answers within `timeout` s."""
    wanted = host.lower().removesuffix(".").removesuffix(".local")
    found = await _browse(timeout, interfaces, lambda f: f.name.lower() == wanted)
    return next((f for f in found if f.name.lower() == wanted), None)


async def _browse(timeout: float, interfaces: Sequence[str] | None, enough: Callable[[Found], bool]) -> list[Found]:
    """Machines answering within `timeout` s; stops early once `enough(found)` holds for one of them."""
    from zeroconf import ServiceStateChange, Zeroconf
    from zeroconf.asyncio import AsyncServiceBrowser, AsyncServiceInfo, AsyncZeroconf

    names: list[str] = []

    def on_change(zeroconf: Zeroconf, service_type: str, name: str, state_change: ServiceStateChange) -> None:
        if state_change in (ServiceStateChange.Added, ServiceStateChange.Updated) and name not in names:
            names.append(name)

    azc = AsyncZeroconf(interfaces=list(interfaces)) if interfaces else AsyncZeroconf()
    found: dict[str, Found] = {}
    asked: set[str] = set()
    loop = asyncio.get_running_loop()
    try:
        browser = AsyncServiceBrowser(azc.zeroconf, [SERVICE_TYPE], handlers=[on_change])
        try:
            deadline = loop.time() + timeout
            while loop.time() < deadline:
                for name in [n for n in names if n not in asked]:
                    asked.add(name)
                    info = AsyncServiceInfo(SERVICE_TYPE, name)
                    if await info.async_request(azc.zeroconf, 1000) and (entry := _entry(info, name)) is not None:
                        found[name] = entry
                        if enough(entry):
                            return list(found.values())
                await asyncio.sleep(0.05)
        finally:
            await browser.async_cancel()
    finally:
        with contextlib.suppress(Exception):
            await azc.async_close()
    return list(found.values())


def _entry(info: ServiceInfo, name: str) -> Found | None:
    addresses = [str(ipaddress.ip_address(raw)) for raw in info.addresses if len(raw) == 4]
    if not addresses or info.port is None:
        return None
    server = info.server or name
    label = server.removesuffix(".").removesuffix(".local")
    return Found(label, server, addresses[0], info.port)


class Advertiser:
    """Publishes `_lineus._tcp.local.` for a listening simulator, as the robot does."""

    def __init__(self, name: str, host: str, port: int) -> None:
        self.name, self.host, self.port = name, host, port
        self._zc: AsyncZeroconf | None = None
        self._info: ServiceInfo | None = None

    async def start(self) -> None:
        import socket

        from zeroconf import ServiceInfo
        from zeroconf.asyncio import AsyncZeroconf

        if self.host in ("0.0.0.0", ""):
            # Listening everywhere: publish this host's own IPv4 addresses.
            found = socket.gethostbyname_ex(socket.gethostname())[2]
            addresses = [a for a in found if not a.startswith("127.")] or ["127.0.0.1"]
        else:
            addresses = [self.host]
        loopback = all(a.startswith("127.") or a == "::1" for a in addresses)
        zc = AsyncZeroconf(interfaces=addresses) if loopback else AsyncZeroconf()
        info = ServiceInfo(
            SERVICE_TYPE, f"{self.name}._lineus._tcp.local.",
            addresses=[socket.inet_pton(socket.AF_INET6 if ":" in a else socket.AF_INET, a) for a in addresses],
            port=self.port, server=f"{self.name}.local.",
        )
        await zc.async_register_service(info)
        self._zc, self._info = zc, info

    async def stop(self) -> None:
        if self._zc is not None and self._info is not None:
            with contextlib.suppress(Exception):
                await self._zc.async_unregister_service(self._info)
            await self._zc.async_close()
        self._zc = self._info = None
