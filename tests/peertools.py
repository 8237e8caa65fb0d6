"""What other servers and machines say on a connection, as captured from one of each kind."""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Iterator

SAID: dict[str, bytes] = {
    "a Line-us drawing robot": b'hello VERSION:"3.2.0 Nov 17 2019 17:54:57" NAME:line-us SERIAL:354003\r\n\0',
    "an SSH server": b"SSH-2.0-OpenSSH_9.2p1 Debian-2+deb12u3\r\n",
    "a web server": b"HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain\r\nContent-Length: 11\r\n\r\nBad Request",
    "an FTP or mail server": b"220 (vsFTPd 3.0.3)\r\n",
    "a Telnet server": b"\xff\xfd\x18\xff\xfd\x20\xff\xfd\x23\xff\xfd\x27",
    "a Marlin or Prusa-firmware 3D printer": b"start\necho:Marlin 2.1.2.1\necho: Last Updated: 2023-05-30\n",
}
"""What each kind of peer says, as captured from one of its kind (a Line-us 3.2.0, OpenSSH, an HTTP server's
answer to a line that is no request, vsftpd, a Telnet server's opening negotiation, a Marlin board's reset)."""


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
