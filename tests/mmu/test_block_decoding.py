"""The reply decoder's fast paths (memo, whole-block decoding) against the byte-at-a-time automaton they stand in
for: the same messages and errors for any byte stream, however it is cut into reads."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fabwire.mmu import protocol as p


def _reply(code: str, value: int, param: str, pvalue: int | None) -> str:
    return p.encode(p.RESPONSE_TYPES[param](code, value, pvalue)).decode().rstrip("\n")


def _crc(code: str, value: int, param: str, pvalue: int = 0) -> str:
    return format(p.response_crc(code, value, param, pvalue), "x")


GOOD = "".join(_reply(*fields) + "\n" for fields in (("Q", 0, "P", 5), ("R", 0x1B, "A", 1), ("T", 1, "A", None)))
"""Well-formed replies around each line below, so it lands in the middle of a block."""

SPELLINGS: list[tuple[str, str, list[str]]] = [
    # (line as received, rule and source, events from it up to the first reply after it: an error noticed only at
    # the newline leaves the decoder in its error state, which eats that reply)
    ("T0 A*e", "ack without digits, CRC over pvalue 0 (reference §2.5)", ["T0 A", "Q0 P5"]),
    ("S3 A36e*4c", "minimal lowercase hex (reference §2.5)", ["S3 A36e", "Q0 P5"]),
    (f"T01 A*{_crc('T', 1, 'A')}", "leading zero in the request value (reference §2.6: digits do not count)",
     ["T1 A", "Q0 P5"]),
    ("T0 A0*e", "a zero written as digits: value 0, not None (protocol.cpp DecodeResponse)", ["T0 A0", "Q0 P5"]),
    (f"T0 P0005*{_crc('T', 0, 'P', 5)}", "leading zeros in the parameter value", ["T0 P5", "Q0 P5"]),
    (f"T101 A*{_crc('T', 1, 'A')}", "over-long request value keeps its low 8 bits", ["T1 A", "Q0 P5"]),
    (f"T0 P10005*{_crc('T', 0, 'P', 5)}", "over-long parameter value keeps its low 16 bits", ["T0 P5", "Q0 P5"]),
    ("T0 A*0e", "leading zero in the CRC", ["T0 A", "Q0 P5"]),
    ("T0 A*10e", "over-long CRC keeps its low 8 bits", ["T0 A", "Q0 P5"]),
    ("T A*e", "empty request value is 0 (protocol.cpp)", ["T0 A", "Q0 P5"]),
    ("Q4 A*", "empty CRC is 0 (Q4 A's CRC is 0)", ["Q4 A", "Q0 P5"]),
    ("T0 A*", "empty CRC that is not 0: mismatch", ["error"]),
    ("T0 A*E", "uppercase hex is an error, noticed before the newline", ["error", "Q0 P5"]),
    ("T0 A*f", "CRC mismatch, noticed at the newline: the next line is eaten", ["error"]),
    ("T0 A*e\r", "CR ends a message like LF (the LF after it is skipped)", ["T0 A", "Q0 P5"]),
    ("\r\n\nT0 A*e", "leading CR/LF are skipped", ["T0 A", "Q0 P5"]),
    ("C0 A*e", "not a request code", ["error", "Q0 P5"]),
    ("T0 G*e", "not a parameter code", ["error", "Q0 P5"]),
    ("T0 AA*e", "a second parameter code", ["error", "Q0 P5"]),
    ("T0  A*e", "two spaces", ["error", "Q0 P5"]),
    ("T0 A", "line cut short: its newline is the error, the next line is eaten", ["error"]),
    ("T0 A*e\x00", "NUL before the newline", ["error", "Q0 P5"]),
    ("\xffT0 A*e", "a byte above 0x7f", ["error", "Q0 P5"]),
    ("E0 F*14", "E0 E9 and E0 F share a CRC (reference §2.6)", ["E0 F", "Q0 P5"]),
    ("a", "a bad first byte right after a frame (the phantom quirk when enabled)", ["error", "Q0 P5"]),
    ("T0 A*e" * 3, "three frames run together without newlines", ["error", "Q0 P5"]),
]


def _reference(wire: bytes, *, phantoms: bool = False, decoder: p.ResponseDecoder | None = None) -> list[object]:
    """The automaton alone, one byte at a time."""
    decoder = decoder or p.ResponseDecoder(phantoms=phantoms)
    events: list[object] = []
    for byte in wire:
        decoder._step(byte, events)
    return events


def _shown(events: list[object]) -> list[str]:
    return ["error" if isinstance(e, p.DecodeError) else str(e) for e in events]


def _assert_agrees(wire: bytes, *, phantoms: bool = False) -> None:
    """Fed whole, cut in two at every offset, and fed again to a decoder whose memo has seen it all."""
    expected = _reference(wire, phantoms=phantoms)
    assert p.ResponseDecoder(phantoms=phantoms).feed(wire) == expected
    for cut in range(1, len(wire)):
        decoder = p.ResponseDecoder(phantoms=phantoms)
        assert decoder.feed(wire[:cut]) + decoder.feed(wire[cut:]) == expected, cut
    warm = p.ResponseDecoder(phantoms=phantoms)
    reference = p.ResponseDecoder(phantoms=phantoms)
    assert warm.feed(wire) == _reference(wire, decoder=reference)
    assert warm.feed(wire) == _reference(wire, decoder=reference)
    assert warm.errors == reference.errors


@pytest.mark.parametrize("phantoms", [False, True])
@pytest.mark.parametrize(("line", "rule", "events"), SPELLINGS, ids=[row[1] for row in SPELLINGS])
def test_spellings_inside_a_block(line: str, rule: str, events: list[str], phantoms: bool) -> None:
    wire = (GOOD + line + "\n" + GOOD).encode("latin-1")
    _assert_agrees(wire, phantoms=phantoms)
    good = _shown(p.ResponseDecoder().feed(GOOD.encode()))
    assert _shown(p.ResponseDecoder().feed(wire)) == good + events + good[1:]


def test_block_keeps_the_phantom_source() -> None:
    """A block's last message is the one a phantom repeats (`phantoms=True`)."""
    wire = (GOOD + "a\n").encode()
    events = p.ResponseDecoder(phantoms=True).feed(wire)
    assert _shown(events) == [*_shown(p.ResponseDecoder().feed(GOOD.encode())), "error", "T1 A"]
    assert events == _reference(wire, phantoms=True)


