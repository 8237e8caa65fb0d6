"""The simulator on the wire, byte for byte: serial and Wi-Fi framing, uploads, and clients that behave like
miniMover (no terminators, never reading upload acks, closing right after a fire-and-forget command)."""

from __future__ import annotations

import asyncio
import socket
import zlib
from collections.abc import AsyncIterator, Awaitable, Callable

import pytest

from fabwire.transport import memory_pair, serve_tcp
from fabwire.transport.base import Transport
from fabwire.xyz import protocol as p
from fabwire.xyz.models import find_model
from fabwire.xyz.protocol import Link
from fabwire.xyz.sim import XYZSimulator
from fabwire.xyz.status import Status
from fabwire.xyz.threew import write_3w
from robustness.fakeclock import run_on_fake_clock

GCODE = b";TIME:600\n;LAYER_COUNT:3\n;Filament used: 0.25m\nG28\nG0 X10 Y10\nG1 X20 Y20 E1\nM84\n"


async def read_until(link: Transport, end: bytes, limit: float = 3.0) -> bytes:
    data = b""
    async with asyncio.timeout(limit):
        while not data.endswith(end):
            data += await link.read()
    return data


async def read_quiet(link: Transport, quiet: float = 0.15) -> bytes:
    """Everything that arrives until the line has been silent for `quiet` seconds."""
    data = b""
    while True:
        try:
            async with asyncio.timeout(quiet):
                data += await link.read()
        except TimeoutError:
            return data


@pytest.fixture
async def serial_link() -> AsyncIterator[tuple[XYZSimulator, Transport]]:
    sim = XYZSimulator(speed=200, link=Link.SERIAL)
    host, device = memory_pair("xyz")
    task = asyncio.create_task(sim.serve(device))
    yield sim, host
    await host.close()
    await asyncio.wait_for(task, 2)


@pytest.fixture
async def tcp_sim() -> AsyncIterator[tuple[XYZSimulator, int]]:
    sim = XYZSimulator(speed=200)
    server = await serve_tcp(sim.serve, "127.0.0.1", 0)
    yield sim, server.sockets[0].getsockname()[1]
    server.close()


async def test_full_status_both_terminators_serial(serial_link: tuple[XYZSimulator, Transport]) -> None:
    _, link = serial_link
    for term in (b"", b"\n", b"\r\n"):
        await link.write(b"XYZv3/query=a" + term)
        reply = await read_until(link, b"$\n")
        lines = reply.decode().split("\n")
        assert len(lines) >= 20
        assert "o:p8,t1,c1,a+" in lines
        assert "j:9511,0" in lines
        assert "p:dv1MW0A000" in lines
        assert b"\r" not in reply
        status = Status.parse(lines)
        assert status.model_number == "dv1MW0A000"


async def test_serial_framing_exact(serial_link: tuple[XYZSimulator, Transport]) -> None:
    _, link = serial_link
    await link.write(b"XYZv3/query=jt\n")
    assert await read_until(link, b"$\n") == b"j:9511,0\nt:1,22,0\n$\n"
    await link.write(b"XYZv3/config=buzzer:off\n")
    assert await read_until(link, b"$\n") == b"ok\n$\n"
    await link.write(b"XYZv3/config=zoffset:set[-469]\n")
    assert await read_until(link, b"$\n") == b"ok\n$\n"
    await link.write(b"XYZv3/config=zoffset:get\n")
    assert await read_until(link, b"$\n") == b"-469\n$\n"
    await link.write(b"XYZv3/query=z\n")
    assert await read_until(link, b"$\n") == b"z:-469\n$\n"
    await link.write(b"XYZv3/query=V9\n")  # a letter no model sends: only the terminator
    assert await read_until(link, b"$\n") == b"V:5.0.9\n$\n"
    await link.write(b"XYZv3/query=s\n")
    assert b'"buzzer":"off"' in await read_until(link, b"$\n")
    await link.write(b"XYZv3/bogus\n")
    assert await read_until(link, b"$\n") == b"E1$\n"


