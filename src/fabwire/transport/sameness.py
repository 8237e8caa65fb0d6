"""Whether two device addresses reach one machine, however each was spelt.

`Endpoint.machine` folds what spelling alone changes (a host name's case, its root dot, the default port). The
same machine also answers under other names: `localhost` and `127.0.0.1`, a host name and its IP address, an
IPv4 address and its IPv6-mapped form, a serial port and the udev links to it (`/dev/serial/by-id/...`). Two
sessions on one machine would interleave their commands and take each other's jobs, so the agent asks this
module before it starts a second one.
"""

from __future__ import annotations

import ipaddress
import os
import socket

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
