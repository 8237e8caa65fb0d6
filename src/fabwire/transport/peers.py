"""What other machines and servers say on a connection, so a client pointed at the wrong port names what it found
as soon as it is said, instead of waiting out its reply timeout and calling the link dead.

Each row is something a peer sends first (a greeting) or in answer to a line it does not understand, with its
source. Only the start of what a peer sent is looked at (`identify`); a row never matches a machine's own protocol.
"""

from __future__ import annotations

import re
from typing import NamedTuple

from fabwire.errors import RemoteProtocolError, excerpt


class Foreign(NamedTuple):
    what: str
    """The peer, as a message names it ("a Line-us drawing robot")."""
    kind: str
    """fabwire's device kind when it is one of ours ("lineus"), else ""."""
    said: re.Pattern[bytes]
    source: str


FOREIGN: tuple[Foreign, ...] = (
    Foreign("a Line-us drawing robot", "lineus", re.compile(rb"hello VERSION:"),
            "Line-us G-code spec: on connect the robot sends `hello VERSION:… NAME:… SERIAL:…`"),
    Foreign("an SSH server", "", re.compile(rb"SSH-[12]\.[0-9]+-"),
            "RFC 4253 §4.2: the identification string `SSH-protoversion-softwareversion` comes first"),
    Foreign("a web server", "",
            re.compile(rb"HTTP/[0-9](?:\.[0-9])? [1-5][0-9][0-9]|\s*<(?:!DOCTYPE html|html)", re.IGNORECASE),
            "RFC 9112 §4: a response starts with its status line (a line that is no request gets 400); RFC 1945 "
            "§4.1: to a request line without a version (HTTP/0.9) the answer is the bare HTML document, as Python's "
            "http.server sends it, which starts with `<!DOCTYPE html>` or `<html>` (HTML §13.1)"),
    Foreign("an FTP or mail server", "", re.compile(rb"220[ -]"),
            "RFC 959 §5.4 and RFC 5321 §4.2: the server greets with reply code 220"),
    Foreign("a Telnet server", "", re.compile(rb"\xff[\xfb-\xfe]"),
            "RFC 854: option negotiation, IAC (255) then WILL/WONT/DO/DONT"),
    Foreign("a Marlin or Prusa-firmware 3D printer", "", re.compile(rb"(?:start(?:\r?\n|$)|echo:)"),
            "Marlin firmware: `start` after a reset, informational lines after SERIAL_ECHO_START (`echo:`)"),
)
"""Peers a client may reach by mistake, by what they say."""


def identify(data: bytes, expected: str) -> Foreign | None:
    """The row of FOREIGN whose words `data` (the first bytes a peer sent, or its first line) starts with, leaving
    out the kind the client expects to find; None when nothing is recognised."""
    head = data[:256]
    for row in FOREIGN:
        if row.kind != expected and row.said.match(head):
            return row
    return None


def wrong_peer(data: bytes, expected: str, kind: str, where: str) -> RemoteProtocolError | None:
    """The error for a client of `kind` ("xyz") that expected `expected` ("an XYZv3 printer") at `where` and was
    answered with `data` by a peer FOREIGN recognises; None when `data` names no other peer."""
    row = identify(data, kind)
    if row is None:
        return None
    said = excerpt(data.decode("latin-1"), 40)
    return RemoteProtocolError(f"{where} is not {expected}: it is {row.what} (it said {said})")
