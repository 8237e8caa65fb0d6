"""Where a Line-us is: `name.local` addresses are looked up by mDNS where the host has no mDNS resolver of its own,
and the port the machine advertises is used unless one was given."""

from __future__ import annotations

import asyncio
import os
import re
import socket
from pathlib import Path
from typing import Any

import msgspec

from fabwire.config import resolve_target
from fabwire.devices import LINEUS
from fabwire.errors import FabwireError, LinkError
from fabwire.lineus.discovery import resolve
from fabwire.transport.urls import Endpoint

_PORT_GIVEN = re.compile(r":\d+/?$")
MDNS_WAIT_MAX = 5.0
"""Seconds to wait for the machine's mDNS answer at most (a Line-us on the network answers in well under one)."""


def _is_local(host: str) -> bool:
    return host.lower().removesuffix(".").endswith(".local")


async def local_endpoint(endpoint: Endpoint, *, port_given: bool, wait: float) -> Endpoint:
    """`endpoint` with a `.local` host replaced by the address (and, unless `port_given`, the port) the machine
    advertises over mDNS; the system resolver is the fallback. LinkError when neither knows the name."""
    if endpoint.scheme != "tcp" or not _is_local(endpoint.host):
        return endpoint
    found = await resolve(endpoint.host, wait)
    if found is not None:
        return msgspec.structs.replace(endpoint, host=found.address, port=endpoint.port if port_given else found.port)
    try:
        await asyncio.get_running_loop().getaddrinfo(endpoint.host, endpoint.port, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError):
        raise LinkError(f"{endpoint.host}: no Line-us answers to that name by mDNS within {wait:g} s and the "
                        "system cannot resolve it; is it switched on and on this network? "
                        "(`fabwire lineus discover` lists the machines it can see)") from None
    return endpoint


async def resolve_local(target: str | None, options: dict[str, Any]) -> tuple[str | Endpoint | None, dict[str, Any]]:
    """A `LineUs.open` target and options with a `.local` name resolved (see `local_endpoint`); a configured
    device's options come along, so resolving its address loses none of them. Anything else is returned as is."""
    wanted = target if target is not None else os.environ.get("FABWIRE_LINEUS_DEVICE")
    config = options.get("config")
    try:
        found = resolve_target(wanted, LINEUS, Path(config) if config is not None else None)
    except FabwireError:
        return target, options  # opening reports it, as for any device
    if found.endpoint.scheme != "tcp" or not _is_local(found.endpoint.host):
        return target, options
    timeout = options.get("timeout") or found.options.get("timeout") or 5.0
    port_given = bool(_PORT_GIVEN.search(wanted or ""))
    endpoint = await local_endpoint(found.endpoint, port_given=port_given,
                                    wait=min(max(float(timeout), 1.0), MDNS_WAIT_MAX))
    merged = {**found.options, **{k: v for k, v in options.items() if v is not None}}
    return endpoint, merged
