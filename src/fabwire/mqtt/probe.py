"""Whether what listens at a broker's address speaks MQTT, told at once: a broker answers a CONNECT with CONNACK,
whose first byte is 0x20 (MQTT 3.1.1 section 3.2.1, MQTT 5.0 section 3.2.1); anything else that answers is another
server, named as the device clients name a wrong peer (`fabwire.transport.peers`). Without this, the MQTT client
waits out its whole connection timeout before calling the address silent.

Line-based servers (a web server, a printer) wait for an end of line before they answer; the CONNECT has none, so
after a short silence the probe sends one. A broker has answered the CONNECT by then, or answers it before it reads
the extra bytes (it reads packets in order), so a broker is never mistaken for something else. A peer still silent
is asked in each other machine's language on fresh connections (a da Vinci answers only XYZv3); one that says
nothing to any, or closes the connection, is left to the MQTT client, whose own message says so.
"""

from __future__ import annotations

import asyncio
import contextlib
import secrets
import struct

from fabwire.errors import excerpt
from fabwire.transport.peers import probe, wrong_peer

CONNACK = 0x20
"""The first byte of CONNACK: packet type 2, flags 0."""
DISCONNECT = b"\xe0\x00"
"""MQTT 3.1.1 section 3.14: a clean goodbye, so the broker logs an ordinary disconnection."""
NUDGE_AFTER_S = 0.5
"""How long the probe waits for an answer to the CONNECT before it sends a line end."""
ASK_AFTER_S = 1.0
"""How long the probe waits after the line end before it asks in the other machines' languages
(`fabwire.transport.peers.PROBES`): a broker has answered long before."""
SILENT = "silent"
"""`not_a_broker`'s answer for a server that said nothing at all."""
NUDGE = b"\r\n\r\n"
"""A line end (and an HTTP request's blank line): what a line-based server waits for before it answers."""


def _text(value: str) -> bytes:
    data = value.encode()
    return struct.pack("!H", len(data)) + data


def connect_packet(client_id: str, username: str | None = None, password: str | None = None,
                   keepalive_s: int = 10) -> bytes:
    """An MQTT 3.1.1 CONNECT (section 3.1) with a clean session, and the login when one is given."""
    flags = 0x02 | (0x80 if username is not None else 0) | (0x40 if password is not None else 0)
    body = _text("MQTT") + bytes([4, flags]) + struct.pack("!H", keepalive_s) + _text(client_id)
    body += (_text(username) if username is not None else b"") + (_text(password) if password is not None else b"")
    length = len(body)
    encoded = bytearray()
    while True:  # the remaining length, 7 bits a byte (section 2.2.3)
        byte, length = length % 128, length // 128
        encoded.append(byte | (0x80 if length else 0))
        if not length:
            break
    return bytes([0x10]) + bytes(encoded) + body


async def _answer(reader: asyncio.StreamReader, within_s: float) -> bytes | None:
    """The first bytes the peer sends within `within_s` (b"" when it closed), None when it said nothing."""
    try:
        async with asyncio.timeout(within_s):
            data = await reader.read(256)
            with contextlib.suppress(TimeoutError):  # a little more of a greeting, for naming it
                async with asyncio.timeout(0.05):
                    while len(data) < 256 and (more := await reader.read(256 - len(data))):
                        data += more
            return data
    except TimeoutError:
        return None


async def not_a_broker(host: str, port: int, *, username: str | None = None, password: str | None = None,
                       timeout_s: float = 10.0) -> str | None:
    """Why the server at host:port is not an MQTT broker ("127.0.0.1:8080 is not an MQTT broker: it is a web
    server (it said 'HTTP/1.0 400 …')"), from its answer to a CONNECT; None when it answered CONNACK, said nothing,
    closed the connection or could not be reached (the MQTT client's own attempt reports those), and a
    `SILENT` answer when it said nothing for `timeout_s` (the MQTT client would wait as long in vain)."""
    where = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
    try:
        async with asyncio.timeout(timeout_s):
            reader, writer = await asyncio.open_connection(host, port)
    except (OSError, TimeoutError):
        return None
    began = asyncio.get_running_loop().time()
    try:
        writer.write(connect_packet(f"fabwire-probe-{secrets.token_hex(4)}", username, password))
        await writer.drain()
        data = await _answer(reader, NUDGE_AFTER_S)
        if data is None:
            writer.write(NUDGE)
            await writer.drain()
            data = await _answer(reader, ASK_AFTER_S)
        if data is None:  # a server that answers only its own language (a da Vinci): ask in each of them
            asked = await probe(f"tcp://{where}", "an MQTT broker", "mqtt", where)
            if asked is not None:
                return str(asked)
            data = await _answer(reader, max(0.0, timeout_s - (asyncio.get_running_loop().time() - began)))
        if data is None:
            return SILENT
        if not data:
            return None
        if data[0] == CONNACK:
            writer.write(DISCONNECT)
            await writer.drain()
            return None
        named = wrong_peer(data, "an MQTT broker", "mqtt", where)
        if named is not None:
            return str(named)
        return (f"{where} is not an MQTT broker: it answered {excerpt(data.decode('latin-1'), 40)}, where a broker "
                "answers with CONNACK")
    except OSError:
        return None
    finally:
        writer.close()
        with contextlib.suppress(OSError, TimeoutError):
            async with asyncio.timeout(1.0):
                await writer.wait_closed()
