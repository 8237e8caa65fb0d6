"""Renders a capture the way protocol transcripts are written: `>` to the device, `<` from it."""

from __future__ import annotations

from collections.abc import Iterable, Iterator

from fabwire.transport.tap import TraceRecord, escape_text

_TEXTLIKE = frozenset(range(0x20, 0x7F)) | {0x0D, 0x0A, 0x09}
_REPLY_ENDS = (b"\n\0", b"\0")
"""A NUL ends a Line-us reply and some XYZ replies; anywhere else NULs are binary (a .3w header's padding)."""


def looks_binary(data: bytes) -> bool:
    """More than one byte in ten outside printable ASCII and line control: show it as a hexdump."""
    for end in _REPLY_ENDS:
        if data.endswith(end):
            data = data[: -len(end)] + end.replace(b"\0", b"")
            break
    odd = len(data) - sum(1 for b in data if b in _TEXTLIKE)
    return odd * 10 > len(data)


def hexdump(data: bytes, indent: str) -> Iterator[str]:
    """16 bytes a row; runs of identical rows are shown once, then `*` (as hexdump(1) does)."""
    previous = b""
    repeating = False
    for offset in range(0, len(data), 16):
        row = data[offset : offset + 16]
        if row == previous and len(row) == 16:
            if not repeating:
                yield f"{indent}*"
                repeating = True
            continue
        previous, repeating = row, False
        hexes = " ".join(f"{b:02x}" for b in row)
        text = "".join(chr(b) if 0x20 <= b < 0x7F else "." for b in row)
        yield f"{indent}{offset:08x}  {hexes:<47}  |{text}|"
    if repeating:
        yield f"{indent}{len(data):08x}"


def _text_lines(data: bytes) -> Iterator[str]:
    """Split after each LF (and after a NUL that ends a reply) so each protocol line stands alone."""
    start = 0
    for i, b in enumerate(data):
        ends_line = b == 0x0A and not (i + 1 < len(data) and data[i + 1] == 0x00)
        if ends_line or (b == 0x00 and i > 0 and data[i - 1] == 0x0A):
            yield escape_text(data[start : i + 1])
            start = i + 1
    if start < len(data):
        yield escape_text(data[start:])


def render_trace(records: Iterable[TraceRecord], *, timestamps: bool = True) -> Iterator[str]:
    for record in records:
        stamp = f"{record.t:10.6f} " if timestamps else ""
        if record.direction is None:
            detail = f": {record.detail}" if record.detail else ""
            yield f"{stamp}-- {record.event}{detail}"
            continue
        if looks_binary(record.data):
            yield f"{stamp}{record.direction} [{len(record.data)} bytes]"
            yield from hexdump(record.data, " " * len(stamp) + "  ")
            continue
        for i, line in enumerate(_text_lines(record.data)):
            yield f"{stamp if i == 0 else ' ' * len(stamp)}{record.direction}{line}"
