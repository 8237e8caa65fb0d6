"""The one interface every link offers, whatever carries the bytes."""

from __future__ import annotations

import abc
import asyncio
import contextlib
from types import TracebackType
from typing import Self

from fabwire.errors import LinkClosed, LinkError

DEFAULT_READ_SIZE = 65536


class Transport(abc.ABC):
    """A bidirectional byte stream to one peer.

    `read` returns at least one byte or raises `LinkClosed` at end of stream, so a caller that forgets
    to check for EOF cannot spin; `write` returns once the bytes are handed to the OS (or peer).
    """

    url: str = ""
    peer: str = ""

    @abc.abstractmethod
    async def read(self, max_bytes: int = DEFAULT_READ_SIZE) -> bytes:
        """Return 1..max_bytes bytes as soon as any are available."""

    @abc.abstractmethod
    async def write(self, data: bytes) -> None:
        """Send all of `data`."""

    @abc.abstractmethod
    async def close(self) -> None:
        """Release the link; safe to call twice."""

    @property
    def closed(self) -> bool:
        return False

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.url or self.peer}>"


class StreamTransport(Transport):
    """A transport over an asyncio stream pair (TCP sockets, serial ports)."""

    def __init__(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, *, url: str, peer: str
    ) -> None:
        self._reader = reader
        self._writer = writer
        self._closed = False
        self.url = url
        self.peer = peer

    @property
    def closed(self) -> bool:
        return self._closed

    async def read(self, max_bytes: int = DEFAULT_READ_SIZE) -> bytes:
        if self._closed:
            raise LinkClosed(f"link to {self.peer} is closed")
        try:
            data = await self._reader.read(max_bytes)
        except (ConnectionError, OSError) as exc:
            raise LinkClosed(f"link to {self.peer} lost: {exc}") from exc
        if not data:
            raise LinkClosed(f"{self.peer} closed the link")
        return data

    async def write(self, data: bytes) -> None:
        if self._closed:
            raise LinkClosed(f"link to {self.peer} is closed")
        if self._writer.is_closing():
            raise LinkClosed(f"{self.peer} closed the link")
        try:
            self._writer.write(data)
            await self._writer.drain()
        except (ConnectionError, OSError) as exc:
            raise LinkClosed(f"link to {self.peer} lost while writing: {exc}") from exc

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._writer.close()
        with contextlib.suppress(ConnectionError, OSError):
            await self._writer.wait_closed()

    async def write_eof(self) -> None:
        """Half-close: tell the peer we will send no more (TCP FIN), keep reading."""
        try:
            if self._writer.can_write_eof():
                self._writer.write_eof()
        except (ConnectionError, OSError) as exc:
            raise LinkError(f"cannot half-close link to {self.peer}: {exc}") from exc
