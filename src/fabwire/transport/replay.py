"""Replaying a capture's host side to a device or simulator and reporting where the replies differ.

A capture is cut into exchanges: the bytes the host sent (`>`), then the bytes that came back (`<`) before the
host sent again. Each exchange's request is sent as recorded; the reply is read until as many bytes as were
recorded have come, or the device has been quiet for `quiet` seconds, and compared with the recording.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

from fabwire.errors import LinkClosed
from fabwire.transport.base import Transport
from fabwire.transport.tap import FROM_DEVICE, TO_DEVICE, TraceRecord

MAX_REPLY = 1 << 20
"""A recorded reply longer than this is compared only up to here (a capture is read one exchange at a time)."""
MAX_SENT = 1 << 20
"""Bytes sent with no reply between them are cut into exchanges of about this size, so a capture of a device that
never answered is not held whole."""


@dataclass(frozen=True, slots=True)
class Exchange:
    number: int
    sent: bytes
    expected: bytes


@dataclass(frozen=True, slots=True)
class Difference:
    exchange: Exchange
    got: bytes

    @property
    def offset(self) -> int:
        """Index of the first byte where the replies part."""
        for i, (a, b) in enumerate(zip(self.exchange.expected, self.got, strict=False)):
            if a != b:
                return i
        return min(len(self.exchange.expected), len(self.got))


def exchanges(records: Iterable[TraceRecord]) -> Iterator[Exchange]:
    """Group a capture's chunks into request/reply exchanges, streaming."""
    sent: list[bytes] = []
    replies: list[bytes] = []
    size = sent_size = 0
    number = 0
    for record in records:
        if record.direction == TO_DEVICE:
            if replies or sent_size >= MAX_SENT:
                number += 1
                yield Exchange(number, b"".join(sent), b"".join(replies))
                sent, replies, size, sent_size = [], [], 0, 0
            sent.append(record.data)
            sent_size += len(record.data)
        elif record.direction == FROM_DEVICE and size < MAX_REPLY:
            replies.append(record.data[: MAX_REPLY - size])
            size += len(replies[-1])
    if sent or replies:
        number += 1
        yield Exchange(number, b"".join(sent), b"".join(replies))


async def _read_reply(link: Transport, wanted: int, quiet: float) -> bytes:
    got = b""
    with contextlib.suppress(TimeoutError, LinkClosed):
        while len(got) < wanted or wanted == 0:
            async with asyncio.timeout(quiet):
                got += await link.read()
    return got


async def replay(link: Transport, records: Iterable[TraceRecord], *, quiet: float = 2.0) -> list[Difference]:
    """Send each exchange's request and compare the reply; the differences, in order (none when all match)."""
    found: list[Difference] = []
    for exchange in exchanges(records):
        if exchange.sent:
            await link.write(exchange.sent)
        got = await _read_reply(link, len(exchange.expected), quiet if exchange.expected else min(quiet, 0.2))
        if got != exchange.expected:
            found.append(Difference(exchange, got))
    return found
