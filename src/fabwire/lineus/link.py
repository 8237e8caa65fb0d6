"""Opening the link to a Line-us from the CLI: `name.local` addresses are looked up by mDNS where the host has no
mDNS resolver of its own, and the port the machine advertises is used unless one was given."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import re
import socket
from collections.abc import AsyncIterator

from fabwire.cli_support import DeviceContext
from fabwire.config import Target
from fabwire.errors import LinkError
from fabwire.lineus.discovery import resolve
from fabwire.transport import Transport

_PORT_GIVEN = re.compile(r":\d+/?$")


def _is_local(host: str) -> bool:
    return host.lower().removesuffix(".").endswith(".local")


async def resolve_target(dctx: DeviceContext) -> Target:
    """The device's target with a `.local` host replaced by the address (and, unless a port was given, the
    port) the machine advertises over mDNS; the system resolver is the fallback. LinkError when neither knows
    the name."""
    target = dctx.target()
    endpoint = target.endpoint
    if endpoint.scheme != "tcp" or not _is_local(endpoint.host):
        return target
    port_given = dctx.device is not None and bool(_PORT_GIVEN.search(dctx.device))
    wait = min(max(dctx.timeout, 1.0), 5.0)
    found = await resolve(endpoint.host, wait)
    if found is not None:
        port = endpoint.port if port_given else found.port
        return dataclasses.replace(target, endpoint=dataclasses.replace(endpoint, host=found.address, port=port))
    try:
        await asyncio.get_running_loop().getaddrinfo(endpoint.host, endpoint.port, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError):
        raise LinkError(f"{endpoint.host}: no Line-us answers to that name by mDNS within {wait:g} s and the "
                        "system cannot resolve it; is it switched on and on this network? "
                        "(`fabwire lineus discover` lists the machines it can see)") from None
    return target


@contextlib.asynccontextmanager
async def open_link(dctx: DeviceContext) -> AsyncIterator[Transport]:
    """`dctx.link()` for a Line-us, with `.local` names resolved as above."""
    async with dctx.link(await resolve_target(dctx)) as transport:
        yield transport