def on_fake_clock(exchange: Callable[[XYZSimulator, Transport], Awaitable[None]]) -> None:
    """Run `exchange` against a serial simulator whose time is a fake clock's: what it answers when depends on
    the simulated time alone, never on how loaded the machine running the test is."""

    async def main() -> None:
        sim = XYZSimulator(speed=200, link=Link.SERIAL, clock=asyncio.get_running_loop().time)
        host, device = memory_pair("xyz")
        task = asyncio.create_task(sim.serve(device))
        try:
            await exchange(sim, host)
        finally:
            await host.close()
            await asyncio.wait_for(task, 2)

    run_on_fake_clock(main())


def test_serial_home_and_load_cancel() -> None:
    async def exchange(_: XYZSimulator, link: Transport) -> None:
        await link.write(b"XYZv3/action=home\n")
        assert await read_until(link, b"$\n") == b'home:{"stat":"start"}\n$\n'
        await link.write(b"XYZv3/query=j\n")
        assert await read_until(link, b"$\n") == b"j:9534,5\n$\n"
        assert await read_until(link, b'home:{"stat":"complete"}\n$\n')
        await link.write(b"XYZv3/action=load:new\n")
        data = await read_until(link, b'load:{"stat":"load"}\n$\n')
        assert data.startswith(b'load:{"stat":"start"}\n$\nload:{"stat":"heat","extemp":"')
        await link.write(b"XYZv3/action=load:cancel\n")
        assert await read_until(link, b"$\n", limit=0.2) == b'load:{"stat":"complete"}\n$\n'
        await link.write(b"XYZv3/query=jt\n")
        reply = await read_until(link, b"$\n")
        assert reply.startswith(b"j:9511,0\nt:1,")
        assert reply.endswith(b",0\n$\n")

    on_fake_clock(exchange)


async def test_serial_calibration_values_reach_status(serial_link: tuple[XYZSimulator, Transport]) -> None:
    sim, link = serial_link
    await link.write(b"XYZv3/action=calibratejr:new\n")
    assert await read_until(link, b'pressdetector"}\n$\n') == (
        b'calibratejr:{"stat":"start"}\n$\ncalibratejr:{"stat":"pressdetector"}\n$\n')
    await link.write(b"XYZv3/action=calibratejr:detectorok\n")
    data = await read_until(link, b"}\n$\n", limit=3)
    assert data == b'calibratejr:{"stat":"processing"}\n$\n'
    data = await read_until(link, b"}\n$\n", limit=3)
    stat = p.parse_stat_line(data.decode().split("\n")[0])
    assert stat is not None
    assert stat.stat == "ok"
    assert len(stat.values) == 9
    await link.write(b"XYZv3/action=calibratejr:getdata\n")
    values = ",".join(map(str, stat.values)).encode()
    assert await read_until(link, b"$\n") == b"calibratejr:{" + values + b"}\n$\n"
    await link.write(b"XYZv3/action=calibratejr:release\n")
    assert await read_until(link, b"$\n") == b'calibratejr:{"stat":"complete"}\n$\n'
    await link.write(b"XYZv3/query=c\n")
    assert await read_until(link, b"$\n") == b"c:{" + values + b"}\n$\n"
    assert sim.printer.state == (9511, 0)


async def test_wifi_framing_exact(tcp_sim: tuple[XYZSimulator, int]) -> None:
    sim, port = tcp_sim
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(b"XYZv3/query=jt\r\n")
    assert await asyncio.wait_for(reader.readuntil(b"t:1,22,0\n"), 2) == b"j:9511,0\nt:1,22,0\n"
    writer.write(b"XYZv3/config=autolevel:off\r\n")
    writer.write(b"XYZv3/config=zoffset:get\r\n")
    assert await asyncio.wait_for(reader.readuntil(b"$\n"), 2) == b"245\n$\n"  # nothing for the config
    writer.write(b"XYZv3/action=cleannozzle:new\r\nXYZv3/query=o\r\n")
    assert await asyncio.wait_for(reader.readuntil(b"\n"), 2) == b"o:p8,t1,c1,a-\n"
    assert sim.printer.state[0] == 9536
    writer.close()