# ------------------------------------------------------------------------------------------- hypothesis

_values = st.tuples(st.sampled_from(p.REQUEST_CODES), st.integers(0, 255), st.sampled_from(p.PARAM_CODES),
                    st.none() | st.integers(0, 0xFFFF))


def _spelled(fields: tuple[str, int, str, int | None], widths: tuple[int, int, int], over: int,
             end: str) -> bytes:
    """A reply with chosen digit counts (0 = no digits when the value allows), optional excess high digits."""
    code, value, param, pvalue = fields
    crc = p.response_crc(code, value, param, pvalue or 0)

    def digits(number: int, width: int, bits: int) -> str:
        text = format(number | (over << bits) if over else number, "x")
        return "" if width == 0 and number == 0 and not over else text.rjust(width, "0")

    pdigits = "" if pvalue is None else digits(pvalue, widths[1], 16)
    return f"{code}{digits(value, widths[0], 8)} {param}{pdigits}*{digits(crc, widths[2], 8)}{end}".encode()


_piece = st.one_of(
    _values.map(lambda f: _reply(*f).encode() + b"\n"),
    st.builds(_spelled, _values, st.tuples(*[st.integers(0, 5)] * 3), st.sampled_from([0, 0, 1, 0xF]),
              st.sampled_from(["\n", "\n", "\r", "\r\n"])),
    st.binary(max_size=12),
    st.lists(st.sampled_from(list(b"QTRWA PEFB0123456789abcdefA*\n\r")), max_size=16).map(bytes),
)


def _damaged(pieces: list[bytes], flips: list[tuple[int, int]], cut: int) -> bytes:
    wire = bytearray(b"".join(pieces))
    for at, bit in flips:
        if wire:
            wire[at % len(wire)] ^= 1 << bit
    return bytes(wire[: len(wire) - cut if cut < len(wire) else len(wire)])


_streams = st.builds(_damaged, st.lists(_piece, max_size=14),
                     st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 7)), max_size=2),
                     st.integers(0, 6))


@settings(max_examples=200, deadline=None)
@given(_streams, st.booleans())
def test_any_stream_decodes_as_the_automaton_at_every_cut(wire: bytes, phantoms: bool) -> None:
    _assert_agrees(wire, phantoms=phantoms)


@settings(max_examples=100, deadline=None)
@given(_streams, st.lists(st.integers(1, 64), min_size=1, max_size=30))
def test_any_stream_in_any_reads_decodes_as_the_automaton(wire: bytes, sizes: list[int]) -> None:
    decoder = p.ResponseDecoder()
    events: list[object] = []
    pos = i = 0
    while pos < len(wire):
        size = sizes[i % len(sizes)]
        events += decoder.feed(wire[pos: pos + size])
        pos += size
        i += 1
    assert events == _reference(wire)
