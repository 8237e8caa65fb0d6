"""What a replayed reply may differ in without anything being wrong: per protocol, the reply fields that vary by
nature (clocks, counters, temperatures, progress, radio), each with the reference it is known from.

`fabwire trace replay` compares replies with these values masked, and reports which of them differed as ignored;
`--strict` compares every byte. A protocol's messages end with its `terminator`, which also tells when a reply
whose varying values changed length is complete.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass

MASK = b"\x00~\x00"
"""What a varying value is replaced by before comparing (no protocol sends it inside a value)."""


@dataclass(frozen=True, slots=True)
class VaryingField:
    """A reply field whose value changes by nature. `pattern`'s groups are the varying bytes of one match."""

    name: str
    """As the protocol names it: a status letter, a reply key, a register."""
    what: str
    pattern: re.Pattern[bytes]
    source: str


@dataclass(frozen=True, slots=True)
class ReplyGrammar:
    protocol: str
    terminator: bytes
    """Ends every reply message."""
    varying: tuple[VaryingField, ...]


def _xyz_letter(letter: str, what: str, value: str = r"([^\n]*)") -> VaryingField:
    """A status line `<letter>:<value>` (XYZv3 replies are `\\n`-ended lines, xyzv3.md 1.4 and 2.1)."""
    return VaryingField(letter, what, re.compile(rb"(?m)^" + re.escape(letter).encode() + rb":" + value.encode()),
                        "xyzv3.md 2.1, status letter table (MM:v3, MM:sock Query_Parse, SEED, RJ)")


XYZ = ReplyGrammar("xyz", b"\n", (
    _xyz_letter("L", "machine, extruder and last power-on minutes", r"[^,\n]*,([^\n]*)"),
    _xyz_letter("b", "bed temperature"),
    _xyz_letter("t", "extruder temperature and target", r"[^,\n]*,([^\n]*)"),
    _xyz_letter("d", "job progress and minutes"),
    _xyz_letter("f", "filament left", r"[^,\n]*,([^\n]*)"),
    _xyz_letter("X", "nozzle print minutes", r"[^,\n]*,(?:[^-,\n]*-){6}([0-9]+)(?:,(?:[^-,\n]*-){6}([0-9]+))?"),
    _xyz_letter("4", "Wi-Fi signal strength", r'[^\n]*?"rssiValue":"([^"]*)"'),
    _xyz_letter("W", "Wi-Fi networks in range"),
))
"""The letters for lifetime counters, temperatures, a job's progress and the radio; the printer's identity,
state (`j`), errors (`e`), settings and calibration are compared."""


def _lineus_key(key: str, what: str) -> VaryingField:
    """A `KEY:value` pair of a reply, the value bare or double-quoted (lineus.md 1.4)."""
    return VaryingField(key, what, re.compile(rb"(?:^| )" + key.encode() + rb':("[^"]*"|[^ \r\n\x00]*)'),
                        "lineus.md 2.4, M122 diagnostics (official lineus module get_info)")


LINEUS = ReplyGrammar("lineus", b"\r\n\x00", (
    _lineus_key("Uptime", "time since power-on"),
    _lineus_key("Time", "the clock"),
    _lineus_key("FreeHeap", "free memory"),
))
"""M122's clock, uptime and free heap; positions, names, files and settings are compared."""


def _mmu_reply(name: str, what: str, head: str) -> VaryingField:
    """A response `<rq><value> <pcode><pvalue>*<crc>\\n` (mmu3.md 2.2): the value and the CRC-8 over it vary."""
    return VaryingField(name, what, re.compile(rb"(?m)^" + head.encode() + rb"([0-9a-f]*)\*([0-9a-f]{1,2})\r?$"),
                        "mmu3.md 2.2 response grammar, 2.4 P progress, 4.4 register 0x1a")


MMU = ReplyGrammar("mmu", b"\n", (
    _mmu_reply("P", "a running command's progress", r"[A-Za-z][0-9a-f]* P"),
    _mmu_reply("R1a", "pulley position", r"R1a A"),
))
"""The progress code of a command under way (it advances with time) and the pulley position; states, errors,
versions and the other registers are compared."""

GRAMMARS: dict[str, ReplyGrammar] = {g.protocol: g for g in (XYZ, LINEUS, MMU)}
"""By device kind name (`fabwire.devices.KINDS`)."""

_MMU_REQUEST = re.compile(rb"[A-Za-z][0-9a-f]*(?: [0-9a-f]+)?\*[0-9a-f]{1,2}\n")


def sniff(sent: bytes, reply: bytes) -> ReplyGrammar | None:
    """The protocol of a capture from its first exchange, for captures that do not name it: XYZv3 commands start
    with `XYZv3/`, a Line-us greets with `hello` ended by `\\r\\n\\0`, MMU requests are CRC-framed lines."""
    if sent.startswith(b"XYZv3/"):
        return XYZ
    if reply.startswith(b"hello") or reply.endswith(LINEUS.terminator):
        return LINEUS
    if _MMU_REQUEST.match(sent):
        return MMU
    return None


@dataclass(frozen=True, slots=True)
class Masked:
    """A reply with its varying values masked, the values taken out (per field name), and where they were."""

    data: bytes
    values: dict[str, list[bytes]]
    spans: tuple[tuple[int, int, int], ...]
    """(start in `data`, length taken out, length put in) per masked value, in order."""

    def raw_offset(self, offset: int) -> int:
        """The index in the unmasked reply of index `offset` in `data`."""
        shift = 0
        for start, taken, put in self.spans:
            if start >= offset:
                break
            if offset < start + put:
                return start + shift
            shift += taken - put
        return offset + shift


def mask(data: bytes, grammar: ReplyGrammar | None) -> Masked:
    """`data` with every varying value of `grammar` replaced by MASK (nothing masked without a grammar)."""
    if grammar is None:
        return Masked(data, {}, ())
    cuts: list[tuple[int, int, str]] = []
    for field in grammar.varying:
        for start, end in _groups(field.pattern, data):
            cuts.append((start, end, field.name))
    cuts.sort()
    out = bytearray()
    values: dict[str, list[bytes]] = {}
    spans: list[tuple[int, int, int]] = []
    at = 0
    for start, end, name in cuts:
        if start < at:
            continue  # two patterns over the same bytes: the first masks them
        out += data[at:start]
        spans.append((len(out), end - start, len(MASK)))
        out += MASK
        values.setdefault(name, []).append(data[start:end])
        at = end
    out += data[at:]
    return Masked(bytes(out), values, tuple(spans))


def _groups(pattern: re.Pattern[bytes], data: bytes) -> Iterator[tuple[int, int]]:
    for match in pattern.finditer(data):
        for group in range(1, (pattern.groups or 0) + 1):
            if match.start(group) >= 0:
                yield match.span(group)


def differing(expected: Masked, got: Masked) -> list[str]:
    """The names of the varying fields whose values differ between two masked replies, as they come."""
    return [name for name in dict.fromkeys([*expected.values, *got.values])
            if expected.values.get(name) != got.values.get(name)]
