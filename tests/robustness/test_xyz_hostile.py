"""XYZ under hostile peers: deep structures and huge numbers at every parsing boundary, bounded simulator memory,
and no success without the printer's word for it."""

from __future__ import annotations

import asyncio
import contextlib
import struct
import tracemalloc
import zlib
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fabwire.errors import DeviceError, LinkTimeout, RemoteProtocolError
from fabwire.transport import Transport
from fabwire.xyz import maintenance
from fabwire.xyz import protocol as xp
from fabwire.xyz.client import XYZPrinter
from fabwire.xyz.protocol import Block, DeviceDecoder, Garbage, Link, Received
from fabwire.xyz.replies import MAX_STATUS_LINES
from fabwire.xyz.sim import COMMAND_HISTORY, UPLOAD_HISTORY, XYZSimulator
from fabwire.xyz.status import Status
from fabwire.xyz.threew import write_3w
from linktools import loopback_tcp

GCODE = b";TIME:60\nG28\nG1 X10 Y10 E1 F1200\nM84\n"
IDLE_STATUS = [b"b:21", b"d:0,0,0", b"e:0", b"f:1,200000", b"i:3FM1WPUS5SIM000001", b"j:9511,0", b"o:p8,t1,c1,a+",
               b"p:dv1MW0A000", b"t:1,22,0", b"v:1.2.3", b"w:1,PMP6QTH64R1093", b"n:mini w"]

HOSTILE_VALUES = st.one_of(
    st.integers(1, 6000).map(lambda n: "[" * n + "]" * n),
    st.integers(1, 6000).map(lambda n: '{"a":' * n + "1" + "}" * n),
    st.integers(4000, 9000).map(lambda n: "9" * n),
    st.text(max_size=200),
)


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(["action=jog:", "upload=x.3w,", "firmware=x.bin,", "config=zoffset:set[", "config=energy:[",
                        "config=life:[", "config=ssid:[a,b,", "config=pda:[", "query="]), HOSTILE_VALUES)
def test_the_command_parser_turns_deep_and_huge_values_into_unknown_commands(verb: str, value: str) -> None:
    command = xp.parse_command(verb + value)
    assert isinstance(command, xp.Command)
    decoder = DeviceDecoder()
    events = decoder.feed(xp.PREFIX + (verb + value).encode() + b"\n", 0.0)
    assert all(isinstance(event, Received | Garbage | Block) for event in events)


@settings(max_examples=60, deadline=None)
@given(st.sampled_from("4OsGWZtjewfd"), HOSTILE_VALUES)
def test_a_status_field_with_a_hostile_value_is_kept_raw(letter: str, value: str) -> None:
    status = Status.parse([f"{letter}:{value}", "j:9511,0"])
    assert status.state_code == 9511
    assert isinstance(status.to_dict(), dict)
    assert status.line(letter) is not None


def test_an_upload_block_longer_than_any_printer_takes_is_refused_unbuffered() -> None:
    decoder = DeviceDecoder()
    decoder.feed(b"XYZv3/upload=a.3w,4000000000\n", 0.0)
    assert decoder.uploading
    events = decoder.feed(struct.pack(">II", 0, 3_000_000_000) + bytes(1000), 0.1)
    assert [type(event) for event in events] == [Garbage]
    assert not decoder.uploading


async def _talk(sim: XYZSimulator, action: Callable[[Transport], object]) -> None:
    async with asyncio.timeout(20), loopback_tcp(sim.serve) as link:
        result = action(link)
        if asyncio.iscoroutine(result):
            await result


async def _read_until(link: Transport, marker: bytes, limit: float = 5.0) -> bytes:
    data = b""
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(limit):
            while marker not in data:
                data += await link.read()
    return data


