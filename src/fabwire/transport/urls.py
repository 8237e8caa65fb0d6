"""Device URLs: `tcp://host:port`, bare `host[:port]`, `serial:///dev/x`, bare `/dev/x`, `sim://name?opt=v`."""

from __future__ import annotations

import ipaddress
import re
import unicodedata
from urllib.parse import quote, urlencode

import msgspec

from fabwire.checks import ASCII_BLANKS, CONTROL, INVISIBLE, MAX_PATH, NUMERIC_HOST, refuse
from fabwire.devices import DeviceKind
from fabwire.errors import InputError, excerpt

WINDOWS_PORT = re.compile(r"^COM\d{1,3}$", re.IGNORECASE)
"""`COM3`: a serial port on Windows (no host is called that)."""
_HOSTNAME = re.compile(r"^(?=.{1,253}$)[A-Za-z0-9_](?:[A-Za-z0-9_-]{0,62})(?:\.[A-Za-z0-9_-]{1,63})*\.?$")


class Endpoint(msgspec.Struct, frozen=True):
    """A parsed device address."""

    scheme: str  # "tcp", "serial" or "sim"
    host: str = ""
    port: int = 0
    path: str = ""
    options: dict[str, str] = msgspec.field(default_factory=dict)

    @property
    def url(self) -> str:
        if self.scheme == "tcp":
            host = f"[{self.host}]" if ":" in self.host else self.host
            return f"tcp://{host}:{self.port}"
        if self.scheme == "serial":
            return f"serial://{self.path}"
        query = urlencode(self.options, quote_via=quote, safe="/:,@")  # reads back as the same options
        return f"sim://{self.host}" + (f"?{query}" if query else "")

    @property
    def machine(self) -> tuple[str, str, int, str]:
        """What names one machine, however the address was spelt: a host name's case and its root dot do not
        matter (RFC 4343, RFC 1034 §3.1); two addresses with the same `machine` reach the same device."""
        host = self.host.lower().rstrip(".") if self.scheme == "tcp" else self.host
        return self.scheme, host, self.port, self.path


def _bad(text: str, code: str, **fields: object) -> InputError:
    """Rule `code`'s refusal of address `text` (`fabwire.checks.RULES`)."""
    return refuse(code, address=excerpt(text, 60), **fields)


def _port(text: str, raw: str) -> int:
    if not re.fullmatch(r"[0-9]{1,5}", raw):  # ASCII digits only, and few: int() of 5,000 digits raises
        what = "too long to be a port" if raw.isascii() and raw.isdigit() else "not a number"
        raise _bad(text, "port-digits", port=excerpt(raw, 12), what=what)
    port = int(raw)
    if not 1 <= port <= 65535:
        raise _bad(text, "port-range", port=port)
    return port


def _check_host(text: str, host: str) -> str:
    if not host:
        raise _bad(text, "no-host")
    try:
        ipaddress.ip_address(host)
    except ValueError:
        if NUMERIC_HOST.fullmatch(host):
            raise _bad(text, "ipv4-form", host=excerpt(host, 40)) from None
        if not _HOSTNAME.match(host):
            raise _bad(text, "host", host=excerpt(host, 40)) from None
    return host


def _tcp(text: str, netloc: str, kind: DeviceKind | None) -> Endpoint:
    if netloc.startswith("["):
        end = netloc.find("]")
        if end < 0:
            raise _bad(text, "bracket")
        host, rest = netloc[1:end], netloc[end + 1 :]
        if rest and not rest.startswith(":"):
            raise _bad(text, "after-bracket")
        port_text = rest[1:] if rest else ""
    elif netloc.count(":") > 1:
        host, port_text = netloc, ""  # a bare IPv6 address
    else:
        host, _, port_text = netloc.partition(":")
        if ":" in netloc and not port_text:
            raise _bad(text, "empty-port")
    _check_host(text, host)
    if port_text:
        return Endpoint("tcp", host=host, port=_port(text, port_text))
    if kind is None or kind.default_port is None:
        raise _bad(text, "no-port", kind=kind.title if kind else "this device")
    return Endpoint("tcp", host=host, port=kind.default_port)


def _serial(text: str, path: str) -> Endpoint:
    if len(path) > MAX_PATH:
        raise _bad(text, "path-too-long", length=len(path))
    return Endpoint("serial", path=path)


def parse_url(text: str, kind: DeviceKind | None = None) -> Endpoint:
    """Parse and check a device address; `kind` supplies the default TCP port for a bare host and is the kind a
    sim:// address must simulate. Every refusal is an InputError worded by its row of `fabwire.checks.RULES`: a
    sim:// address's options are checked here, by the simulator's own table (`simaddress.SIMULATORS`), so an
    address accepted here opens."""
    text = text.strip(ASCII_BLANKS)
    if not text:
        raise _bad(text, "empty")
    control = CONTROL.search(text)
    if control:
        raise _bad(text, "control", char=repr(control.group()))
    invisible = INVISIBLE.search(text)
    if invisible:
        char = invisible.group()
        raise _bad(text, "invisible", char=f"U+{ord(char):04X} ({unicodedata.name(char, 'unnamed')})")
    if text.startswith("/") or WINDOWS_PORT.match(text):
        return _serial(text, text)
    if "://" not in text:
        return _tcp(text, text, kind)
    scheme, _, rest = text.partition("://")
    scheme = scheme.lower()
    if scheme == "tcp":
        netloc = rest.rstrip("/")
        if "/" in netloc or "?" in netloc:
            raise _bad(text, "tcp-path")
        return _tcp(text, netloc, kind)
    if scheme == "serial":
        if not rest.startswith("/") and not WINDOWS_PORT.fullmatch(rest):
            raise _bad(text, "serial-path")
        return _serial(text, rest)
    if scheme == "sim":
        from fabwire.transport.simaddress import check_simulator

        name, options = check_simulator(text, kind)
        return Endpoint("sim", host=name, options=options)
    raise _bad(text, "scheme", scheme=excerpt(scheme, 20))
