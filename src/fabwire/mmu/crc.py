"""The MMU3 protocol's CRC-8 (`MMU:src/modules/crc.h`, reference §2.6): CRC-8/SMBUS over the binary field values.

Requests: code, value, then the 16-bit W word little-endian (0 for every other request). Responses: the request
CRC with the word forced to 0, continued over the parameter code and its 16-bit value.
"""

from __future__ import annotations

from typing import Final


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


CRC_TABLE: Final = _crc_table()


def crc8(data: bytes | bytearray, crc: int = 0) -> int:
    """CRC-8/SMBUS: poly 0x07, init 0, no reflection, no final XOR."""
    table = CRC_TABLE
    for byte in data:
        crc = table[crc ^ byte]
    return crc


def request_crc(code: str, value: int, value2: int = 0) -> int:
    """The request CRC: over code, value and the 16-bit W word little-endian (0 for every other request)."""
    t = CRC_TABLE
    return t[t[t[t[ord(code)] ^ (value & 0xFF)] ^ (value2 & 0xFF)] ^ ((value2 >> 8) & 0xFF)]


def response_crc(code: str, value: int, param: str, pvalue: int) -> int:
    """The response CRC: the request CRC with value2 = 0, continued over param code and 16-bit value."""
    t = CRC_TABLE
    crc = t[request_crc(code, value) ^ ord(param)]
    return t[t[crc ^ (pvalue & 0xFF)] ^ ((pvalue >> 8) & 0xFF)]
