"""Finding da Vinci printers: USB serial ports with XYZprinting's vendor id, and TCP 9100 probes.

The printers announce nothing on the network, so a host or subnet is probed with `query=a` under a
concurrency bound and a per-host timeout; only hosts answering with a status carrying a model count.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import logging
import socket
from collections.abc import Iterable
from dataclasses import dataclass

import serialx

from fabwire.errors import FabwireError, InputError, RemoteProtocolError, excerpt
from fabwire.transport.peers import FirstBytes, name_peer
from fabwire.transport.tcp import open_tcp
from fabwire.xyz import protocol as p
from fabwire.xyz.protocol import Link, Reply, ReplyReader
from fabwire.xyz.status import Status

log = logging.getLogger("fabwire.xyz")

XYZ_VID = 0x11F1
USB_MODELS = {0x2519: "da Vinci nano", 0x2520: "da Vinci 1.0 Pro"}
PORT = 9100
MAX_HOSTS = 4096


@dataclass(frozen=True, slots=True)
class Found:
    address: str
    """`/dev/ttyACM0` or `host:port`."""
    model_number: str | None
    name: str | None
    serial: str | None
    detail: str = ""


def usb_printers() -> list[Found]:
    """Serial ports whose USB vendor id is XYZprinting's (0x11F1); no port is opened."""
    found = []
    for port in serialx.list_serial_ports():
        if port.vid != XYZ_VID:
            continue
        hint = USB_MODELS.get(port.pid or 0, f"USB product 0x{port.pid or 0:04X}")
        found.append(Found(port.device, None, port.product, port.serial_number, hint))
    return found


def this_subnet() -> str | None:
    """The /24 around this computer's address on its default route (where a printer on the same Wi-Fi or LAN
    would be), e.g. "192.168.1.0/24"; None without an IPv4 route. Nothing is sent: a UDP socket's connect only
    picks the route."""
    with contextlib.suppress(OSError), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.connect(("192.0.2.1", 9))  # TEST-NET-1 (RFC 5737): any routable address picks the default route
        address = ipaddress.ip_address(sock.getsockname()[0])
        if not address.is_loopback and not address.is_unspecified:
            return str(ipaddress.ip_network(f"{address}/24", strict=False))
    return None


def hosts_in(subnet: str) -> list[str]:
    try:
        network = ipaddress.ip_network(subnet, strict=False)
    except ValueError as exc:
        raise InputError(f"bad subnet {subnet!r}: {exc}") from None
    if network.num_addresses > MAX_HOSTS:
        raise InputError(f"subnet {subnet} has {network.num_addresses} addresses; probe at most {MAX_HOSTS}")
    hosts = list(network.hosts()) or [network.network_address]
    return [str(h) for h in hosts]


@dataclass(frozen=True, slots=True)
class Missed:
    """A probed host that is not a da Vinci printer, and why (in the link's own words)."""

    address: str
    """`host:port`."""
    reason: str


async def probe(host: str, port: int = PORT, timeout: float = 1.0, *, named: bool = False) -> Found | Missed:
    """Ask one host for its status: what answered, or why no printer did (no answer within `timeout` seconds, a
    name that does not resolve, nothing listening, another kind of server, named from what it sent; a `named`
    host, one asked for by name, that said nothing is also asked what it is, as every client asks)."""
    address = f"{host}:{port}"
    heard = FirstBytes()
    event: object = None
    opened = False
    try:
        async with asyncio.timeout(timeout):
            transport = await open_tcp(host, port, timeout=timeout)
            opened = True
            try:
                reader = ReplyReader(Link.WIFI)
                query = p.Query("a")
                await transport.write(reader.send(query, 0.0, timeout))
                while event is None:
                    chunk = await transport.read()
                    heard.feed(chunk)
                    reader.receive(chunk, 0.0)
                    event = reader.next_event(0.0)
            finally:
                await transport.close()
    except TimeoutError:
        return await _not_a_printer(host, port, heard, named, f"no answer to 'query=a' within {timeout:g} s")
    except (FabwireError, OSError) as exc:
        # a link that opened and then broke (a reset, a close) was ended by a server: a named host is asked what
        return await _not_a_printer(host, port, heard, named and opened, str(exc) or type(exc).__name__)
    if not isinstance(event, Reply):
        return await _not_a_printer(host, port, heard, False,
                                    f"it answered {excerpt(str(event), 80)}, not an XYZv3 status")
    status = Status.parse(event.lines)
    if status.model_number is None:
        return _missed(address, "its status names no model number")
    model = status.model
    return Found(address, status.model_number, model.name if model else None, status.serial, status.state_name)


async def _not_a_printer(host: str, port: int, heard: FirstBytes, ask: bool, otherwise: str) -> Missed:
    """Why the peer at host:port is no printer: the server its first bytes (`heard`) name, or, with `ask` and
    nothing heard, the one its answer to a probe names (as every client names a wrong peer), else `otherwise`."""
    address = f"{host}:{port}"
    if heard or ask:
        expected = "an XYZv3 printer"
        named_peer = await name_peer(heard.data, f"tcp://{host}:{port}", expected, "xyz", address)
        if isinstance(named_peer, RemoteProtocolError):
            return _missed(address, str(named_peer).removeprefix(f"{address} is not {expected}: "))
    if heard:  # it spoke, in no language a row names: what it said is the evidence
        return _missed(address, f"it answered {excerpt(bytes(heard.data[:80]))}, which is no XYZv3 status")
    return _missed(address, otherwise)


def _missed(address: str, reason: str) -> Missed:
    log.info("%s: no printer (%s)", address, reason)
    return Missed(address, reason)


async def probe_hosts(targets: Iterable[tuple[str, int]], *, timeout: float = 1.0, concurrency: int = 64,
                      named: int = 0) -> list[Found | Missed]:
    """Probe many (host, port) targets at once, at most `concurrency` in flight; one result per target, in order.
    The first `named` targets were asked for by name (see `probe`)."""
    limit = asyncio.Semaphore(max(1, concurrency))

    async def one(index: int, host: str, port: int) -> Found | Missed:
        async with limit:
            try:
                return await probe(host, port, timeout, named=index < named)
            except Exception as exc:  # one odd host never ends a scan of the others
                return _missed(f"{host}:{port}", f"probe failed: {exc}")

    return list(await asyncio.gather(*(one(index, host, port) for index, (host, port) in enumerate(targets))))
