"""A transport over a raw, non-blocking file descriptor (the master side of a pty)."""

from __future__ import annotations

import asyncio
import contextlib
import errno
import os

from fabwire.errors import LinkClosed
from fabwire.transport.base import DEFAULT_READ_SIZE, Transport


class FdTransport(Transport):
    """Reads and writes one fd through the event loop's readiness callbacks; closes `owned` fds on close."""

    def __init__(self, fd: int, *, url: str, peer: str, owned: tuple[int, ...] = ()) -> None:
        os.set_blocking(fd, False)
        self._fd = fd
        self._owned = owned or (fd,)
        self._closed = False
        self._waiters: set[asyncio.Future[None]] = set()
        self.url = url
        self.peer = peer

    @property
    def closed(self) -> bool:
        return self._closed

    async def _wait(self, writable: bool) -> None:
        loop = asyncio.get_running_loop()
        waiter: asyncio.Future[None] = loop.create_future()
        self._waiters.add(waiter)

        def ready() -> None:
            if not waiter.done():
                waiter.set_result(None)

        add, remove = (loop.add_writer, loop.remove_writer) if writable else (loop.add_reader, loop.remove_reader)
        add(self._fd, ready)
        try:
            await waiter
        finally:
            self._waiters.discard(waiter)
            if not self._closed:
                remove(self._fd)
        if self._closed:
            raise LinkClosed(f"link to {self.peer} is closed")

    async def read(self, max_bytes: int = DEFAULT_READ_SIZE) -> bytes:
        while True:
            if self._closed:
                raise LinkClosed(f"link to {self.peer} is closed")
            try:
                data = os.read(self._fd, max_bytes)
            except BlockingIOError:
                await self._wait(writable=False)
                continue
            except OSError as exc:
                # A pty master reads EIO once the last slave fd is closed: that is the peer hanging up.
                if exc.errno == errno.EIO:
                    raise LinkClosed(f"{self.peer} hung up") from None
                raise LinkClosed(f"link to {self.peer} lost: {exc.strerror}") from exc
            if not data:
                raise LinkClosed(f"{self.peer} closed the link")
            return data

    async def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            if self._closed:
                raise LinkClosed(f"link to {self.peer} is closed")
            try:
                sent = os.write(self._fd, view)
            except BlockingIOError:
                await self._wait(writable=True)
                continue
            except OSError as exc:
                raise LinkClosed(f"link to {self.peer} lost while writing: {exc.strerror}") from exc
            view = view[sent:]

    async def close(self) -> None:
        if self._closed:
            return
        loop = asyncio.get_running_loop()
        loop.remove_reader(self._fd)
        loop.remove_writer(self._fd)
        self._closed = True
        for waiter in list(self._waiters):
            if not waiter.done():
                waiter.set_result(None)
        for fd in self._owned:
            with contextlib.suppress(OSError):
                os.close(fd)
