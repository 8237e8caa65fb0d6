"""Found on the network: each machine announced over mDNS/DNS-SD the way OctoPrint and Moonraker announce
themselves, so a slicer's "Browse" (PrusaSlicer's BonjourDialog, Cura's OctoPrint plugin) and Home Assistant
list the printers.

`SERVICES` is the table of what is announced, each row naming its public source. Only LAN addresses are
announced: an agent listening on loopback announces nothing (nobody else could reach it), and one listening on
every address announces its non-loopback ones.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import logging
import socket
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from fabwire import __version__
from fabwire.agent.model import MachineView

if TYPE_CHECKING:
    from zeroconf.asyncio import AsyncServiceInfo, AsyncZeroconf

    from fabwire.agent.core import Agent

log = logging.getLogger("fabwire.agent")
INSTANCE_MAX = 63
"""Bytes in a DNS-SD instance name (RFC 6763 §4.1.1)."""


def _octoprint_txt(view: MachineView, path: str) -> dict[str, str]:
    from fabwire.agent.doors.octoprint import API_VERSION, OCTOPRINT_VERSION, unique_id

    return {"path": path, "api": API_VERSION, "version": OCTOPRINT_VERSION, "model": view.model or view.kind,
            "uuid": unique_id(view), "vendor": "fabwire", "vendor_version": __version__}


def _moonraker_txt(view: MachineView, path: str) -> dict[str, str]:
    from fabwire.agent.doors.moonraker import MOONRAKER_VERSION
    from fabwire.agent.doors.octoprint import unique_id

    return {"uuid": unique_id(view), "https_port": "", "version": f"{MOONRAKER_VERSION}-fabwire",
            "route_prefix": path.strip("/")}


def _http_txt(view: MachineView, path: str) -> dict[str, str]:
    return {"path": path}


@dataclass(frozen=True, slots=True)
class Service:
    type: str
    txt: Callable[[MachineView, str], dict[str, str]]
    """The TXT record of a machine served at `path` ("/" or "/printers/NAME/")."""
    source: str


SERVICES: tuple[Service, ...] = (
    Service("_octoprint._tcp.local.", _octoprint_txt,
            "OctoPrint src/octoprint/plugins/discovery/__init__.py (TXT path, api, version, model); Cura's "
            "OctoPrint plugin reads `path` (OctoPrintOutputDevicePlugin.py)"),
    Service("_moonraker._tcp.local.", _moonraker_txt,
            "Moonraker moonraker/components/zeroconf.py (TXT uuid, https_port, version, route_prefix)"),
    Service("_http._tcp.local.", _http_txt, "RFC 6763 §7 / DNS-SD service types: the web page, TXT path"),
)


def lan_addresses(host: str) -> list[str]:
    """The addresses to announce for an agent listening on `host`: none for loopback, every non-loopback IPv4
    address of this computer for the wildcard, else `host` itself."""
    try:
        ip = ipaddress.ip_address(host.strip("[]"))
    except ValueError:
        try:
            ip = ipaddress.ip_address(socket.gethostbyname(host))
        except OSError:
            return []
    if ip.is_loopback or (ip.version == 6 and not ip.is_unspecified):
        return []  # IPv6 announcements are not made (the zeroconf registration here is IPv4)
    if not ip.is_unspecified:
        return [str(ip)]
    import ifaddr

    found = []
    for adapter in ifaddr.get_adapters():
        for address in adapter.ips:
            if isinstance(address.ip, str) and not ipaddress.ip_address(address.ip).is_loopback:
                found.append(address.ip)
    return found


def instance_name(view: MachineView, host_name: str) -> str:
    name = f"{view.name} on {host_name}"
    while len(name.encode()) > INSTANCE_MAX:
        name = name[:-1]
    return name.replace(".", "-")


class Advertiser:
    """The services of every machine, registered on the LAN addresses of the agent's listening socket."""

    def __init__(self, agent: Agent, host: str, port: int) -> None:
        self.agent = agent
        self.port = port
        self.addresses = lan_addresses(host)
        self._zeroconf: AsyncZeroconf | None = None
        self._registered: dict[str, AsyncServiceInfo] = {}
        """The announced services by the instance name they were asked for."""
        self._watcher: asyncio.Task[None] | None = None

    def infos(self) -> list[AsyncServiceInfo]:
        from zeroconf.asyncio import AsyncServiceInfo

        host_name = socket.gethostname().split(".")[0] or "fabwire"
        machines = self.agent.library.machines
        default = machines.default()
        infos = []
        for view in machines.all():
            if not view.takes_jobs:
                continue  # an MMU is no printer: a slicer listing it could send it nothing
            paths = [f"/printers/{view.name}/"] + (["/"] if default is not None and default.id == view.id else [])
            name = instance_name(view, host_name)
            for service in SERVICES:
                info = AsyncServiceInfo(
                    service.type, f"{name}.{service.type}", port=self.port,
                    addresses=[socket.inet_aton(a) for a in self.addresses],
                    properties=service.txt(view, paths[-1]), server=f"{host_name}.local.")
                infos.append(info)
        return infos

    async def start(self) -> None:
        """Announce every machine now, and a machine added later when it first comes online."""
        if not self.addresses:
            return
        from zeroconf import IPVersion
        from zeroconf.asyncio import AsyncZeroconf

        self._zeroconf = AsyncZeroconf(interfaces=self.addresses, ip_version=IPVersion.V4Only)
        await self.resync()
        self._watcher = asyncio.create_task(self._watch(), name="advertise")

    async def resync(self) -> None:
        """Register the services of machines not announced yet; withdraw those of machines gone."""
        if self._zeroconf is None:
            return
        wanted = {info.name: info for info in self.infos()}
        for name in [n for n in self._registered if n not in wanted]:
            with contextlib.suppress(Exception):
                await self._zeroconf.async_unregister_service(self._registered.pop(name))
        for name, info in wanted.items():
            if name in self._registered:
                continue
            try:  # on a name clash zeroconf picks another instance name; it stays filed under the one wanted
                await self._zeroconf.async_register_service(info, allow_name_change=True)
                self._registered[name] = info
            except Exception as exc:  # a dead interface must not stop the agent
                log.warning("cannot announce %s: %s", info.name, exc)

    async def _watch(self) -> None:
        subscription = self.agent.subscribe()
        try:
            async for event in subscription:
                if event["type"] == "online":
                    await self.resync()
        finally:
            subscription.close()

    async def stop(self) -> None:
        if self._watcher is not None:
            self._watcher.cancel()
            with contextlib.suppress(BaseException):
                await self._watcher
        zeroconf, self._zeroconf = self._zeroconf, None
        if zeroconf is None:
            return
        try:
            await zeroconf.async_unregister_all_services()
        finally:
            await zeroconf.async_close()

    def announced(self) -> list[dict[str, Any]]:
        """What is announced: `{"type", "name", "addresses", "port", "txt"}` per service."""
        return [{"type": i.type, "name": i.name, "addresses": self.addresses, "port": self.port,
                 "txt": {k.decode(): (v or b"").decode() for k, v in i.properties.items()}}
                for i in self._registered.values()]
