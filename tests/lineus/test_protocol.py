"""Line-us codec: command encoding/parsing, the device's command reader and the host's reply reader."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from fabwire.errors import LocalProtocolError, RemoteProtocolError
from fabwire.lineus import protocol as p

HELLO3 = b'hello VERSION:"3.2.0 Nov 17 2019 17:54:57" NAME:line-us SERIAL:123456\r\n\x00'
HELLO1 = b'hello VERSION:"1.0.1 Feb 11 2018 15:47:35" NAME:line-us SERIAL:990055\r\n\x00'
M122 = (
    b"ok ChipID:1575520 WifiMode:1 WifiModeSet:0 WifisConfigured:1 MemDraw:0 Gestures:0 ContinuousDrawing:0 "
    b"DrawingCount:0 name:line-us-dev mac:5C:3A:E8:18:0A:60 FlashChipID:0x1640ef FlashChipMode:0 "
    b'FlashChipSpeed:40000000 FreeHeap:25728 ResetReason:"External System" Uptime:0d0h12m11s '
    b'Time:"Fri Nov 29 16:00:00 2019" FSUsed:112197 FSTotal:1953282 FSFree:1841085 FSPercent:5 '
    b'FS:"/0000001.txt-109291;/cal-29;/key-344; " Serial:ikdBW+ Cal:10.79735,-1.902405,9.900639 '
    b"ZMap:0;100;300;200 ServoReverse:0,0,1\r\n\x00"
)

REPLY_VECTORS: list[tuple[bytes, p.Message]] = [
    (HELLO3, p.Hello("3.2.0 Nov 17 2019 17:54:57", "line-us", "123456")),
    (HELLO1, p.Hello("1.0.1 Feb 11 2018 15:47:35", "line-us", "990055")),
    (b"ok X:1000.00 Y:0.00 Z:1000.00\r\n\x00", p.Reply(True, (("X", "1000.00"), ("Y", "0.00"), ("Z", "1000.00")))),
    (b"ok X:1000 Y:1000 Z:1000\r\n\x00", p.Reply(True, (("X", "1000"), ("Y", "1000"), ("Z", "1000")))),
    (b"ok CONNECTMODE:ST MACHINENAME:line-us\r\n\x00",
     p.Reply(True, (("CONNECTMODE", "ST"), ("MACHINENAME", "line-us")))),
    (b'ok FS:"/0000001.txt-9496;/0000002.txt-11323;"\r\n\x00',
     p.Reply(True, (("FS", "/0000001.txt-9496;/0000002.txt-11323;"),))),
    (b'error INFO:"unknown command G04"\r\n\x00', p.Reply(False, (("INFO", "unknown command G04"),))),
    (b"error\r\n\x00", p.Reply(False)),
    (b"ok\r\n\x00", p.Reply(True)),
]


def read_all(reader: p.ReplyReader, data: bytes) -> list[p.Message]:
    reader.feed(data)
    out = []
    while (message := reader.next_message()) is not None:
        out.append(message)
    return out


@pytest.mark.parametrize(("wire", "message"), REPLY_VECTORS)
def test_reply_vectors_whole_bytewise_and_trailing(wire: bytes, message: p.Message) -> None:
    assert read_all(p.ReplyReader(), wire) == [message]
    reader = p.ReplyReader()
    got: list[p.Message] = []
    for i in range(len(wire)):
        got += read_all(reader, wire[i : i + 1])
        if i < len(wire) - 1:
            assert got == []
    assert got == [message]
    reader = p.ReplyReader()
    assert read_all(reader, wire + b"ok X:1") == [message]
    assert reader.pending == b"ok X:1"
    assert message.encode() == wire


def test_m122_parses_with_colons_and_quotes() -> None:
    [reply] = read_all(p.ReplyReader(), M122)
    assert isinstance(reply, p.Reply)
    assert reply.ok
    fields = reply.as_dict()
    assert fields["mac"] == "5C:3A:E8:18:0A:60"
    assert fields["ResetReason"] == "External System"
    assert fields["ZMap"] == "0;100;300;200"
    assert fields["FS"].endswith("; ")
    assert p.Reply(True, reply.fields, quoted=frozenset({"FS"})).encode() == M122


def test_hello_firmware_numbers() -> None:
    hello = p.Hello("3.2.0 Nov 17 2019 17:54:57", "line-us", "123456")
    assert hello.firmware == (3, 2, 0)
    assert hello.firmware_major == 3
    assert p.Hello("2.0.2Beta6 Sep 14 2018", "x", "1").firmware == (2, 0, 2)
    assert p.Hello("weird", "x", "1").firmware_major == 0


def test_reply_reader_needs_exact_terminator() -> None:
    reader = p.ReplyReader()
    assert read_all(reader, b"ok X:1\r\n") == []
    assert read_all(reader, b"ok\x00") == []  # "\r\n" then "ok\0" is not "\r\n\0"
    reader.feed(b"\r\n\x00")
    with pytest.raises(RemoteProtocolError):  # "ok X:1\r\nok" is one malformed message
        reader.next_message()
    reader = p.ReplyReader()
    both = [p.Reply(True, (("A", "1"),)), p.Reply(True, (("B", "2"),))]
    assert read_all(reader, b"ok A:1\r\n\x00ok B:2\r\n\x00") == both


@pytest.mark.parametrize("bad", [b"\r\n\x00", b"OK\r\n\x00", b"ok nocolon\r\n\x00", b'ok A:"x\r\n\x00',
                                 b"ok A:\xff\r\n\x00", b"SSH-2.0-OpenSSH\r\n\x00"])
def test_reply_reader_rejects_bad_messages_and_recovers(bad: bytes) -> None:
    reader = p.ReplyReader()
    reader.feed(bad + b"ok\r\n\x00")
    with pytest.raises(RemoteProtocolError):
        reader.next_message()
    assert reader.next_message() == p.Reply(True)


def test_reply_reader_overflow() -> None:
    reader = p.ReplyReader(max_size=100)
    reader.feed(b"x" * 101)
    with pytest.raises(RemoteProtocolError, match="not a Line-us"):
        reader.next_message()


@settings(max_examples=300, deadline=None)
@given(st.lists(st.binary(max_size=40), max_size=8))
def test_reply_reader_total(chunks: list[bytes]) -> None:
    reader = p.ReplyReader(max_size=200)
    for chunk in chunks:
        reader.feed(chunk)
        while True:
            try:
                message = reader.next_message()
            except RemoteProtocolError:
                continue
            if message is None:
                break
            assert isinstance(message, p.Reply | p.Hello)


# --- commands, host side -----------------------------------------------------------------------------------------

COMMAND_VECTORS: list[tuple[p.Command, bytes]] = [
    (p.Move(1000, 0, 1000), b"G01 X1000 Y0 Z1000\x00"),
    (p.Move(z=0), b"G01 Z0\x00"),
    (p.Move(1000.5, 1e-05), b"G01 X1000.5 Y0.00001\x00"),
    (p.Move(900, 300, rapid=True), b"G00 X900 Y300\x00"),
    (p.Home(), b"G28\x00"),
    (p.ZMap(), b"G31\x00"),
    (p.ZMap(clear=True), b"G31 Sclear\x00"),
    (p.ZMap((0, 100, 300, 200)), b"G31 S0;100;300;200\x00"),
    (p.RawMove(1000, 0, keep="xy"), b"G40 X1000 Y0 Kxy\x00"),
    (p.SetOrigin(100, 0, 2.5), b"G54 X100 Y0 S2.5\x00"),
    (p.SetSpeed(3), b"G94 S3\x00"),
    (p.SetSpeed(5, 15), b"G94 S5 P15\x00"),
    (p.ListFiles(), b"M20\x00"),
    (p.MemoryDrawing(2, "default"), b"M23 S2 Kdefault\x00"),
    (p.StartSave(2), b"M28 S2\x00"),
    (p.EndSave(), b"M29\x00"),
    (p.DeleteFile(32), b"M30 S32\x00"),
    (p.StorageUsage(), b"M39\x00"),
    (p.TimedDemo(3, 120), b"M85 S3 P120\x00"),
    (p.GetPosition(), b"M114\x00"),
    (p.GetPosition(servos=True), b"M114 S\x00"),
    (p.Capabilities(), b"M115\x00"),
    (p.Diagnostics(), b"M122\x00"),
    (p.Reserved(172), b"M172\x00"),
    (p.FactoryReset(), b"M171 SCONFIRM\x00"),
    (p.FactoryReset(wipe_files=True), b"M171 SSPIFFS\x00"),
    (p.ReverseServos(), b"M280\x00"),
    (p.Gestures(False), b"M291 S2\x00"),
    (p.SaveCalibration(), b"M374\x00"),
    (p.SaveCalibration(clear=True), b"M374 Sclear\x00"),
    (p.MachineName(), b"M550\x00"),
    (p.MachineName("my-bot"), b"M550 Pmy-bot\x00"),
    (p.StartupMode(2, 1), b"M552 S2 P1\x00"),
    (p.Wifi(), b"M587\x00"),
    (p.Wifi("my-ssid", "password with spaces"), b'M587 Smy-ssid P"password with spaces"\x00'),
    (p.ForgetWifi(), b"M588 S*\x00"),
    (p.ForgetWifi("home net"), b'M588 S"home net"\x00'),
    (p.FirmwareUpdate(), b"M997\x00"),
]


@pytest.mark.parametrize(("command", "wire"), COMMAND_VECTORS)
def test_command_round_trip(command: p.Command, wire: bytes) -> None:
    assert command.encode() == wire
    assert p.parse_command(wire[:-1].decode()) == command


@pytest.mark.parametrize(
    "make",
    [
        lambda: p.Move(),
        lambda: p.Move(float("nan")),
        lambda: p.Move(x=float("inf")),
        lambda: p.Move(x=1e9),
        lambda: p.SetSpeed(),
        lambda: p.SetSpeed(0),
        lambda: p.SetSpeed(31),
        lambda: p.SetSpeed(travel=50),
        lambda: p.StartSave(0),
        lambda: p.StartSave(33),
        lambda: p.DeleteFile(True),
        lambda: p.MachineName("bad name!"),
        lambda: p.MachineName(""),
        lambda: p.MachineName("x" * 33),
        lambda: p.Wifi("ssid", 'pw"quote'),
        lambda: p.Wifi(password="x"),
        lambda: p.StartupMode(),
        lambda: p.StartupMode(5),
        lambda: p.ZMap((1, 2, 3)),  # type: ignore[arg-type]
        lambda: p.MemoryDrawing(4),
        lambda: p.Reserved(171),
    ],
)
def test_command_validation(make: object) -> None:
    with pytest.raises(LocalProtocolError):
        make()  # type: ignore[operator]


@pytest.mark.parametrize(
    ("line", "command"),
    [
        ("G01  X1000 Y0 Z1000", p.Move(1000, 0, 1000)),
        ("g01 x1200 y0 z1000", p.Move(1200, 0, 1000)),
        ("G1 X1", p.Move(1)),
        ("G0 X1", p.Move(1, rapid=True)),
        ("G01 X1000.5 Y216.6666666666667", p.Move(1000.5, 216.6666666666667)),
        ("G01 X-0 Y.5", p.Move(0, 0.5)),
        ("M114 ", p.GetPosition()),
        ("m550 P\"quoted-name\"", p.MachineName("quoted-name")),
        ("G54", p.SetOrigin()),
        ("M587 Sx Py", p.Wifi("x", "y")),
    ],
)
def test_parse_variants(line: str, command: p.Command) -> None:
    assert p.parse_command(line) == command


@pytest.mark.parametrize(
    "line",
    ["G04 P100", "G01", "G01 Q5", "G01 X", "G01 X1 X2", "G01 X1e3", "G01 Y1e-05", "G01 XNaN", "G01 Xinf",
     "G01 X99999999", "G94 S0", "G94 S31", "G94 S-1", "G94 P50", "M28", "M28 S0", "M28 S33", "M550 Pbad!",
     "hello", "X100", "M171", "M171 Sfoo", 'M587 S"open', "M291 S3", "M588", "G31 S1;2", "G40 Kq", "123"],
)
def test_parse_rejects(line: str) -> None:
    with pytest.raises(RemoteProtocolError):
        p.parse_command(line)


# --- device side: the command reader -------------------------------------------------------------------------------


def lines(data: bytes, *, bytewise: bool = False) -> list[p.Line | p.BadLine]:
    reader = p.CommandReader()
    if not bytewise:
        return reader.feed(data)
    out: list[p.Line | p.BadLine] = []
    for i in range(len(data)):
        out += reader.feed(data[i : i + 1])
    return out


@pytest.mark.parametrize("terminator", [b"\x00", b"\n", b"\r", b"\r\n", b"\x00\n", b"\r\n\x00", b"\x00\r", b"\n\n\n"])
@pytest.mark.parametrize("bytewise", [False, True])
def test_every_terminator_gives_one_line(terminator: bytes, bytewise: bool) -> None:
    assert lines(b"M114" + terminator, bytewise=bytewise) == [p.Line("M114")]
    assert lines(b"M114" + terminator + b"M115" + terminator, bytewise=bytewise) == [p.Line("M114"), p.Line("M115")]
    assert lines(b"M114" + terminator + b"G01 X1", bytewise=bytewise) == [p.Line("M114")]


def test_reader_blank_and_spaces() -> None:
    assert lines(b"\x00\x00\n   \x00\t\r\n") == []
    assert lines(b"  M20 \x00") == [p.Line("M20")]
    reader = p.CommandReader()
    assert reader.feed(b"G01 X12") == []
    assert reader.feed(b"00 Y0 Z1000\x00") == [p.Line("G01 X1200 Y0 Z1000")]


def test_reader_overlong_and_binary() -> None:
    reader = p.CommandReader(max_line=1024)
    out = reader.feed(b"G" * 5000)
    out += reader.feed(b"X" * 5000 + b"\x00M114\x00")
    assert out == [p.BadLine("line longer than 1024 bytes"), p.Line("M114")]
    assert lines(b"G01 X\xff\x00") == [p.BadLine("command is not ASCII text")]
    assert lines(b"G01\x01X\x00") == [p.BadLine("command holds control characters")]


@settings(max_examples=300, deadline=None)
@given(st.lists(st.binary(max_size=60), max_size=8))
def test_command_reader_total(chunks: list[bytes]) -> None:
    reader = p.CommandReader(max_line=64)
    for chunk in chunks:
        for item in reader.feed(chunk):
            assert isinstance(item, p.Line | p.BadLine)
            if isinstance(item, p.Line):
                assert item.text
                assert item.text == item.text.strip()
                with contextlib.suppress(RemoteProtocolError):
                    assert isinstance(p.parse_command(item.text), p.Command)


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet="GMXYZSPK0123456789.-; \"abc*", max_size=30))
def test_parse_command_total(text: str) -> None:
    try:
        command = p.parse_command(text)
    except RemoteProtocolError:
        return
    assert p.parse_command(command.text()) == command


def test_number_formatting() -> None:
    assert p.format_number(1e-05) == "0.00001"
    assert p.format_number(-0.0) == "0"
    assert p.format_number(1000.0) == "1000"
    assert p.format_coordinate(216.6666, True) == "216.67"
    assert p.format_coordinate(-0.001, True) == "0.00"
    assert p.format_coordinate(999.6, False) == "1000"
    with pytest.raises(LocalProtocolError):
        p.format_number(float("nan"))


@pytest.mark.parametrize(("line", "expected"), [
    ("G01 X1000 Y-300 Z0", p.Move(1000, -300, 0)),
    ("g1 x1200.5 y.5", p.Move(1200.5, 0.5)),
    ("G0 Z1000", p.Move(z=1000, rapid=True)),
    ("G001\tX-0", p.Move(0.0)),
])
def test_plain_moves_parse_like_the_general_grammar(line: str, expected: p.Command) -> None:
    assert p.parse_command(line) == expected


@pytest.mark.parametrize("line", ["G01 X1 X2", "G01 X999999", "G01 X1e3", "G02 X1"])
def test_plain_move_lookalikes_are_still_refused(line: str) -> None:
    with pytest.raises(RemoteProtocolError):
        p.parse_command(line)


def test_position_reply_bytes_match_the_reply_codec() -> None:
    assert p.encode_position(1000, -0.001, 0, True) == b"ok X:1000.00 Y:0.00 Z:0.00\r\n\x00"
    assert p.encode_position(1200.4, 0, 1000, False) == p.Reply(
        True, (("X", "1200"), ("Y", "0"), ("Z", "1000"))).encode()


LONG_TOKENS = st.tuples(st.text(alphabet="ok:GMXYZ\"ab \x01é", max_size=8), st.integers(1, 60_000)).map(
    lambda t: t[0] * (t[1] // max(1, len(t[0]))))
"""Text up to a whole reply buffer long, built from a few characters repeated."""


@settings(max_examples=200, deadline=None)
@given(st.lists(LONG_TOKENS, max_size=3).map(" ".join))
@example("ok " + "x" * 60_000)
@example("y" * 60_000)
@example("ok a:" + "\x01" * 20_000)
def test_a_bad_device_message_is_refused_in_one_short_line(text: str) -> None:
    message = ""
    try:
        p.parse_message(text)
    except RemoteProtocolError as e:
        message = str(e)
    assert len(message) <= 120
    assert "\n" not in message


@settings(max_examples=200, deadline=None)
@given(st.lists(LONG_TOKENS, max_size=3).map(" ".join))
@example("G01 X" + "9" * 1000)
@example("Q" * 1000)
@example("G01 " + "X" * 1000)
def test_a_bad_command_line_is_refused_in_one_short_line(text: str) -> None:
    message = ""
    try:
        p.parse_command(text[: p.MAX_LINE])
    except (RemoteProtocolError, LocalProtocolError) as e:
        message = str(e)
    assert len(message) <= 120
    assert "\n" not in message