async def test_the_simulator_keeps_bounded_histories_and_drops_abandoned_uploads() -> None:
    sim = XYZSimulator(speed=1000, gap=0.01)

    async def flood(link: Transport) -> None:
        await link.write(b"XYZv3/nonsense\r\n" * (COMMAND_HISTORY + 500))
        await link.write(b"XYZv3/query=a\r\n")
        await _read_until(link, b"$\n")

    await _talk(sim, flood)
    assert len(sim.commands) == COMMAND_HISTORY
    block = b"\0" * 8192
    for n in range(UPLOAD_HISTORY + 3):
        async def abandon(link: Transport, n: int = n) -> None:
            await link.write(f"XYZv3/upload=junk{n}.3w,{1 << 20}\r\n".encode())
            await _read_until(link, b"ok")
            await link.write(struct.pack(">II", 0, len(block)) + block + struct.pack(">I", zlib.crc32(block)))
            await _read_until(link, b"ok")

        await _talk(sim, abandon)
    await asyncio.sleep(0.2)
    assert len(sim.uploads) == UPLOAD_HISTORY
    assert all(record.data == b"" and record.received == 8192 and not record.complete for record in sim.uploads)


async def test_a_declared_size_over_the_cap_and_a_second_concurrent_upload_are_refused() -> None:
    sim = XYZSimulator(speed=1000, gap=0.01, max_upload=1 << 20)
    async with asyncio.timeout(20), loopback_tcp(sim.serve) as first, loopback_tcp(sim.serve) as second:
        await first.write(b"XYZv3/upload=big.3w,4294967295\r\n")
        assert b"E1$" in await _read_until(first, b"$")
        await first.write(b"XYZv3/upload=a.3w,1000\r\n")
        assert b"ok" in await _read_until(first, b"ok")
        await second.write(b"XYZv3/upload=b.3w,1000\r\n")
        assert b"E3$" in await _read_until(second, b"$")


async def test_the_simulator_survives_a_handler_fault_and_keeps_answering() -> None:
    sim = XYZSimulator(speed=1000, gap=0.01)

    async def hostile(link: Transport) -> None:
        await link.write(b"XYZv3/action=jog:" + b"[" * 3000 + b"\r\n")
        await link.write(b"XYZv3/upload=x.3w," + b"9" * 5000 + b"\r\n")
        await link.write(b"XYZv3/query=a\r\n")
        assert b"j:9511" in await _read_until(link, b"$\n")

    await _talk(sim, hostile)


# ------------------------------------------------------------------------------------- lying printers


@contextlib.asynccontextmanager
async def fake_printer(answer: Callable[[bytes], bytes | None]) -> AsyncIterator[XYZPrinter]:
    """A TCP peer that answers each command line with `answer(line)` and acknowledges every upload block."""

    async def serve(link: Transport) -> None:
        buffer = b""
        with contextlib.suppress(Exception):
            while True:
                buffer += await link.read()
                while True:
                    if buffer.startswith(b"XYZv3/"):
                        end = buffer.find(b"\n")
                        if buffer.startswith(b"XYZv3/uploadDidFinish"):
                            buffer = buffer[len(b"XYZv3/uploadDidFinish"):]
                            await link.write(b"ok\nok\n")
                            continue
                        if end < 0:
                            break
                        line, buffer = buffer[:end].rstrip(b"\r"), buffer[end + 1:]
                        reply = answer(line)
                        if reply:
                            await link.write(reply)
                    elif len(buffer) >= 8:
                        length = struct.unpack_from(">I", buffer, 4)[0]
                        if len(buffer) < length + 12:
                            break
                        buffer = buffer[length + 12:]
                        await link.write(b"ok\n")
                    else:
                        break

    async with loopback_tcp(serve) as link:
        printer = XYZPrinter(link, link=Link.WIFI, timeout=2.0)
        printer.poll_interval = 0.01
        try:
            yield printer
        finally:
            await printer.close()


def _idle_printer(line: bytes) -> bytes | None:
    if line.startswith(b"XYZv3/query=a"):
        return b"\n".join(IDLE_STATUS) + b"\n$\n"
    if line.startswith(b"XYZv3/query="):
        return b"o:p8,t1,c1,a+\n"
    return b"ok \n" if line.startswith(b"XYZv3/upload=") else None


async def test_a_printer_that_takes_the_file_but_never_starts_is_no_success() -> None:
    async with asyncio.timeout(30), fake_printer(_idle_printer) as printer:
        with pytest.raises(DeviceError, match="did not start the job"):
            await printer.print_file(GCODE, wait=False, start_limit=0.3)


