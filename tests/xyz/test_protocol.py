"""The XYZv3 codec: command bytes, the host's reply reader per link kind, block framing, the device splitter."""

from __future__ import annotations

import json
import math
import re
import struct
import zlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fabwire.errors import LocalProtocolError
from fabwire.xyz import protocol as p
from fabwire.xyz.protocol import (
    ActionStat,
    Block,
    DeviceDecoder,
    ErrorReply,
    Garbage,
    Link,
    NoReply,
    Received,
    Reply,
    ReplyReader,
    UploadStalled,
)

VECTORS: list[tuple[p.Command, str]] = [
    (p.Query("a"), "query=a"),
    (p.Query("jt"), "query=jt"),
    (p.SetAutoLevel(False), "config=autolevel:off"),
    (p.SetBuzzer(True), "config=buzzer:on"),
    (p.GetZOffset(), "config=zoffset:get"),
    (p.SetZOffset(261), "config=zoffset:set[261]"),
    (p.SetZOffset(-469), "config=zoffset:set[-469]"),
    (p.NudgeZOffset(True), "action=zoffset:up"),
    (p.RestoreDefaults(), "config=restoredefault:on"),
    (p.SetLanguage("fr"), "config=lang:[fr]"),
    (p.SetEnergy(3), "config=energy:[3]"),
    (p.SetName("Office"), "config=name:[Office]"),
    (p.SetLife(7), "config=life:[7]"),
    (p.JoinWifi("home", "secret", 6), "config=ssid:[home,secret,6]"),
    (p.LeaveWifi(), "config=disconnectap"),
    (p.PlaceObject(), "config=engrave:placeobject"),
    (p.PrintControl("pause"), "config=print[pause]"),
    (p.UnlockFilament("a", 1591), "config=pda:[1591]"),
    (p.TagInfo(), "config=taginfo"),
    (p.Signature(), "config=signature:[get]"),
    (p.Uid(), "config=uid"),
    (p.Home(), "action=home"),
    (p.Jog("y", 150), 'action=jog:{"axis":"y","dir":"+","len":"150"}'),
    (p.Jog("z", -5), 'action=jog:{"axis":"z","dir":"-","len":"5"}'),
    (p.Flow("load", "new"), "action=load:new"),
    (p.Flow("unload", "retry"), "action=unload:retry"),
    (p.Flow("cleannozzle", "cancel"), "action=cleannozzle:cancel"),
    (p.Flow("calibratejr", "detectorok"), "action=calibratejr:detectorok"),
    (p.Upload("MyTest.gcode", 18688), "upload=MyTest.gcode,18688"),
    (p.Upload("a.3w", 10, save_to_sd=True), "upload=a.3w,10,SaveToSD"),
    (p.FirmwareUpload("temp.bin", 20000), "firmware=temp.bin,20000"),
    (p.UploadDidFinish(), "uploadDidFinish"),
]


@pytest.mark.parametrize(("command", "body"), VECTORS)
def test_encode_and_parse_back(command: p.Command, body: str) -> None:
    assert command.body == body
    assert p.parse_command(body) == command


def test_terminators_per_link() -> None:
    assert p.encode(p.Query("a"), Link.SERIAL) == b"XYZv3/query=a\n"
    assert p.encode(p.Query("a"), Link.WIFI) == b"XYZv3/query=a\r\n"
    assert p.encode(p.UploadDidFinish(), Link.WIFI) == b"XYZv3/uploadDidFinish"


@pytest.mark.parametrize("bad", [
    lambda: p.Query("a b"), lambda: p.SetZOffset(99999), lambda: p.SetLanguage("english"),
    lambda: p.SetEnergy(12), lambda: p.SetName("x]y"), lambda: p.Jog("w", 1), lambda: p.Jog("x", 0),
    lambda: p.Flow("load", "explode"), lambda: p.Upload("a,b", 1), lambda: p.Upload("a", 0),
    lambda: p.PrintControl("stop"), lambda: p.JoinWifi("a,b", "c"),
])
def test_commands_refuse_what_the_wire_cannot_carry(bad: object) -> None:
    with pytest.raises(LocalProtocolError):
        bad()  # type: ignore[operator]


