"""What other machines and servers say on a connection, so a client pointed at the wrong port names what it found
instead of waiting out its reply timeout and calling the link dead.

Each row of `FOREIGN` is something a peer sends first (a greeting), in answer to a line it does not understand, or
in answer to one of the `PROBES`, with its public source. Only the first `HEAD_BYTES` bytes a peer sent are looked
at, however they were cut into reads (`FirstBytes` gathers them): a verdict is given once those bytes are
conclusive (they match a row, or can no longer become one), and at the latest when `HEAD_BYTES` have come or the
client stops waiting (`final`). A peer that said nothing before it closed the link or let the client's timeout pass
is asked again on a fresh TCP connection with each probe in turn (`probe`).
"""

from __future__ import annotations

import contextlib
import functools
import re
from typing import TYPE_CHECKING, NamedTuple

from fabwire.errors import LinkError, RemoteProtocolError, excerpt

if TYPE_CHECKING:
    import regex

HEAD_BYTES = 256
"""How much of what a peer says first is kept and looked at: every signature is decided within it."""
PROBE_SECONDS = 1.0
"""How long one probe waits for its answer to start, and for each next piece while what came is not yet conclusive
(a peer that answers does so at once)."""
PROBE_LIMIT = 6.0
"""The longest one probe listens, however slowly a peer trickles its answer."""


class Foreign(NamedTuple):
    name: str
    """The row's short name ("ssh", "html")."""
    what: str
    """The peer, as a message names it ("a Line-us drawing robot")."""
    kind: str
    """fabwire's device kind when it is one of ours ("lineus"), else "": a client never takes its own kind of
    machine for a foreign one."""
    said: bytes
    """What the peer's first bytes start with: a regular expression."""
    source: str
    nocase: bool = False
    """Whether letters match in either case (HTML, header names)."""

    @property
    def pattern(self) -> re.Pattern[bytes]:
        """`said`, compiled."""
        return _compiled(self.said, self.nocase)

    @property
    def partial(self) -> regex.Pattern[bytes]:
        """`said`, compiled to also tell a start that may still become a match (`partial=True`)."""
        return _partially(self.said, self.nocase)


@functools.cache
def _compiled(said: bytes, nocase: bool) -> re.Pattern[bytes]:
    return re.compile(said, re.IGNORECASE if nocase else 0)


@functools.cache
def _partially(said: bytes, nocase: bool) -> regex.Pattern[bytes]:
    import regex  # only once some row matches: a machine's own replies never need it

    return regex.compile(said, regex.IGNORECASE if nocase else 0)


_STATUS_LINE = rb"HTTP/[0-9](?:\.[0-9])? [1-5][0-9][0-9]"