async def test_a_reply_of_junk_lines_is_no_status() -> None:
    def junk(line: bytes) -> bytes | None:
        return b"".join(b"x:junk %d\n" % i for i in range(50)) + b"$\n" if b"query" in line else None

    async with asyncio.timeout(30), fake_printer(junk) as printer:
        with pytest.raises(RemoteProtocolError, match="no state"):
            await printer.status()


async def test_a_file_check_that_never_ends_is_reported_with_how_to_cancel() -> None:
    sim = XYZSimulator(speed=1000, gap=0.01, faults=("stuck",))
    clock = [0.0]
    async with asyncio.timeout(30), loopback_tcp(sim.serve) as link:
        printer = XYZPrinter(link, timeout=5.0, clock=lambda: clock[0])
        printer.poll_interval = 0.01
        try:
            await printer.upload(write_3w(GCODE, "dv1MW0A000"), "part.3w")

            def later(_status: Status) -> None:
                clock[0] += 30.0

            with pytest.raises(LinkTimeout, match="fabwire xyz cancel"):
                await printer.follow_job(later)
        finally:
            await printer.close()


def _ignores_settings(line: bytes) -> bytes | None:
    """A Wi-Fi printer that answers status queries with its unchanged settings and nothing else."""
    if line.startswith(b"XYZv3/query=a"):
        return b"\n".join([*IDLE_STATUS, b"z:245", b"l:en", b's:{"buzzer":"on"}']) + b"\n$\n"
    if line.startswith(b"XYZv3/query="):
        wanted = line.removeprefix(b"XYZv3/query=")
        return b"".join(row + b"\n" for row in [*IDLE_STATUS, b"z:245", b"l:en", b's:{"buzzer":"on"}']
                        if row[:1] in [bytes([c]) for c in wanted])
    return None


SETTINGS = [("set_autolevel", (False,)), ("set_buzzer", (False,)), ("set_zoffset", (120,)), ("set_name", ("Lab",)),
            ("set_language", ("fr",)), ("nudge_zoffset", (True,)), ("nudge_zoffset", (False,))]


@pytest.fixture
def quick_confirm(monkeypatch: pytest.MonkeyPatch) -> None:
    """The wait for a setting to show shortened, on the real clock: a printer that never applies it fails the
    same way however slowly the machine runs (a fake clock would also speed up the reply timeouts)."""
    monkeypatch.setattr(maintenance, "CONFIRM_LIMIT", 0.05)


@pytest.mark.usefixtures("quick_confirm")
@pytest.mark.parametrize(("method", "args"), SETTINGS)
async def test_a_wifi_printer_that_ignores_a_setting_is_no_success(method: str, args: tuple[object, ...]) -> None:
    async with asyncio.timeout(30), fake_printer(_ignores_settings) as printer:
        with pytest.raises(DeviceError, match="did not apply"):
            await getattr(printer, method)(*args)


@pytest.mark.parametrize(("method", "args"), SETTINGS)
async def test_a_wifi_printer_that_applies_a_setting_confirms_it_in_its_status(method: str,
                                                                                args: tuple[object, ...]) -> None:
    sim = XYZSimulator(speed=1000, gap=0.01)
    async with asyncio.timeout(30), loopback_tcp(sim.serve) as link:
        printer = XYZPrinter(link, link=Link.WIFI, timeout=5.0)
        try:
            before = (await printer.status()).zoffset
            result = await getattr(printer, method)(*args)
            status = await printer.status()
        finally:
            await printer.close()
    if method == "nudge_zoffset":
        assert before is not None
        assert result == status.zoffset == before + (1 if args[0] else -1)
    elif method == "set_zoffset":
        assert result == status.zoffset == args[0]
    else:
        assert result is True
    assert (status.autolevel, status.buzzer, status.zoffset, status.name, status.language) != (
        True, True, 245, "mini w", "en")


async def test_settings_without_a_status_field_are_sent_but_not_claimed_on_wifi() -> None:
    async with asyncio.timeout(30), fake_printer(_ignores_settings) as printer:
        assert await printer.set_energy(5) is False
        assert await printer.restore_defaults() is False


