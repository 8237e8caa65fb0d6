"""Replaying a capture's host side to a device or simulator and reporting where the replies differ.

A capture is cut into exchanges: the bytes the host sent (`>`), then the bytes that came back (`<`) before the
host sent again. Each exchange's request is sent as recorded; the reply is read until it holds as many of the
protocol's message terminators as the recording (or as many bytes, when the protocol is not known), or the device
has been quiet for `quiet` seconds, and compared with the recording. Values that vary by nature (uptime, clocks,
temperatures: `fabwire.transport.volatile`) are masked before comparing unless `strict`; those that differed are
reported as ignored.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

from fabwire.errors import LinkClosed
from fabwire.transport.base import Transport
from fabwire.transport.tap import FROM_DEVICE, TO_DEVICE, TraceRecord
from fabwire.transport.volatile import ReplyGrammar, differing, mask, sniff

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
    offset: int
    """Index in `got` of the first byte where the replies part (varying values aside unless strict)."""


@dataclass(frozen=True, slots=True)
class Ignored:
    """Varying fields whose values differed in one exchange, ignored by the comparison."""

    exchange: int
    fields: tuple[str, ...]


@dataclass
class ReplayReport:
    grammar: ReplyGrammar | None
    """The protocol the replies were read by; None when neither the capture nor its bytes tell it."""
    strict: bool
    differences: list[Difference] = field(default_factory=list)
    ignored: list[Ignored] = field(default_factory=list)


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


def _complete(got: bytes, expected: bytes, grammar: ReplyGrammar | None) -> bool:
    """Whether `got` is as long as the recorded reply: as many messages when the recording ends with a whole one
    (a varying value may change a message's length), else as many bytes."""
    if grammar is not None and expected.endswith(grammar.terminator):
        return got.count(grammar.terminator) >= expected.count(grammar.terminator)
    return len(got) >= len(expected)


async def _read_reply(link: Transport, expected: bytes, grammar: ReplyGrammar | None, quiet: float) -> bytes:
    got = b""
    with contextlib.suppress(TimeoutError, LinkClosed):
        while not expected or not _complete(got, expected, grammar):
            async with asyncio.timeout(quiet):
                got += await link.read()
    return got


def _first_difference(a: bytes, b: bytes) -> int:
    for i, (x, y) in enumerate(zip(a, b, strict=False)):
        if x != y:
            return i
    return min(len(a), len(b))


def compare(exchange: Exchange, got: bytes, grammar: ReplyGrammar | None,
            strict: bool) -> tuple[Difference | None, Ignored | None]:
    """The difference between the recorded and the new reply, if any, and the varying fields ignored."""
    if got == exchange.expected:
        return None, None
    if strict or grammar is None:
        return Difference(exchange, got, _first_difference(exchange.expected, got)), None
    expected_masked, got_masked = mask(exchange.expected, grammar), mask(got, grammar)
    changed = tuple(differing(expected_masked, got_masked))
    ignored = Ignored(exchange.number, changed) if changed else None
    if expected_masked.data == got_masked.data:
        return None, ignored
    offset = got_masked.raw_offset(_first_difference(expected_masked.data, got_masked.data))
    return Difference(exchange, got, offset), ignored


async def replay(link: Transport, records: Iterable[TraceRecord], *, quiet: float = 2.0,
                 grammar: ReplyGrammar | None = None, strict: bool = False) -> ReplayReport:
    """Send each exchange's request and compare the reply. `grammar` is the capture's protocol; None: found
    from the first exchange (`volatile.sniff`), or, failing that, every byte is compared."""
    report: ReplayReport | None = None
    for exchange in exchanges(records):
        if report is None:
            report = ReplayReport(grammar or sniff(exchange.sent, exchange.expected), strict)
        if exchange.sent:
            await link.write(exchange.sent)
        got = await _read_reply(link, exchange.expected, report.grammar,
                                quiet if exchange.expected else min(quiet, 0.2))
        difference, ignored = compare(exchange, got, report.grammar, strict)
        if difference is not None:
            report.differences.append(difference)
        if ignored is not None:
            report.ignored.append(ignored)
    return report or ReplayReport(grammar, strict)


def _shown(data: bytes, limit: int) -> str:
    from fabwire.transport.tap import escape_text

    text = escape_text(data[: limit * 4])
    return text if len(text) <= limit else text[:limit] + "…"


def report_lines(report: ReplayReport, quiet: float) -> Iterator[str]:
    """The report for people: each differing exchange (sent, expected, got), then the varying fields ignored."""
    if not report.differences:
        yield "every reply matches the recording"
    for d in report.differences:
        yield f"exchange {d.exchange.number}: sent {_shown(d.exchange.sent, 80)}"
        yield f"  expected {_shown(d.exchange.expected, 200)}"
        if d.got:
            yield f"  got      {_shown(d.got, 200)}  (differs from byte {d.offset})"
        else:
            yield f"  got      no reply ({quiet:g} s of silence)"
    if report.ignored and report.grammar is not None:
        described = {f.name: f.what for f in report.grammar.varying}
        exchanges_of: dict[str, list[int]] = {}
        for entry in report.ignored:
            for name in entry.fields:
                exchanges_of.setdefault(name, []).append(entry.exchange)
        parts = [f"{name} ({described[name]}) in exchange{'s' if len(numbers) > 1 else ''} "
                 f"{', '.join(map(str, numbers[:5]))}{' …' if len(numbers) > 5 else ''}"
                 for name, numbers in exchanges_of.items()]
        yield f"ignored: {'; '.join(parts)} — {report.grammar.protocol} values that vary by nature (--strict " \
              "compares them)"
    elif report.grammar is None and not report.strict:
        yield "ignored: nothing (the capture's protocol is unknown, so every byte is compared; name it with " \
              "--protocol)"


def report_json(report: ReplayReport) -> dict[str, object]:
    """The report as data: `protocol` (None when unknown), `strict`, `differences` (exchange, sent, expected, got,
    offset; bytes as latin-1 text by the caller's encoder) and `ignored` (exchange, fields)."""
    return {
        "protocol": report.grammar.protocol if report.grammar is not None else None,
        "strict": report.strict,
        "differences": [{"exchange": d.exchange.number, "sent": d.exchange.sent, "expected": d.exchange.expected,
                         "got": d.got, "offset": d.offset} for d in report.differences],
        "ignored": [{"exchange": i.exchange, "fields": list(i.fields)} for i in report.ignored],
    }
