"""Upload framing, both roles: the blocks a print or firmware file travels in (`[index][len][data][crc32]`) and the
host's count of the printer's per-block acknowledgements (reference §4.5)."""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterator
from typing import BinaryIO

from fabwire.errors import LocalProtocolError
from fabwire.xyz.commands import (
    DEFAULT_BLOCK_SIZE,
)


def block_size_from_packet(k: int) -> int:
    """`o:p<k>` → bytes per block; k ≤ 0 falls back to 8192, as clients do."""
    return k * 1024 if k > 0 else DEFAULT_BLOCK_SIZE


def encode_block(index: int, data: bytes, *, crc: bool = True) -> bytes:
    """`[index u32be][len u32be][data][crc32(data) u32be or 0]`."""
    trailer = zlib.crc32(data) if crc else 0
    return struct.pack(">II", index, len(data)) + data + struct.pack(">I", trailer)


def iter_blocks(data: bytes | BinaryIO, block_size: int, *, crc: bool = True) -> Iterator[bytes]:
    """The framed upload blocks of `data`, or of a file read one block at a time (memory: one block)."""
    if block_size <= 0:
        raise LocalProtocolError("upload block size must be positive")
    if not isinstance(data, bytes | bytearray | memoryview):
        for index, chunk in enumerate(iter(lambda: data.read(block_size), b"")):
            yield encode_block(index, chunk, crc=crc)
        return
    view = memoryview(data)
    for index, start in enumerate(range(0, len(data), block_size)):
        yield encode_block(index, bytes(view[start : start + block_size]), crc=crc)


def block_count(size: int, block_size: int) -> int:
    return -(-size // block_size)