FOREIGN: tuple[Foreign, ...] = (
    Foreign("lineus", "a Line-us drawing robot", "lineus", rb'hello VERSION:|error INFO:"',
            "Line-us G-code spec (github.com/Line-us/Line-us-Programming, GCodeSpec.md): on connect the robot sends "
            "`hello VERSION:… NAME:… SERIAL:…`; a command it cannot run gets `error INFO:\"…\"`"),
    Foreign("xyz", "an XYZv3 printer", "xyz",
            rb"(?:[A-Za-z0-9]:[^\r\n]{0,200}\r?\n){2}|E[0-9]{1,3}\$\r?\n",
            "XYZv3 protocol as documented by miniMover (github.com/reckdo/miniMover, xyzv3.cpp): a `query=a` reply is "
            "one `letter:value` line per item (`b:20`, `j:9511,0` …) ending in `$`; a refused command gets `E<n>$`"),
    Foreign("mmu", "a Prusa MMU3", "mmu",
            rb"[A-Z][0-9a-f]{1,4}(?: [0-9a-f]{1,4})? [ABEFPR][0-9a-f]{0,4}\*[0-9a-f]{1,2}\n",
            "Prusa-Firmware-MMU src/modules/protocol.cpp (EncodeResponse…): a response repeats the request's code and "
            "value, then its status letter and value, then `*` and a CRC-8 in hex (`S0 A3*22`)"),
    Foreign("agent", "fabwire's agent, `fabwire serve`", "",
            _STATUS_LINE + rb"[^\r\n]*\r?\n(?:[!#-9;-~]+:[^\r\n]*\r?\n)*?server: *fabwire\b",
            "RFC 9110 §10.2.4: the Server header names the origin server's software; fabwire's agent sends "
            "`server: fabwire/<version>` with every answer, its refusals of requests it cannot read included",
            nocase=True),
    Foreign("http", "a web server", "", _STATUS_LINE,
            "RFC 9112 §4: a response starts with its status line; a line that is no request gets 400 (Moonraker for "
            "Klipper, OctoPrint, nginx, uvicorn …)"),
    Foreign("html", "a web server", "", rb"[\t\n\r ]*(?:<!doctype html|<html)",
            "RFC 1945 §4.1 (HTTP/0.9 simple response: the body alone, no status line, as Python's http.server "
            "answers a one-word line) and WHATWG HTML §13.1: a document starts with `<!DOCTYPE html>` or `<html`",
            nocase=True),
    Foreign("ssh", "an SSH server", "", rb"SSH-[12]\.[0-9]+-",
            "RFC 4253 §4.2: the identification string `SSH-protoversion-softwareversion` comes first"),
    Foreign("ftp-smtp", "an FTP or mail server", "", rb"220[ -]",
            "RFC 959 §5.4 and RFC 5321 §4.2: the server greets with reply code 220"),
    Foreign("pop3", "a mail server", "", rb"\+OK[ \r\n]",
            "RFC 1939 §4: a POP3 server greets with a positive response, `+OK`"),
    Foreign("imap", "a mail server", "", rb"\* (?:OK|PREAUTH)[ \r\n]",
            "RFC 9051 §7.1: an IMAP server greets with an untagged `* OK` (or `* PREAUTH`)"),
    Foreign("telnet", "a Telnet server", "", rb"\xff[\xfb-\xfe]",
            "RFC 854: option negotiation, IAC (255) then WILL/WONT/DO/DONT"),
    Foreign("vnc", "a VNC server", "", rb"RFB [0-9]{3}\.[0-9]{3}\n",
            "RFC 6143 §7.1.1: the server sends its ProtocolVersion, `RFB 003.008\\n`, first"),
    Foreign("redis", "a Redis server", "", rb"-(?:ERR|WRONGTYPE|NOAUTH) ",
            "Redis serialization protocol (redis.io/docs/latest/develop/reference/protocol-spec): an inline command "
            "it does not know gets a simple error, `-ERR unknown command …`"),
    Foreign("mqtt", "an MQTT broker", "", rb"\x20\x02[\x00\x01][\x00-\x05]",
            "MQTT 3.1.1 §3.2 (OASIS): a broker answers CONNECT with CONNACK, 0x20 0x02, the session-present flag "
            "and a return code 0-5 (a broker such as Mosquitto drops a connection whose first packet is no CONNECT)"),
    Foreign("marlin", "a Marlin or Prusa-firmware 3D printer", "",
            rb"start\r?\n|echo:|Error:|ok T:|// action:",
            "Marlin firmware (MarlinCore.cpp, language.h): `start` after a reset, informational lines after "
            "SERIAL_ECHO_START (`echo:`, as `echo:Unknown command:`), `Error:` for a bad line, `ok T:` temperatures, "
            "`// action:` host actions"),
)
"""Peers a client may reach by mistake, by what they say, most specific first."""


class Probe(NamedTuple):
    kind: str
    """The device kind whose opening words these are ("" for none): not sent by a client of that kind, which has
    just said them itself."""
    says: bytes
    source: str


PROBES: tuple[Probe, ...] = (
    Probe("mqtt", b"\x10\x0c\x00\x04MQTT\x04\x02\x00\x3c\x00\x00",
          "MQTT 3.1.1 §3.1: CONNECT, protocol level 4, clean session, 60 s keep-alive, empty client id"),
    Probe("", b"HEAD / HTTP/1.0\r\n\r\n", "RFC 9110 §9.3.2: HEAD, an answer without a body"),
    Probe("xyz", b"XYZv3/query=a\n", "XYZv3 (miniMover xyzv3.cpp): the status query every XYZware session opens with"),
    Probe("mmu", b"S0*c6\n", "Prusa-Firmware-MMU protocol.cpp: S0, the firmware version query, with its CRC-8"),
)
"""What a client sends a peer that said nothing, one probe per fresh connection: each draws a row of FOREIGN from
the peers it is the language of, and is a line the other machines ignore."""


def _scan(data: bytes | bytearray, kind: str, final: bool, *, wanted: bool) -> tuple[Foreign | None, bool]:
    """The row `data` matches and whether more bytes could still change the verdict (`final`: they cannot);
    unless `wanted` (whether more bytes are needed), a start no row matches yet is answered at once."""
    head = bytes(data[:HEAD_BYTES])
    final = final or len(head) >= HEAD_BYTES
    rows = [row for row in FOREIGN if row.kind != kind]
    if not wanted and not any(row.pattern.match(head) for row in rows):
        return None, False
    for row in rows:
        if final:
            if row.pattern.match(head):
                return row, False
            continue
        found = row.partial.match(head, partial=True)
        if found is None:
            continue
        if found.partial:  # this row may yet match: a less specific one below must not decide first
            return None, True
        return row, False
    return None, False


