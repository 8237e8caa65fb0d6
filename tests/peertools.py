"""What other servers and machines say on a connection, as captured from one of each kind."""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Iterator

SAID: dict[str, bytes] = {
    "lineus": b'hello VERSION:"3.2.0 Nov 17 2019 17:54:57" NAME:line-us SERIAL:354003\r\n\0',
    "xyz": b"b:20\nc:{336,374,377,355,373,371,364,377,356}\nd:0,0,0\nj:9511,0\nt:1,22,0\n$\n",
    "mmu": b"S0 A3*22\n",
    "agent": b"HTTP/1.1 400 Bad Request\r\ncontent-type: text/plain; charset=utf-8\r\nserver: fabwire/0.1.0\r\n"
             b"Connection: close\r\n\r\nInvalid HTTP request received.",
    "http": b"HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain\r\nContent-Length: 11\r\n\r\nBad Request",
    "html": b'<!DOCTYPE HTML>\n<html lang="en">\n    <head>\n        <meta charset="utf-8">\n'
            b"        <title>Error response</title>\n    </head>\n",
    "ssh": b"SSH-2.0-OpenSSH_9.2p1 Debian-2+deb12u3\r\n",
    "ftp-smtp": b"220 (vsFTPd 3.0.3)\r\n",
    "pop3": b"+OK Dovecot ready.\r\n",
    "imap": b"* OK [CAPABILITY IMAP4rev1 SASL-IR LOGIN-REFERRALS ID ENABLE IDLE LITERAL+] Dovecot ready.\r\n",
    "telnet": b"\xff\xfd\x18\xff\xfd\x20\xff\xfd\x23\xff\xfd\x27",
    "vnc": b"RFB 003.008\n",
    "redis": b"-ERR unknown command 'XYZv3/query=a', with args beginning with: \r\n",
    "mqtt": b"\x20\x02\x00\x00",
    "marlin": b"start\necho:Marlin 2.1.2.1\necho: Last Updated: 2023-05-30\n",
}
"""What each kind of peer says, as captured from one of its kind (a Line-us 3.2.0, fabwire's XYZ and MMU
simulators, `fabwire serve` and Python's http.server refusing a line that is no request, OpenSSH, vsftpd, Dovecot
POP3 and IMAP, a Telnet server's opening negotiation, a VNC server, Redis refusing a line, Mosquitto answering
CONNECT, a Marlin board's reset)."""


@contextlib.contextmanager
def saying(words: bytes | None, *, first: bool = True, again: bool = True) -> Iterator[int]:
    """A TCP server on a free loopback port (yielded) that sends `words` on connect (`first`) and after every chunk
    it is sent (`again`), or after the first line end it is sent when not `first`; None: it says nothing."""
    server = socket.create_server(("127.0.0.1", 0))
    stop = threading.Event()
    held: list[socket.socket] = []

    def serve(conn: socket.socket) -> None:
        with contextlib.suppress(OSError):
            if words is not None and first:
                conn.sendall(words)
            seen = b""
            while not stop.is_set() and (chunk := conn.recv(4096)):
                seen += chunk
                if words is not None and ((first and again) or (not first and b"\n" in seen)):
                    conn.sendall(words)
                    seen = b""

    def accept() -> None:
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except OSError:
                return
            held.append(conn)
            threading.Thread(target=serve, args=(conn,), daemon=True).start()

    threading.Thread(target=accept, daemon=True).start()
    try:
        yield server.getsockname()[1]
    finally:
        stop.set()
        server.close()
        for conn in held:
            with contextlib.suppress(OSError):
                conn.close()