def test_block_framing_exact() -> None:
    data = bytes(range(256)) * 72  # 18432 bytes
    blocks = list(p.iter_blocks(data, 8192))
    assert [len(b) for b in blocks] == [8204, 8204, 2060]
    assert blocks[1][:8] == bytes.fromhex("00000001 00002000")
    assert blocks[2][:8] == bytes.fromhex("00000002 00000800")
    assert blocks[0][-4:] == struct.pack(">I", zlib.crc32(data[:8192]))
    assert next(iter(p.iter_blocks(b"abc", 8192, crc=False))) == bytes.fromhex("00000000 00000003") + b"abc" + bytes(4)
    assert p.block_size_from_packet(8) == 8192
    assert p.block_size_from_packet(0) == 8192


def test_stat_lines() -> None:
    assert p.stat_line("load", "heat", extemp="24") == 'load:{"stat":"heat","extemp":"24"}'
    stat = p.parse_stat_line('calibratejr:{"stat":"ok",438,453,453,437,445,443,412,420,424}')
    assert stat == ActionStat("calibratejr", "ok", (438, 453, 453, 437, 445, 443, 412, 420, 424))
    assert p.parse_stat_line("j:9511,0") is None


# ------------------------------------------------------------------------------------------- reply reader


def run_reader(link: Link, command: p.Command, wire: bytes, *, bytewise: bool = False,
               later: float = 0.0) -> list[object]:
    reader = ReplyReader(link)
    reader.send(command, now=0.0)
    chunks = [wire[i : i + 1] for i in range(len(wire))] if bytewise else [wire]
    events: list[object] = []
    for chunk in chunks:
        reader.receive(chunk, 0.01)
        while (event := reader.next_event(0.01)) is not None:
            events.append(event)
    if later:
        while (event := reader.next_event(later)) is not None:
            events.append(event)
    return events


@pytest.mark.parametrize("bytewise", [False, True])
def test_full_status_both_links(bytewise: bool) -> None:
    wire = b"b:20\nj:9511,0\no:p8,t1,c1,a+\n$\n"
    for link in Link:
        events = run_reader(link, p.Query("a"), wire, bytewise=bytewise)
        assert events == [Reply(p.Query("a"), ("b:20", "j:9511,0", "o:p8,t1,c1,a+"))]


def test_partial_query_wifi_ends_when_letters_seen() -> None:
    events = run_reader(Link.WIFI, p.Query("jt"), b"j:9511,0\nt:1,22,0\n")
    assert events == [Reply(p.Query("jt"), ("j:9511,0", "t:1,22,0"))]
    # serial waits for `$`
    assert run_reader(Link.SERIAL, p.Query("jt"), b"j:9511,0\nt:1,22,0\n") == []
    assert run_reader(Link.SERIAL, p.Query("jt"), b"j:9511,0\nt:1,22,0\n$\n")[0] == Reply(
        p.Query("jt"), ("j:9511,0", "t:1,22,0"))


def test_wifi_partial_query_missing_letter_settles() -> None:
    events = run_reader(Link.WIFI, p.Query("jV"), b"j:9511,0\n", later=1.0)
    assert events == [Reply(p.Query("jV"), ("j:9511,0",))]


def test_config_ack_per_link() -> None:
    assert run_reader(Link.WIFI, p.SetBuzzer(False), b"") == [Reply(p.SetBuzzer(False))]
    events = run_reader(Link.SERIAL, p.SetBuzzer(False), b"ok\n$\n", bytewise=True)
    assert events == [Reply(p.SetBuzzer(False), (), acked=True)]


def test_zoffset_number_both_links() -> None:
    for link in Link:
        assert run_reader(link, p.GetZOffset(), b"-469\n$\n") == [Reply(p.GetZOffset(), ("-469",))]


