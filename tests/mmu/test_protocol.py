"""Codec: every reference vector both ways, fed whole, byte by byte and with trailing bytes; quirks; fuzzing."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fabwire.errors import LocalProtocolError
from fabwire.mmu import protocol as p

DATA = json.loads((Path(__file__).parent / "data" / "vectors.json").read_text())


def _request(code: str, value: int, data: int) -> p.Request:
    return p.make_request(code, value, data)


def _response(code: str, value: int, param: str, pvalue: int | None) -> p.Response:
    return p.RESPONSE_TYPES[param](code, value, pvalue)


def _feeds(decoder_type: type[p.RequestDecoder] | type[p.ResponseDecoder], wire: bytes) -> list[list[object]]:
    """The same bytes fed whole, one byte at a time, and in two uneven halves."""
    whole = decoder_type().feed(wire)
    bytewise_decoder = decoder_type()
    bytewise = [event for i in range(len(wire)) for event in bytewise_decoder.feed(wire[i : i + 1])]
    split_decoder = decoder_type()
    cut = len(wire) // 3
    split = split_decoder.feed(wire[:cut]) + split_decoder.feed(wire[cut:])
    return [whole, bytewise, split]


@pytest.mark.parametrize(("text", "fields"), sorted(DATA["requests"].items()))
def test_request_vectors(text: str, fields: list[int | str]) -> None:
    wire = text.encode() + b"\n"
    message = _request(*fields)  # type: ignore[arg-type]
    assert p.encode(message) == wire
    for events in _feeds(p.RequestDecoder, wire):
        assert events == [message]
    trailing = p.RequestDecoder()
    assert trailing.feed(wire + b"Q0*e") == [message]
    assert not trailing.idle
    assert trailing.feed(b"a\n") == [p.Query(0)]


@pytest.mark.parametrize(("text", "fields"), sorted(DATA["responses"].items()))
def test_response_vectors(text: str, fields: list[int | str | None]) -> None:
    wire = text.encode() + b"\n"
    message = _response(*fields)  # type: ignore[arg-type]
    assert p.encode(message) == wire
    for events in _feeds(p.ResponseDecoder, wire):
        assert events == [message]
    trailing = p.ResponseDecoder()
    assert trailing.feed(wire + b"X0 F") == [message]
    assert trailing.feed(b"0*87\n") == [p.Finished("X", 0, 0)]


@pytest.mark.parametrize(("text", "fields"), sorted(DATA["request_quirks"].items()))
def test_request_quirks_decode(text: str, fields: list[int | str]) -> None:
    for events in _feeds(p.RequestDecoder, text.encode() + b"\n"):
        assert events == [_request(*fields)]  # type: ignore[arg-type]


@pytest.mark.parametrize(("text", "fields"), sorted(DATA["response_quirks"].items()))
def test_response_quirks_decode(text: str, fields: list[int | str | None]) -> None:
    for events in _feeds(p.ResponseDecoder, text.encode() + b"\n"):
        assert events == [_response(*fields)]  # type: ignore[arg-type]


@pytest.mark.parametrize(("wire", "expected"), DATA["request_traces"])
def test_request_error_traces(wire: str, expected: list[str]) -> None:
    for events in _feeds(p.RequestDecoder, wire.encode()):
        messages = [p.encode(e).decode().rstrip("\n") for e in events if isinstance(e, p.Request)]
        assert messages == expected
        assert all(isinstance(e, p.Request | p.DecodeError) for e in events)
        assert any(isinstance(e, p.DecodeError) for e in events) == (wire.count("\n") + wire.count("\r") > len(
            expected))


@pytest.mark.parametrize(("wire", "expected"), DATA["response_traces"])
def test_response_error_traces(wire: str, expected: list[str]) -> None:
    for events in _feeds(p.ResponseDecoder, wire.encode()):
        assert [p.encode(e).decode().rstrip("\n") for e in events if isinstance(e, p.Response)] == expected


def test_crc8_check_value() -> None:
    assert p.crc8(b"123456789") == 0xF4


def test_write_reply_crc_ignores_data_word() -> None:
    assert p.response_crc("W", 0x14, "A", 0) == 0x52
    assert p.request_crc("W", 0x14, 0x14) == 0x94


def test_uppercase_hex_is_an_error() -> None:
    events = p.RequestDecoder().feed(b"T0*A4\n")
    assert len(events) == 1
    assert isinstance(events[0], p.DecodeError)
    assert "hex" in str(events[0].exception())


def test_encoder_refuses_out_of_range() -> None:
    with pytest.raises(LocalProtocolError):
        p.ToolChange(256)
    with pytest.raises(LocalProtocolError):
        p.Write(1, 0x10000)
    with pytest.raises(LocalProtocolError):
        p.Accepted("C", 0)
    with pytest.raises(LocalProtocolError):
        p.make_request("C", 0)


# ------------------------------------------------------------------------------------------- hypothesis

requests = st.one_of(
    st.builds(p.Write, st.integers(0, 255), st.integers(0, 0xFFFF)),
    *[st.builds(cls, st.integers(0, 255)) for code, cls in p.REQUEST_TYPES.items() if code != "W"],
)
responses = st.builds(
    lambda cls, code, value, pvalue: cls(code, value, pvalue),
    st.sampled_from(list(p.RESPONSE_TYPES.values())),
    st.sampled_from(list(p.REQUEST_CODES)),
    st.integers(0, 255),
    st.none() | st.integers(0, 0xFFFF),
)


@given(st.lists(requests, max_size=8), st.integers(1, 7))
def test_request_round_trip(messages: list[p.Request], chunk: int) -> None:
    wire = b"".join(p.encode(m) for m in messages)
    decoder = p.RequestDecoder()
    events = [e for i in range(0, len(wire), chunk) for e in decoder.feed(wire[i : i + chunk])]
    assert events == messages


@given(st.lists(responses, max_size=8), st.integers(1, 7))
def test_response_round_trip(messages: list[p.Response], chunk: int) -> None:
    wire = b"".join(p.encode(m) for m in messages)
    decoder = p.ResponseDecoder()
    events = [e for i in range(0, len(wire), chunk) for e in decoder.feed(wire[i : i + chunk])]
    assert events == messages


_alphabet = st.sampled_from(list(b"QTLMUXPSBEWKFfHRARPEFB0123456789abcdefA* \n\r\x00\xff"))


@settings(max_examples=300)
@given(st.lists(_alphabet, max_size=200).map(bytes) | st.binary(max_size=200), st.integers(1, 9))
def test_decoders_are_total_and_agree_across_chunking(data: bytes, chunk: int) -> None:
    for decoder_type in (p.RequestDecoder, p.ResponseDecoder):
        whole = decoder_type().feed(data)
        chunked_decoder = decoder_type()
        chunked = [e for i in range(0, len(data), chunk) for e in chunked_decoder.feed(data[i : i + chunk])]
        assert whole == chunked
        kinds = (p.Request, p.DecodeError) if decoder_type is p.RequestDecoder else (p.Response, p.DecodeError)
        assert all(isinstance(e, kinds) for e in whole)
        assert all(len(e.data) <= 32 for e in whole if isinstance(e, p.DecodeError))


@given(st.lists(requests, min_size=1, max_size=5), st.binary(max_size=40))
def test_fast_path_matches_automaton(messages: list[p.Request], noise: bytes) -> None:
    """Whole-line fast decoding and byte-by-byte automaton decoding give identical events."""
    wire = noise + b"\n\n" + b"".join(p.encode(m) for m in messages) + noise
    fast = p.RequestDecoder().feed(wire)
    slow_decoder = p.RequestDecoder()
    slow = [e for b in wire for e in slow_decoder.feed(bytes([b]))]
    assert fast == slow


def test_memory_stays_bounded_on_endless_garbage() -> None:
    decoder = p.ResponseDecoder()
    for _ in range(200):
        decoder.feed(b"Zzzzzzzzzz" * 100)
        decoder.feed(b"T0 P" + b"f" * 1000)
    assert len(decoder._line) <= 32
    assert len(decoder._memo) <= 4096