async def test_a_setting_lost_with_the_link_is_sent_again_once_the_status_shows_it_missing() -> None:
    """A Wi-Fi printer whose connection drops as a setting arrives: the client reconnects, sees the buzzer still
    on, sends the setting again, and reports success only once the status shows it."""
    buzzer = ["on"]
    heard: list[bytes] = []

    async def printer(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        with contextlib.suppress(ConnectionError):
            while line := await reader.readline():
                heard.append(line.strip())
                if line.startswith(b"XYZv3/config=buzzer:off"):
                    if heard.count(line.strip()) == 1:
                        writer.transport.abort()  # the first one is lost with the link
                        return
                    buzzer[0] = "off"
                elif line.startswith(b"XYZv3/query="):
                    letters = line.strip().removeprefix(b"XYZv3/query=")
                    rows = [*IDLE_STATUS, b's:{"buzzer":"%s"}' % buzzer[0].encode()]
                    if letters == b"a":
                        writer.write(b"\n".join(rows) + b"\n$\n")
                    else:
                        writer.write(b"".join(r + b"\n" for r in rows if r[:1] in [bytes([c]) for c in letters]))
                await writer.drain()
        writer.close()

    server = await asyncio.start_server(printer, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    try:
        async with asyncio.timeout(30), await XYZPrinter.open(f"127.0.0.1:{port}", timeout=3.0) as client:
            client.poll_interval = 0.01
            assert await client.set_buzzer(False) is True
            assert client.reconnects >= 1
    finally:
        server.close()
    assert buzzer == ["off"]
    assert heard.count(b"XYZv3/config=buzzer:off") == 2


async def test_printing_a_gcode_holds_the_same_memory_whatever_its_size(tmp_path: Path) -> None:
    """The file is converted and uploaded from disk: peak memory is the intake's and converter's working set, the
    same for 8 and 40 MiB (it grew by about 3.5 times the file when the file, its conversion and the upload were
    all held at once)."""
    line = b"G1 X10.123 Y20.456 E0.01234 F1200 ; a slicer's comment to make the line longer\n"
    started = [False]

    def printer(line: bytes) -> bytes | None:
        if line.startswith(b"XYZv3/query=a"):
            state = b"j:9505,0" if started[0] else b"j:9511,0"
            return b"\n".join([*(r for r in IDLE_STATUS if not r.startswith(b"j:")), state]) + b"\n$\n"
        if line.startswith(b"XYZv3/query="):
            return b"o:p8,t1,c1,a+\n"
        if line.startswith(b"XYZv3/upload="):
            started[0] = True
            return b"ok \n"
        return None

    peaks = []
    for mib in (8, 40):
        source = tmp_path / f"{mib}.gcode"
        with source.open("wb") as out:
            out.write(b";TIME:60\n")
            for _ in range(mib):
                out.write(line * ((1 << 20) // len(line)))
        started[0] = False
        async with asyncio.timeout(120), fake_printer(printer) as client:
            tracemalloc.start()
            try:
                await client.print_file(source, wait=False)
                peaks.append(tracemalloc.get_traced_memory()[1])
            finally:
                tracemalloc.stop()
    assert peaks[1] - peaks[0] < 4 << 20, f"peaks {[p >> 20 for p in peaks]} MiB for 8 and 40 MiB files"


@pytest.mark.usefixtures("quick_confirm")
@pytest.mark.parametrize(("state", "method"), [(b"j:9505,0", "pause"), (b"j:9505,0", "cancel"),
                                               (b"j:9601,0", "resume"), (b"j:9509,0", "acknowledge")])
async def test_a_wifi_printer_that_ignores_job_control_is_no_success(state: bytes, method: str) -> None:
    def printer(line: bytes) -> bytes | None:
        rows = [*(r for r in IDLE_STATUS if not r.startswith(b"j:")), state]
        if line.startswith(b"XYZv3/query=a"):
            return b"\n".join(rows) + b"\n$\n"
        if line.startswith(b"XYZv3/query="):
            return state + b"\n"
        return None

    async with asyncio.timeout(30), fake_printer(printer) as client:
        with pytest.raises(DeviceError, match=r"did not apply 'config=print\["):
            await getattr(client, method)()


@pytest.mark.parametrize("reply", [b"calibratejr:{}\n$\n", b"calibratejr:{1,2,3}\n$\n", b"junk\n$\n",
                                   b'calibratejr:{"stat":"ok",' + b"9" * 5000 + b"}\n$\n"])
async def test_a_calibration_without_nine_readings_is_no_result(reply: bytes) -> None:
    """A printer that walks through the calibration states but answers `getdata` with anything but 9 readings."""
    steps = iter([b"j:9535,41", b"j:9535,44"])
    state = [b"j:9511,0"]

    def printer(line: bytes) -> bytes | None:
        if line.startswith(b"XYZv3/action=calibratejr:"):
            op = line.removeprefix(b"XYZv3/action=calibratejr:")
            if op in (b"new", b"detectorok"):
                state[0] = next(steps)
            elif op == b"release":
                state[0] = b"j:9511,0"
            return reply if op == b"getdata" else None
        if line.startswith(b"XYZv3/query="):
            rows = [*(r for r in IDLE_STATUS if not r.startswith(b"j:")), state[0]]
            return b"\n".join(rows) + (b"\n$\n" if line.endswith(b"=a") else b"\n")
        return None

    async def confirm(message: str) -> None:
        return None

    async with asyncio.timeout(30), fake_printer(printer) as client:
        with pytest.raises(RemoteProtocolError, match="not 9 bed readings"):
            await client.calibrate(confirm)
    assert state[0] == b"j:9511,0"  # the flow was released


def test_a_status_reply_that_never_ends_is_held_to_a_bounded_number_of_lines() -> None:
    reader = xp.ReplyReader(Link.WIFI)
    reader.send(xp.Query("a"), 0.0, 5.0)
    tracemalloc.start()
    try:
        for _ in range(200):
            reader.receive(b"".join(b"q:" + b"y" * 200 + b"\n" for _ in range(500)), 0.0)
        grown = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    assert grown < 1 << 20  # 20 MB arrived
    reader.receive(b"j:9511,0\n$\n", 0.0)
    reply = reader.next_event(0.0)
    assert isinstance(reply, xp.Reply)
    assert len(reply.lines) == MAX_STATUS_LINES  # the first ones; the state line came too late to count


async def test_a_flows_later_lines_go_only_to_the_client_that_started_it() -> None:
    """Two clients on serial framing: one homes, the other polls the moment the homing has ended; the homing's
    `complete` line is the homing client's, and the poller's reply stays a status reply."""
    clock = [0.0]
    sim = XYZSimulator(speed=1, gap=0.01, link=Link.SERIAL, clock=lambda: clock[0])
    async with asyncio.timeout(30), loopback_tcp(sim.serve) as homer, loopback_tcp(sim.serve) as poller:
        await homer.write(b"XYZv3/action=home\n")
        heard = await _read_until(homer, b"$\n")
        assert heard.startswith(b'home:{"stat":"start"}')
        clock[0] += 60.0  # the homing is over; the poller is the first to ask
        await poller.write(b"XYZv3/query=j\n")
        polled = await _read_until(poller, b"$\n")
        while b'home:{"stat":"complete"}' not in heard:
            heard += await _read_until(homer, b"$\n")
    assert polled.startswith(b"j:9511")


@pytest.mark.parametrize(("flow", "state"), [("load_filament", 9530), ("unload_filament", 9531),
                                             ("clean_nozzle", 9536)])
async def test_a_flow_stopped_while_the_printer_heats_is_cancelled_on_the_printer(flow: str, state: int) -> None:
    sim = XYZSimulator(speed=1, gap=0.01)
    async with asyncio.timeout(30), loopback_tcp(sim.serve) as link:
        client = XYZPrinter(link, link=Link.WIFI, timeout=5.0)
        client.poll_interval = 0.01

        async def confirm(message: str) -> None:
            await asyncio.Event().wait()  # nobody answers

        heating = asyncio.Event()

        def seen(status: Status) -> None:
            if status.state_code == state:
                heating.set()

        args = () if flow == "unload_filament" else (confirm,)
        try:
            task = asyncio.create_task(getattr(client, flow)(*args, on_status=seen))
            await heating.wait()
            task.cancel()  # what Ctrl-C does to the command
            with pytest.raises(asyncio.CancelledError):
                await task
            assert (await client.status()).idle  # not left heating
        finally:
            await client.close()
