"""Every decoder is total: any input gives messages (or the module's documented error), nothing else, and a
flood of junk leaves only bounded state behind."""

from __future__ import annotations

import contextlib
import os
import tempfile
import tracemalloc
from collections.abc import Callable, Iterator

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fabwire.errors import InputError, RemoteProtocolError
from fabwire.lineus import protocol as lp
from fabwire.mmu import protocol as mp
from fabwire.transport.tap import FROM_DEVICE, TO_DEVICE, TraceRecord, read_trace
from fabwire.xyz import protocol as xp
from fabwire.xyz.models import find_model
from fabwire.xyz.status import Status
from fabwire.xyz.threew import ThreeWFile, read_3w, write_3w

SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FLOOD = 2_000_000
"""Bytes of junk pushed through each decoder in the bounded-memory checks."""
RETAINED = 512 * 1024
"""What a decoder may still hold after the flood."""


def mixed(frames: list[bytes]) -> st.SearchStrategy[list[bytes]]:
    """Chunks built from valid frames, frames with a flipped bit, truncated frames and raw junk."""
    frame = st.sampled_from(frames)
    flipped = st.tuples(frame, st.integers(0, 10_000), st.integers(0, 7)).map(
        lambda t: t[0] if not t[0] else t[0][: t[1] % len(t[0])] + bytes([t[0][t[1] % len(t[0])] ^ (1 << t[2])])
        + t[0][t[1] % len(t[0]) + 1 :])
    cut = st.tuples(frame, st.integers(0, 200)).map(lambda t: t[0][: t[1]])
    pieces = st.lists(st.one_of(frame, flipped, cut, st.binary(max_size=40)), max_size=20).map(b"".join)
    return st.lists(pieces, min_size=1, max_size=4)