def test_error_reply_and_timeout() -> None:
    assert run_reader(Link.SERIAL, p.Query("a"), b"E7$\n") == [ErrorReply(p.Query("a"), 7)]
    assert run_reader(Link.SERIAL, p.Query("a"), b"b:1\n", later=10.0) == [NoReply(p.Query("a"), ("b:1",))]


def test_upload_ack_with_trailing_space_and_late_extra_ok() -> None:
    reader = ReplyReader(Link.WIFI)
    reader.send(p.Upload("a.3w", 5), 0.0)
    reader.receive(b"ok \n", 0.0)
    assert reader.next_event(0.0) == Reply(p.Upload("a.3w", 5), (), acked=True)
    reader.send(p.UploadDidFinish(), 0.0)
    reader.receive(b"ok\n", 0.0)
    assert isinstance(reader.next_event(0.0), Reply)
    # the extra ok arrives late, inside the next status reply, together with a stale `$`
    reader.send(p.Query("a"), 0.0)
    reader.receive(b"ok\n$\nj:9520,0\nd:0,0,0\n$\n", 0.1)
    assert reader.next_event(0.1) == Reply(p.Query("a"), ("j:9520,0", "d:0,0,0"))
    assert reader.noise == 2


def test_serial_action_stats_and_their_dollars() -> None:
    reader = ReplyReader(Link.SERIAL)
    reader.send(p.Flow("calibratejr", "new"), 0.0)
    reader.receive(b'calibratejr:{"stat":"start"}\n$\ncalibratejr:{"stat":"pressdetector"}\n$\n', 0.0)
    assert reader.next_event(0.0) == Reply(p.Flow("calibratejr", "new"), ('calibratejr:{"stat":"start"}',))
    assert reader.next_event(0.0) == ActionStat("calibratejr", "pressdetector")
    reader.send(p.Query("j"), 0.0)
    reader.receive(b"j:9535,41\n$\n", 0.0)
    assert reader.next_event(0.0) == Reply(p.Query("j"), ("j:9535,41",))
    # an unsolicited stat with its `$` arriving before a status reply must not end that reply
    reader.send(p.Query("a"), 0.0)
    reader.receive(b'load:{"stat":"load"}\n$\nj:9530,12\n$\n', 0.0)
    assert reader.next_event(0.0) == ActionStat("load", "load")
    assert reader.next_event(0.0) == Reply(p.Query("a"), ("j:9530,12",))


def test_wifi_actions_need_no_reply_but_getdata_does() -> None:
    assert run_reader(Link.WIFI, p.Home(), b"") == [Reply(p.Home())]
    cmd = p.Flow("calibratejr", "getdata")
    events = run_reader(Link.WIFI, cmd, b"calibratejr:{335,372,377,352,375,369,365,378,356}\n$\n")
    assert events == [Reply(cmd, ("calibratejr:{335,372,377,352,375,369,365,378,356}",))]


@settings(max_examples=300)
@given(st.binary(max_size=300), st.sampled_from([c for c, _ in VECTORS]), st.sampled_from(list(Link)))
def test_reader_is_total(data: bytes, command: p.Command, link: Link) -> None:
    reader = ReplyReader(link)
    reader.send(command, 0.0)
    reader.receive(data, 0.0)
    while reader.next_event(100.0) is not None:
        pass
    assert not reader.busy


# -------------------------------------------------------------------------------------- device splitter


def split(wire: bytes, *, bytewise: bool = False, eof: bool = False, gap_at: float | None = None) -> list[object]:
    dec = DeviceDecoder(gap=0.03)
    events: list[object] = []
    chunks = [wire[i : i + 1] for i in range(len(wire))] if bytewise else [wire]
    for chunk in chunks:
        events += dec.feed(chunk, 0.0)
    if gap_at is not None:
        events += dec.poll(gap_at)
    if eof:
        events += dec.eof(0.0)
    return events


def bodies(events: list[object]) -> list[str]:
    return [e.command.body for e in events if isinstance(e, Received)]


