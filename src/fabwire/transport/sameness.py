"""Whether two device addresses reach one machine, however each was spelt.

`Endpoint.machine` folds what spelling alone changes (a host name's case, its root dot, the default port). The
same machine also answers under other names: `localhost` and `127.0.0.1`, a host name and its IP address, an
IPv4 address and its IPv6-mapped form, a serial port and the udev links to it (`/dev/serial/by-id/...`). Two
sessions on one machine would interleave their commands and take each other's jobs, so the agent asks this
module before it starts a second one.
"""

from __future__ import annotations

import concurrent.futures
import ipaddress
import os
import socket
import time

from fabwire.transport.urls import Endpoint

Machine = tuple[str, str, int, str]
"""(scheme, host, port, path), as `Endpoint.machine`."""


def _address(text: str) -> str:
    """An IP address in one form: IPv4-mapped IPv6 (`::ffff:127.0.0.1`) as its IPv4 address, no zone."""
    try:
        parsed = ipaddress.ip_address(text.split("%", 1)[0])
    except ValueError:
        return text
    mapped = getattr(parsed, "ipv4_mapped", None)
    return str(mapped or parsed)


def machine_keys(endpoint: Endpoint) -> frozenset[Machine]:
    """Every name of the machine `endpoint` reaches: its spelt form, and for TCP each address its host resolves to
    (getaddrinfo, blocking: call it off the event loop; a host that does not resolve keeps its spelt form only),
    for a serial port the device the path resolves to through its links. A `sim://` address opens a simulator of its
    own, so only the very same address (options included) is the same machine. Two endpoints reach one machine when
    their keys meet."""
    if endpoint.scheme == "sim":
        return frozenset({("sim", endpoint.url, 0, "")})  # each opens a simulator of its own: the same options twice
    keys = {endpoint.machine}
    if endpoint.scheme == "tcp":
        try:
            found = socket.getaddrinfo(endpoint.machine[1], endpoint.port, type=socket.SOCK_STREAM)
        except (OSError, UnicodeError):
            found = []
        keys.update(("tcp", _address(str(sockaddr[0])), endpoint.port, "") for *_, sockaddr in found)
    elif endpoint.scheme == "serial":
        keys.add(("serial", "", 0, os.path.realpath(endpoint.path)))
    return frozenset(keys)


RESOLVE_WAIT_S = 2.0
"""How long a check waits for host names' addresses: a resolver that does not answer must not hold a command or
the agent up (the spelt forms still count)."""


def machines_of(endpoints: list[Endpoint], seconds: float = RESOLVE_WAIT_S) -> list[frozenset[Machine]]:
    """`machine_keys` of each endpoint, resolved side by side within `seconds` in all; an endpoint whose host has
    not resolved by then keeps its spelt form only."""
    if not endpoints:
        return []
    pool = concurrent.futures.ThreadPoolExecutor(max_workers=min(16, len(endpoints)))
    try:
        futures = [pool.submit(machine_keys, endpoint) for endpoint in endpoints]
        end = time.monotonic() + seconds
        found = []
        for endpoint, future in zip(endpoints, futures, strict=True):
            try:
                found.append(future.result(timeout=max(0.0, end - time.monotonic())))
            except concurrent.futures.TimeoutError:
                found.append(frozenset({endpoint.machine}))
        return found
    finally:
        pool.shutdown(wait=False, cancel_futures=True)  # a lookup still running ends on its own


def same_machine(keys: frozenset[Machine], others: list[tuple[str, frozenset[Machine]]]) -> str | None:
    """The name among `others` (name, keys) whose machine `keys` reaches too, or None."""
    return next((name for name, theirs in others if theirs & keys), None)