def flood_chunks(seed: bytes) -> Iterator[bytes]:
    """Two megabytes of junk in 4 KiB reads: never a terminator a decoder could rest on."""
    block = (seed * (4096 // max(1, len(seed)) + 1))[:4096]
    for _ in range(FLOOD // 4096):
        yield block


def retained_after(feed: Callable[[bytes], object], seed: bytes) -> int:
    """Memory still allocated after the flood (the decoder is kept alive by the caller)."""
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for chunk in flood_chunks(seed):
            feed(chunk)
        return tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()


# ------------------------------------------------------------------------------------------------- MMU3

MMU_REQUESTS = [mp.encode_request(r) for r in (
    mp.Query(0), mp.ToolChange(2), mp.Load(4), mp.Unload(0), mp.Cut(1), mp.Eject(3), mp.Home(0), mp.Reset(0),
    mp.Read(0x22), mp.Write(0x22, 500), mp.ButtonPress(1), mp.FSensorState(1), mp.Version(1),
)]
MMU_RESPONSES = [mp.encode_response(r) for r in (
    mp.Accepted("T", 2), mp.Rejected("L", 1), mp.Processing("T", 1, 5), mp.CommandError("T", 1, 0x8001),
    mp.Finished("T", 1), mp.ButtonPressed("Q", 0, 1), mp.Accepted("R", 0x22, 360), mp.Finished("X", 0),
)]


@SETTINGS
@given(mixed(MMU_REQUESTS))
def test_mmu_request_decoder_is_total(chunks: list[bytes]) -> None:
    decoder = mp.RequestDecoder()
    for chunk in chunks:
        for event in decoder.feed(chunk):
            assert isinstance(event, mp.Request | mp.DecodeError)
            if isinstance(event, mp.Request):
                assert mp.RequestDecoder().feed(mp.encode_request(event)) == [event]
            else:
                assert isinstance(event.exception(), RemoteProtocolError)
                assert len(event.data) <= 32


@SETTINGS
@given(mixed(MMU_RESPONSES))
def test_mmu_response_decoder_is_total(chunks: list[bytes]) -> None:
    decoder = mp.ResponseDecoder()
    for chunk in chunks:
        for event in decoder.feed(chunk):
            assert isinstance(event, mp.Response | mp.DecodeError)
            if isinstance(event, mp.Response):
                assert mp.ResponseDecoder().feed(mp.encode_response(event)) == [event]
            else:
                assert isinstance(event.exception(), RemoteProtocolError)
                assert len(event.data) <= 32


# ------------------------------------------------------------------------------------------------ Line-us

LINEUS_COMMANDS = [b"G01 X1000 Y0 Z0\x00", b"G28\n", b"M114\r\n", b"G54 X10 Y-5 S1.5\x00", b"M550 Pbob\x00",
                   b"G01 X1100.25 Y-200.5\x00", b"M115\x00", b"M122\x00", b"G00 Z1000\x00", b"M28 S3\x00"]
LINEUS_REPLIES = [b"ok X:1000.00 Y:0.00 Z:0.00\r\n\x00", b'error INFO:"unknown command"\r\n\x00',
                  b'hello VERSION:"3.1.1 Apr 23 2021 10:10:10" NAME:line-us SERIAL:123456\r\n\x00',
                  b"ok\r\n\x00", b'ok INFO:"M122" A:"1"\r\n\x00', b'hello VERSION:"" NAME:x SERIAL:1\r\n\x00']


@SETTINGS
@given(mixed(LINEUS_COMMANDS))
def test_lineus_command_reader_and_parser_are_total(chunks: list[bytes]) -> None:
    reader = lp.CommandReader()
    for chunk in chunks:
        for item in reader.feed(chunk):
            assert isinstance(item, lp.Line | lp.BadLine)
            if isinstance(item, lp.BadLine):
                assert item.reason
                continue
            try:
                command: lp.Command | RemoteProtocolError = lp.parse_command(item.text)
            except RemoteProtocolError as exc:
                command = exc
            if isinstance(command, RemoteProtocolError):
                assert str(command)
            else:
                assert isinstance(command, lp.Command)
                assert isinstance(command.text(), str)


@SETTINGS
@given(mixed(LINEUS_REPLIES))
def test_lineus_reply_reader_is_total(chunks: list[bytes]) -> None:
    reader = lp.ReplyReader(max_size=4096)
    for chunk in chunks:
        reader.feed(chunk)
        for _ in range(len(chunk) + 2):
            try:
                message: lp.Message | RemoteProtocolError | None = reader.next_message()
            except RemoteProtocolError as exc:
                message = exc
            if isinstance(message, RemoteProtocolError):
                assert str(message)
                continue
            if message is None:
                break
            assert isinstance(message, lp.Reply | lp.Hello)
        else:
            pytest.fail("the reply reader kept producing messages from a finite input")
        assert len(reader.pending) <= 4096 + len(chunk)


@SETTINGS
@given(st.one_of(st.text(max_size=200), st.sampled_from(LINEUS_REPLIES).map(lambda b: b[:-3].decode()),
                 st.builds(lambda v, rest: f'hello VERSION:"{v}" {rest}', st.text(max_size=20),
                           st.text(max_size=40))))
def test_lineus_hello_parser_is_total(text: str) -> None:
    try:
        message: lp.Message | RemoteProtocolError = lp.parse_message(text)
    except RemoteProtocolError as exc:
        message = exc
    if isinstance(message, RemoteProtocolError):
        assert str(message)
        return
    if isinstance(message, lp.Hello):
        assert isinstance(message.firmware_major, int)
        assert all(isinstance(part, int) for part in message.firmware)
        assert lp.parse_message(message.text()) == message
    else:
        assert isinstance(message, lp.Reply)
        assert isinstance(message.as_dict(), dict)


# ------------------------------------------------------------------------------------------------- XYZ

XYZ_REPLIES = [b"a:1\n", b"j:9511,0\n", b"o:p8,t1,c1,a+\n", b"$\n", b"ok\n", b"ok \n", b"E4$\n", b"E1\n",
               b'load:{"stat":"heat","extemp":"24"}\n', b'calibratejr:{"stat":"ok",438,1,2}\n', b"-469\n",
               b"V:5.1.0\n", b"t:1,210,215\n", b"\r\n"]
XYZ_COMMANDS = [xp.Query("a"), xp.Query("b"), xp.GetZOffset(), xp.Home(), xp.UploadDidFinish(),
                xp.Upload("x.3w", 100), xp.SetBuzzer(True), xp.Flow("load", "new"), xp.Jog("x", 10)]


@SETTINGS
@pytest.mark.parametrize("link", list(xp.Link), ids=lambda link: link.name.lower())
@given(chunks=mixed(XYZ_REPLIES), which=st.integers(0, len(XYZ_COMMANDS) - 1), step=st.floats(0, 1))
def test_xyz_reply_reader_is_total(link: xp.Link, chunks: list[bytes], which: int, step: float) -> None:
    reader = xp.ReplyReader(link)
    command = XYZ_COMMANDS[which]
    now = 0.0
    reader.send(command, now, timeout=2.0)
    seen: list[xp.ReaderEvent] = []
    for chunk in chunks:
        now += step
        reader.receive(chunk, now)
        while (event := reader.next_event(now)) is not None:
            assert isinstance(event, xp.Reply | xp.ErrorReply | xp.NoReply | xp.ActionStat)
            seen.append(event)
    while (event := reader.next_event(now + 10)) is not None:
        seen.append(event)
    answers = [e for e in seen if not isinstance(e, xp.ActionStat)]
    assert len(answers) == 1, "exactly one outcome for the command in flight: a reply, an error or none"
    assert answers[0].command is command
    assert not reader.busy


@SETTINGS
@given(mixed([b"XYZv3/query=a\n", b"XYZv3/config=buzzer:on\r\n", b"XYZv3/upload=a.3w,20,SaveToSD\n",
              xp.encode_block(0, b"0123456789"), xp.encode_block(1, b"abcdefghij", crc=False), xp.FINISH,
              b"XYZv3/action=home", b"\r\n"]), st.floats(0, 0.1))
def test_xyz_device_splitter_and_block_reader_are_total(chunks: list[bytes], step: float) -> None:
    decoder = xp.DeviceDecoder(gap=0.03, upload_idle=1.0)
    now = 0.0
    events: list[xp.DeviceEvent] = []
    for chunk in chunks:
        now += step
        events += decoder.feed(chunk, now)
        events += decoder.poll(now)
    events += decoder.eof(now + 5)
    for event in events:
        assert isinstance(event, xp.Received | xp.Block | xp.UploadStalled | xp.Garbage)
        if isinstance(event, xp.Block):
            assert len(event.data) <= event.length
            assert isinstance(event.crc_ok, bool)
        if isinstance(event, xp.Received):
            assert isinstance(event.command, xp.Command)


@SETTINGS
@given(st.text(max_size=300))
def test_xyz_command_parser_is_total(text: str) -> None:
    command = xp.parse_command(text)
    assert isinstance(command, xp.Command)


STATUS_LINE = st.one_of(
    st.builds(lambda letter, value: f"{letter}:{value}", st.sampled_from("abcdefijLmopstvnXlzV4wWk"),
              st.text(max_size=40)),
    st.text(max_size=40),
)


@SETTINGS
@given(st.lists(STATUS_LINE, max_size=25), st.lists(STATUS_LINE, max_size=5))
def test_xyz_status_parser_is_total(lines: list[str], update: list[str]) -> None:
    status = Status.parse(lines).update(update)
    assert status.block_size > 0  # an upload must always get a usable block size
    assert isinstance(status.state_name, str)
    assert isinstance(status.to_dict(), dict)
    assert isinstance(status.lines(), list)
    for word in status.error_words:
        assert word.meaning


@SETTINGS
@given(st.text(max_size=120))
def test_xyz_stat_line_parser_is_total(line: str) -> None:
    stat = xp.parse_stat_line(line)
    assert stat is None or isinstance(stat, xp.ActionStat)


@SETTINGS
@given(mixed(XYZ_REPLIES))
def test_xyz_upload_ack_counter_is_total(chunks: list[bytes]) -> None:
    counter = xp.AckCounter()
    total = 0
    for chunk in chunks:
        acks, error = counter.feed(chunk)
        total += acks
        assert acks >= 0
        assert error is None or error >= 0
    assert total <= b"".join(chunks).count(b"\n")


SAMPLE_3W = write_3w(b";machine = dv1MW0A000\nG28\nG1 X10 Y10 E1\nM84\n", find_model("dv1MW0A000"))


@SETTINGS
@given(st.one_of(
    st.binary(max_size=9000),
    st.tuples(st.integers(0, len(SAMPLE_3W) - 1), st.integers(0, 255)).map(
        lambda t: SAMPLE_3W[: t[0]] + bytes([SAMPLE_3W[t[0]] ^ t[1]]) + SAMPLE_3W[t[0] + 1 :]),
    st.integers(0, len(SAMPLE_3W)).map(lambda n: SAMPLE_3W[:n]),
    st.binary(max_size=64).map(lambda tail: SAMPLE_3W[:8192] + tail),
))
def test_threew_reader_is_total(data: bytes) -> None:
    try:
        result: ThreeWFile | InputError = read_3w(data)
    except InputError as exc:
        result = exc
    if isinstance(result, InputError):
        assert str(result)
        return
    assert isinstance(result, ThreeWFile)
    assert isinstance(result.gcode, bytes)


TRACE_LINES = [b'{"trace":"fabwire","version":1}', b'{"t":0.1,"dir":">","data":"abc"}',
               b'{"t":0.2,"dir":"<","data":"\\u00ff"}', b'{"t":0.3,"event":"open","detail":"x"}', b"[]",
               b'{"t":"x","dir":">","data":1}', b"null", b'{"t":1,"dir":"?","data":""}', b"\xff\xfe"]


@SETTINGS
@given(st.lists(st.one_of(st.sampled_from(TRACE_LINES), st.binary(max_size=30)), max_size=8))
def test_trace_reader_is_total(lines: list[bytes]) -> None:
    fd, name = tempfile.mkstemp(suffix=".jsonl")
    try:
        with os.fdopen(fd, "wb") as out:
            out.write(b"\n".join(lines))
        try:
            records: list[TraceRecord] | InputError = list(read_trace(name))
        except InputError as exc:
            records = exc
        if isinstance(records, InputError):
            assert str(records)
            return
        for record in records:
            assert isinstance(record, TraceRecord)
            assert record.direction in (None, TO_DEVICE, FROM_DEVICE)
            assert isinstance(record.data, bytes)
    finally:
        os.unlink(name)


# ----------------------------------------------------------------------------------------- bounded memory


def _xyz_reader(link: xp.Link) -> Callable[[bytes], object]:
    reader = xp.ReplyReader(link)
    reader.send(xp.Query("a"), 0.0, timeout=1e9)

    def feed(chunk: bytes) -> None:
        reader.receive(chunk, 0.0)
        reader.next_event(0.0)
    return feed


def _lineus_replies() -> Callable[[bytes], object]:
    reader = lp.ReplyReader()

    def feed(chunk: bytes) -> None:
        reader.feed(chunk)
        with contextlib.suppress(RemoteProtocolError):
            reader.next_message()
    return feed


def _xyz_device() -> Callable[[bytes], object]:
    decoder = xp.DeviceDecoder()
    return lambda chunk: decoder.feed(chunk, 0.0)


FLOODED: dict[str, Callable[[], Callable[[bytes], object]]] = {
    "mmu-requests": lambda: mp.RequestDecoder().feed,
    "mmu-responses": lambda: mp.ResponseDecoder().feed,
    "lineus-commands": lambda: lp.CommandReader().feed,
    "lineus-replies": _lineus_replies,
    "xyz-replies-serial": lambda: _xyz_reader(xp.Link.SERIAL),
    "xyz-replies-wifi": lambda: _xyz_reader(xp.Link.WIFI),
    "xyz-device": _xyz_device,
    "xyz-acks": lambda: xp.AckCounter().feed,
}


@pytest.mark.parametrize("junk", [b"A", b"T1", b"XYZv3/q", b"\xff\x00"], ids=["letters", "mmu", "xyz", "binary"])
@pytest.mark.parametrize("name", sorted(FLOODED))
def test_a_flood_without_terminators_leaves_bounded_state(name: str, junk: bytes) -> None:
    feed = FLOODED[name]()
    assert retained_after(feed, junk) < RETAINED