@pytest.mark.parametrize("bytewise", [False, True])
@pytest.mark.parametrize("term", [b"\n", b"\r\n"])
def test_splitter_terminated(term: bytes, bytewise: bool) -> None:
    wire = b"XYZv3/query=a" + term + b"XYZv3/config=buzzer:off" + term
    assert bodies(split(wire, bytewise=bytewise)) == ["query=a", "config=buzzer:off"]


def test_splitter_two_commands_in_one_packet_without_terminators() -> None:
    events = split(b"XYZv3/action=load:newXYZv3/query=j")
    assert bodies(events) == ["action=load:new"]  # the second waits for the gap
    assert bodies(split(b"XYZv3/action=load:newXYZv3/query=j", gap_at=0.05)) == ["action=load:new", "query=j"]


def test_splitter_idle_gap_and_deadline() -> None:
    dec = DeviceDecoder(gap=0.03)
    assert dec.feed(b"XYZv3/query=a", 1.0) == []
    assert dec.next_deadline() == pytest.approx(1.03)
    assert dec.poll(1.02) == []
    assert bodies(dec.poll(1.031)) == ["query=a"]
    assert dec.next_deadline() is None


def test_splitter_eof_flushes() -> None:
    assert bodies(split(b"XYZv3/config=autolevel:off", eof=True)) == ["config=autolevel:off"]


def test_upload_stream_with_binary_right_after_command() -> None:
    data = bytes(range(256)) * 40  # 10240 bytes: one full block and a 2048-byte one
    wire = b"XYZv3/upload=temp.gcode," + str(len(data)).encode()
    wire += b"".join(p.iter_blocks(data, 8192, crc=False)) + b"XYZv3/uploadDidFinish"
    for bytewise in (False, True):
        events = split(wire, bytewise=bytewise)
        assert isinstance(events[0], Received)
        assert events[0].command == p.Upload("temp.gcode", 10240)
        blocks = [e for e in events if isinstance(e, Block)]
        assert [b.index for b in blocks] == [0, 1]
        assert b"".join(b.data for b in blocks) == data
        assert all(b.crc_ok for b in blocks)
        assert isinstance(events[-1], Received)
        assert events[-1].command == p.UploadDidFinish()


def test_upload_last_block_claims_full_size_and_zero_length_block() -> None:
    dec = DeviceDecoder()
    dec.feed(b"XYZv3/upload=x,10\n", 0.0)
    events = dec.feed(struct.pack(">II", 0, 8192) + b"0123456789" + bytes(4) + b"XYZv3/uploadDidFinish", 0.0)
    assert isinstance(events[0], Block)
    assert events[0].data == b"0123456789"
    dec = DeviceDecoder()
    dec.feed(b"XYZv3/upload=x,8192\n" + p.encode_block(0, bytes(8192), crc=False), 0.0)
    events = dec.feed(struct.pack(">II", 1, 0) + bytes(4) + b"XYZv3/uploadDidFinish", 0.0)
    assert isinstance(events[0], Block)
    assert events[0].length == 0
    assert isinstance(events[1], Received)


def test_bad_crc_is_flagged() -> None:
    block = Block(0, 3, b"abc", 1234)
    assert not block.crc_ok
    assert Block(0, 3, b"abc", zlib.crc32(b"abc")).crc_ok


def test_upload_stall_returns_to_text() -> None:
    dec = DeviceDecoder(upload_idle=5.0)
    dec.feed(b"XYZv3/upload=x,100\n" + bytes(20), 0.0)
    assert dec.uploading
    assert dec.poll(6.0) == [UploadStalled(0, 100)]
    assert bodies(dec.feed(b"XYZv3/query=a\n", 7.0)) == ["query=a"]


def test_garbage_is_reported_not_fatal() -> None:
    events = split(b"hello\nXYZv3/query=a\n")
    assert events[0] == Garbage(b"hello")
    assert bodies(events) == ["query=a"]