async def test_minimover_style_socket(tcp_sim: tuple[XYZSimulator, int]) -> None:
    """No terminators, two commands in one segment, close right after fire-and-forget, upload acks never read."""
    sim, port = tcp_sim
    sock = socket.create_connection(("127.0.0.1", port))
    sock.sendall(b"XYZv3/config=buzzer:off")
    sock.close()
    sock = socket.create_connection(("127.0.0.1", port))
    sock.sendall(b"XYZv3/config=zoffset:set[300]XYZv3/config=autolevel:off")
    sock.close()
    await asyncio.sleep(0.2)
    settings = sim.printer.settings
    assert (settings.buzzer, settings.zoffset, settings.autolevel) == (False, 300, False)

    data = write_3w(GCODE * 400, find_model("dv1MW0A000"))
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    blob = b"XYZv3/upload=temp.gcode," + str(len(data)).encode() + b"\n"
    blob += b"".join(p.iter_blocks(data, 8192, crc=False)) + b"XYZv3/uploadDidFinish"
    writer.write(blob)  # everything back to back, nothing read
    await writer.drain()
    await asyncio.sleep(0.5)
    writer.write(b"XYZv3/query=j")
    acks = await asyncio.wait_for(reader.readuntil(b"j:"), 3)
    blocks = -(-len(data) // 8192)
    assert acks == b"ok \n" + b"ok\n" * blocks + b"ok\nok\n" + b"j:"
    writer.close()
    assert sim.received("temp.gcode") == data


async def test_upload_with_crc_trailers_is_stored_exactly(serial_link: tuple[XYZSimulator, Transport]) -> None:
    sim, link = serial_link
    data = write_3w(GCODE * 600, find_model("dv1MW0A000"))
    await link.write(b"XYZv3/upload=crc.3w," + str(len(data)).encode())  # no terminator, as XYZprint
    assert await read_until(link, b"\n") == b"ok\n"
    for block in p.iter_blocks(data, 8192):
        await link.write(block)
        assert await read_until(link, b"\n") == b"ok\n"
    await link.write(b"XYZv3/uploadDidFinish")
    assert await read_quiet(link) == b"ok\n"  # serial: one ok, no `$`
    assert sim.received("crc.3w") == data
    assert sim.uploads[-1].crc_checked == -(-len(data) // 8192)
    await link.write(b"XYZv3/query=j\n")
    assert await read_until(link, b"$\n") in (b"j:9520,0\n$\n", b"j:9505,0\n$\n")


async def test_zero_length_last_block_is_a_short_upload(serial_link: tuple[XYZSimulator, Transport]) -> None:
    """miniMover sends a file of exactly 2 blocks as one block and a len-0 block: the printer rejects it."""
    sim, link = serial_link
    data = bytes(16384)
    await link.write(b"XYZv3/upload=temp.gcode,16384\n")
    assert await read_until(link, b"\n") == b"ok\n"
    await link.write(p.encode_block(0, data[:8192], crc=False))
    assert await read_until(link, b"\n") == b"ok\n"
    await link.write(bytes.fromhex("00000001 00000000 00000000"))
    assert await read_until(link, b"\n") == b"ok\n"
    await link.write(b"XYZv3/uploadDidFinish")
    assert await read_until(link, b"\n") == b"ok\n"
    assert not sim.uploads[-1].complete
    assert sim.uploads[-1].received == 8192
    assert sim.uploads[-1].data == data[:8192]  # finished short: kept for the file check (an abandoned one is not)
    await asyncio.sleep(0.1)
    await link.write(b"XYZv3/query=je\n")
    assert await read_until(link, b"$\n") == b"e:525\nj:9509,0\n$\n"


async def test_strict_mode_rejects_bad_crc() -> None:
    sim = XYZSimulator(speed=200, link=Link.SERIAL, strict=True)
    host, device = memory_pair("xyz")
    task = asyncio.create_task(sim.serve(device))
    await host.write(b"XYZv3/upload=a.3w,10\n")
    assert await read_until(host, b"\n") == b"ok\n"
    block = p.encode_block(0, b"0123456789", crc=False)[:-4] + (zlib.crc32(b"x")).to_bytes(4, "big")
    await host.write(block)
    assert await read_until(host, b"\n") == b"E1$\n"
    await host.write(b"XYZv3/query=e\n")
    assert await read_until(host, b"$\n") == b"e:513\n$\n"
    await host.close()
    await asyncio.wait_for(task, 2)


async def test_plain_gcode_is_rejected_with_0x020d(serial_link: tuple[XYZSimulator, Transport]) -> None:
    _sim, link = serial_link
    await link.write(b"XYZv3/upload=temp.gcode," + str(len(GCODE)).encode() + b"\n")
    await read_until(link, b"ok\n")
    await link.write(p.encode_block(0, GCODE, crc=False))
    await read_until(link, b"ok\n")
    await link.write(b"XYZv3/uploadDidFinish")
    await read_until(link, b"ok\n")
    await asyncio.sleep(0.1)
    await link.write(b"XYZv3/query=je\n")
    assert await read_until(link, b"$\n") == b"e:525\nj:9509,0\n$\n"


async def test_several_connections_share_one_printer(tcp_sim: tuple[XYZSimulator, int]) -> None:
    sim, port = tcp_sim
    _r1, w1 = await asyncio.open_connection("127.0.0.1", port)
    r2, w2 = await asyncio.open_connection("127.0.0.1", port)
    w1.write(b"XYZv3/config=name:[Shared]\r\n")
    await w1.drain()
    await asyncio.sleep(0.05)
    w2.write(b"XYZv3/query=n\r\n")
    assert await asyncio.wait_for(r2.readuntil(b"\n"), 2) == b"n:Shared          \n"
    w1.close()
    w2.close()
    assert sim.connections >= 0


async def test_minimover_over_a_real_pty() -> None:
    """Serial miniMover: commands without terminators (the idle gap ends them), exact `ok` lines,
    `$` right behind a config's `ok`, and no `$` after upload acks."""
    from fabwire.transport import open_pty
    from fabwire.transport.serial import open_serial

    sim = XYZSimulator(speed=200)
    device = open_pty()
    task = asyncio.create_task(sim.serve(device.transport))
    port = await open_serial(device.path, 115200)
    try:
        await port.write(b"XYZv3/query=a")
        status = await read_until(port, b"$\n")
        assert b"\no:p8,t1,c1,a+\n" in status
        await port.write(b"XYZv3/config=autolevel:off")
        assert await read_until(port, b"$\n", limit=1.0) == b"ok\n$\n"
        data = write_3w(GCODE * 300, find_model("dv1MW0A000"))
        await port.write(b"XYZv3/upload=temp.gcode," + str(len(data)).encode() + b"\n")
        assert await read_until(port, b"\n") == b"ok\n"
        for block in p.iter_blocks(data, 8192, crc=False):
            await port.write(block)
            assert await read_until(port, b"\n") == b"ok\n"
        await port.write(b"XYZv3/uploadDidFinish")
        assert await read_until(port, b"\n") == b"ok\n"
        assert await read_quiet(port) == b""
        assert sim.received("temp.gcode") == data
        assert sim.printer.settings.autolevel is False
    finally:
        await port.close()
        task.cancel()
        await device.close()


async def test_in_band_control_can_be_switched_off() -> None:
    from fabwire.transport import open_transport

    on = await open_transport("sim://xyz?speed=100&fault=door-open")
    off = await open_transport("sim://xyz?speed=100&control=0")
    try:
        async with asyncio.timeout(10):
            await on.write(b"XYZv3/simctl=fault:stuck:on\n")
            assert await read_until(on, b"$\n") == b"simctl:door-open+stuck\n$\n"
            await off.write(b"XYZv3/simctl=fault:stuck:on\n")
            assert await read_until(off, b"$\n") == b"E1$\n"
    finally:
        await on.close()
        await off.close()