def identify(data: bytes | bytearray, kind: str, *, final: bool = False) -> Foreign | None:
    """The row of FOREIGN, other than a machine of `kind`, that the first bytes a peer sent (`data`, up to
    HEAD_BYTES of them are looked at) conclusively match; None while they could still become one of another row
    (unless `final`: no more will come) or when they match none."""
    return _scan(data, kind, final, wanted=False)[0]


def undecided(data: bytes | bytearray, kind: str) -> bool:
    """Whether `data` is the start of some row's words (other than a machine of `kind`), so more bytes are needed."""
    return _scan(data, kind, False, wanted=True)[1]


def wrong_peer(data: bytes | bytearray, expected: str, kind: str, where: str, *,
               final: bool = False) -> RemoteProtocolError | None:
    """The error for a client of `kind` ("xyz") that expected `expected` ("an XYZv3 printer") at `where` and was
    sent `data` by a peer FOREIGN recognises; None when `data` names no other peer (yet)."""
    row = identify(data, kind, final=final)
    if row is None:
        return None
    head = bytes(data[:HEAD_BYTES])
    line = head.lstrip(b"\r\n").split(b"\n", 1)[0].rstrip(b"\r") or head  # its first line, when it has lines
    text = line.decode("latin-1")
    said = excerpt(text, 60) if line.isascii() and text.isprintable() else excerpt(line, 60)  # binary as bytes
    return RemoteProtocolError(f"{where} is not {expected}: it is {row.what} (it said {said})")


class FirstBytes:
    """The first HEAD_BYTES bytes a peer sent, gathered over however many reads they came in."""

    __slots__ = ("data",)

    def __init__(self) -> None:
        self.data = bytearray()

    def feed(self, chunk: bytes | bytearray) -> None:
        room = HEAD_BYTES - len(self.data)
        if room > 0:
            self.data += chunk[:room]

    def __bool__(self) -> bool:
        return bool(self.data)


def _tcp_address(url: str) -> tuple[str, int] | None:
    if not url.startswith("tcp://"):
        return None
    host, _, port = url.removeprefix("tcp://").rpartition(":")
    if not port.isdigit() or not host:
        return None
    return host.strip("[]"), int(port)


async def _answer(host: str, port: int, says: bytes, kind: str, seconds: float) -> bytes:
    """What the peer says on a fresh connection after `says`, until it is conclusive, HEAD_BYTES have come, the
    peer is silent for `seconds` or PROBE_LIMIT has passed."""
    import asyncio  # here: the first-bytes check is also used by readers that never open a link (`xyz info`)

    heard = FirstBytes()
    try:
        async with asyncio.timeout(seconds):
            reader, writer = await asyncio.open_connection(host, port)
    except (OSError, TimeoutError):
        return b""
    try:
        writer.write(says)
        async with asyncio.timeout(PROBE_LIMIT):
            while len(heard.data) < HEAD_BYTES:
                async with asyncio.timeout(seconds):
                    chunk = await reader.read(HEAD_BYTES)
                if not chunk:
                    break
                heard.feed(chunk)
                if not undecided(heard.data, kind):
                    break
    except (OSError, TimeoutError):
        pass
    finally:
        writer.close()
        with contextlib.suppress(OSError):
            await writer.wait_closed()
    return bytes(heard.data)


async def probe(url: str, expected: str, kind: str, where: str, *,
                seconds: float = PROBE_SECONDS) -> RemoteProtocolError | None:
    """Ask the TCP peer at `url` ("tcp://host:port"), which said nothing to a client of `kind`, with each of PROBES
    in turn (a fresh connection each, `seconds` each at most) and return the error naming what answered, as
    `wrong_peer`; None when no probe drew a row of FOREIGN, or `url` is no TCP address."""
    address = _tcp_address(url)
    if address is None:
        return None
    for row in PROBES:
        if row.kind == kind:
            continue
        answer = await _answer(*address, row.says, kind, seconds)
        if (wrong := wrong_peer(answer, expected, kind, where, final=True)) is not None:
            return wrong
    return None


async def name_peer(said: bytes | bytearray, url: str, expected: str, kind: str,
                    where: str) -> LinkError | RemoteProtocolError | None:
    """Why a peer never heard as `expected` ended a client's wait or closed its link: a simulator's farewell
    (`refusal`) or the peer FOREIGN names from the first bytes it sent (`said`, as gathered), or, when it said
    nothing, from its answer to a probe; None when nothing names it."""
    if not said:
        return await probe(url, expected, kind, where)
    from fabwire.transport.limits import refusal

    return refusal(said, where) or wrong_peer(said, expected, kind, where, final=True)
