"""Device URLs: `tcp://host:port`, bare `host[:port]`, `serial:///dev/x`, bare `/dev/x`, `sim://name?opt=v`."""

from __future__ import annotations

import ipaddress
import re
from urllib.parse import parse_qsl, urlsplit

import msgspec

from fabwire.devices import DeviceKind
from fabwire.errors import InputError, excerpt

_WINDOWS_PORT = re.compile(r"^COM\d{1,3}$", re.IGNORECASE)
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
        query = "&".join(f"{k}={v}" for k, v in self.options.items())
        return f"sim://{self.host}" + (f"?{query}" if query else "")


def _bad(text: str, why: str) -> InputError:
    return InputError(
        f"malformed device address {excerpt(text, 60)}: {why} "
        "(use host, host:port, tcp://host:port, /dev/ttyX, serial:///dev/ttyX or sim://name)"
    )


def _port(text: str, raw: str) -> int:
    if not re.fullmatch(r"[0-9]{1,5}", raw):  # ASCII digits only, and few: int() of 5,000 digits raises
        shown = excerpt(raw, 12)
        what = "too long to be a port" if raw.isascii() and raw.isdigit() else "not a number"
        raise _bad(text, f"port {shown} is {what}")
    port = int(raw)
    if not 1 <= port <= 65535:
        raise _bad(text, f"port {port} is outside 1-65535")
    return port


def _check_host(text: str, host: str) -> str:
    if not host:
        raise _bad(text, "no host name")
    try:
        ipaddress.ip_address(host)
    except ValueError:
        if not _HOSTNAME.match(host):
            raise _bad(text, f"{excerpt(host, 40)} is not a valid host name or IP address") from None
    return host


def _tcp(text: str, netloc: str, kind: DeviceKind | None) -> Endpoint:
    if netloc.startswith("["):
        end = netloc.find("]")
        if end < 0:
            raise _bad(text, "unclosed '[' in IPv6 address")
        host, rest = netloc[1:end], netloc[end + 1 :]
        if rest and not rest.startswith(":"):
            raise _bad(text, "unexpected text after ']'")
        port_text = rest[1:] if rest else ""
    elif netloc.count(":") > 1:
        host, port_text = netloc, ""  # a bare IPv6 address
    else:
        host, _, port_text = netloc.partition(":")
        if ":" in netloc and not port_text:
            raise _bad(text, "empty port after ':'")
    _check_host(text, host)
    if port_text:
        return Endpoint("tcp", host=host, port=_port(text, port_text))
    if kind is None or kind.default_port is None:
        name = kind.title if kind else "this device"
        raise _bad(text, f"no port given and {name} has no default TCP port")
    return Endpoint("tcp", host=host, port=kind.default_port)


def parse_url(text: str, kind: DeviceKind | None = None) -> Endpoint:
    """Parse a device address; `kind` supplies the default TCP port for a bare host."""
    text = text.strip()
    if not text:
        raise _bad(text, "it is empty")
    if text.startswith("/") or _WINDOWS_PORT.match(text):
        return Endpoint("serial", path=text)
    if "://" not in text:
        return _tcp(text, text, kind)
    scheme, _, rest = text.partition("://")
    scheme = scheme.lower()
    if scheme == "tcp":
        netloc = rest.rstrip("/")
        if "/" in netloc or "?" in netloc:
            raise _bad(text, "a tcp:// address takes no path or options")
        return _tcp(text, netloc, kind)
    if scheme == "serial":
        if not rest.startswith("/"):
            raise _bad(text, "a serial:// address needs an absolute device path, e.g. serial:///dev/ttyACM0")
        return Endpoint("serial", path=rest)
    if scheme == "sim":
        parts = urlsplit(text)
        name = parts.netloc or (kind.name if kind else "")
        if not name:
            raise _bad(text, "no simulator name")
        if parts.path not in ("", "/"):
            raise _bad(text, "a sim:// address takes no path")
        try:
            options = dict(parse_qsl(parts.query, keep_blank_values=True, strict_parsing=bool(parts.query)))
        except ValueError:
            raise _bad(text, f"unreadable options {excerpt(parts.query, 40)}") from None
        return Endpoint("sim", host=name, options=options)
    raise _bad(text, f"unknown scheme {excerpt(scheme, 20)}")