@settings(max_examples=300)
@given(st.lists(st.binary(max_size=60), max_size=8))
def test_splitter_is_total(chunks: list[bytes]) -> None:
    dec = DeviceDecoder()
    for i, chunk in enumerate(chunks):
        dec.feed(chunk, float(i))
        dec.poll(i + 0.5)
    dec.eof(100.0)
    dec.poll(1000.0)


@given(st.sampled_from([c for c, _ in VECTORS if not isinstance(c, p.Upload | p.FirmwareUpload)]),
       st.sampled_from([b"", b"\n", b"\r\n"]))
def test_every_command_survives_every_terminator(command: p.Command, term: bytes) -> None:
    wire = p.PREFIX + command.body.encode() + term
    events = split(wire, bytewise=True, eof=True)
    assert bodies(events) == [command.body]


@settings(max_examples=200)
@given(st.lists(st.tuples(st.sampled_from([c for c, _ in VECTORS if not isinstance(c, p.Upload | p.FirmwareUpload)
                                           and not isinstance(c, p.UploadDidFinish)]),
                          st.sampled_from([b"\n", b"\r\n", b""])), min_size=1, max_size=6),
       st.integers(min_value=1, max_value=17))
def test_splitter_recovers_any_command_stream_in_any_chunking(commands: list[tuple[p.Command, bytes]],
                                                              chunk: int) -> None:
    wire = b"".join(p.PREFIX + c.body.encode() + term for c, term in commands)
    dec = DeviceDecoder(gap=0.03)
    events: list[object] = []
    for i in range(0, len(wire), chunk):
        events += dec.feed(wire[i : i + chunk], 0.0)
    events += dec.eof(0.0)
    assert bodies(events) == [c.body for c, _ in commands]


@pytest.mark.parametrize("bytewise", [False, True])
def test_raw_signature_and_uid_are_read_by_count(bytewise: bool) -> None:
    value = b'\n"$ok\r\n' + bytes(range(25))
    for link in Link:
        reader = ReplyReader(link)
        reader.send(p.Signature(), 0.0)
        wire = (p.raw_reply_line(p.Signature(), value) + "\n").encode("latin-1")
        for chunk in ([wire[i : i + 1] for i in range(len(wire))] if bytewise else [wire]):
            reader.receive(chunk, 0.0)
        reply = reader.next_event(0.0)
        assert isinstance(reply, p.Reply)
        assert p.raw_reply_value(p.Signature(), reply.lines[0]) == value
        reader.send(p.Uid(), 0.0)
        reader.receive((p.raw_reply_line(p.Uid(), b"\n\n$\n") + "\n$\n").encode("latin-1"), 0.0)
        uid = reader.next_event(0.0)
        assert isinstance(uid, p.Reply)
        assert p.raw_reply_value(p.Uid(), uid.lines[0]) == b"\n\n$\n"


def test_sim_control_vectors() -> None:
    assert p.encode(p.SimControl("fault:door-open:on"), Link.WIFI) == b"XYZv3/simctl=fault:door-open:on\r\n"
    assert p.parse_command("simctl=clear") == p.SimControl("clear")
    assert isinstance(p.parse_command("simctl=rm -rf"), p.UnknownCommand)


@given(st.floats(min_value=p.JOG_STEP, max_value=p.JOG_LIMIT), st.sampled_from([1, -1]))
def test_a_jog_length_is_a_plain_decimal_of_at_most_three_places(distance: float, sign: int) -> None:
    body = p.Jog("x", sign * distance).body
    length = json.loads(body.removeprefix("action=jog:"))["len"]
    assert re.fullmatch(r"[0-9]+(\.[0-9]{1,3})?", length), length
    assert abs(float(length) - distance) <= 0.0005 + 1e-12


@pytest.mark.parametrize("distance", [1e-5, 9.99989e-321, 0.0009, -0.0009, 300.5, math.nan, math.inf])
def test_a_jog_too_small_or_large_to_write_is_refused(distance: float) -> None:
    with pytest.raises(LocalProtocolError, match=r"jog distance must be 0\.001 to 300 mm"):
        p.Jog("x", distance)
