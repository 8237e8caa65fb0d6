"""The simulator on a real TCP socket, checked byte for byte against the documented behaviour."""

from __future__ import annotations

import asyncio
import math
import time

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from fabwire.lineus import kinematics as kin
from fabwire.lineus.sim import SimOptions, resolve_version

HELLO3 = b'hello VERSION:"3.2.0 Nov 17 2019 17:54:57" NAME:line-us SERIAL:123456\r\n\x00'
HOME3 = b"ok X:1000.00 Y:1000.00 Z:1000.00\r\n\x00"


async def test_greeting_is_first_and_alone(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port, read_hello=False)
    assert await peer.reply() == HELLO3
    assert await peer.nothing_more() == b""


async def test_hello_is_configurable(lineus_sim, raw_peer) -> None:
    running = await lineus_sim(version=resolve_version("1.0.1"), name="bot-7", serial="990055")
    peer = await raw_peer(running.port, read_hello=False)
    assert await peer.reply() == b'hello VERSION:"1.0.1 Feb 11 2018 15:47:35" NAME:bot-7 SERIAL:990055\r\n\x00'


@pytest.mark.parametrize(
    "wire", [b"M114\x00", b"M114\x00\n", b"M114\r\n\x00", b"M114\r\n", b"M114\n", b"M114\r", b"M114\x00\r\x00"]
)
async def test_every_terminator_one_reply(lineus_sim, raw_peer, wire: bytes) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    assert await peer.ask(wire) == HOME3
    assert await peer.nothing_more() == b""
    assert await peer.ask(b"M114\x00") == HOME3


async def test_naive_client_reads_one_whole_reply_per_read(lineus_sim, raw_peer) -> None:
    running = await lineus_sim(speed=200.0)
    peer = await raw_peer(running.port)
    for wire in (b"G01 X1200 Y0 Z1000\x00", b"M114\x00", b"M122\x00", b"G01 Z0\x00", b"M20\x00", b"G28\x00"):
        await peer.send(wire)
        async with asyncio.timeout(5):
            chunk = await peer.reader.read(4096)
        assert chunk.endswith(b"\r\n\x00")
        assert chunk.count(b"\x00") == 1


async def test_blank_lines_draw_no_reply(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    await peer.send(b"\x00\n\r\n   \x00\t\x00")
    assert await peer.nothing_more() == b""


async def test_pipelined_and_split_input(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    await peer.send(b"M114\x00M115\x00")
    assert await peer.reply() == HOME3
    assert await peer.reply() == b"ok CONNECTMODE:ST MACHINENAME:line-us\r\n\x00"
    await peer.send(b"G01 X12")
    await asyncio.sleep(0.05)
    assert await peer.ask(b"00 Y0 Z1000\x00") == b"ok X:1200.00 Y:0.00 Z:1000.00\r\n\x00"


async def test_official_spacing_case_floats_partial_axes(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    assert await peer.ask(b"G01  X1000 Y0 Z1000\x00") == b"ok X:1000.00 Y:0.00 Z:1000.00\r\n\x00"
    assert await peer.ask(b"g01 x1200 y0 z1000\n") == b"ok X:1200.00 Y:0.00 Z:1000.00\r\n\x00"
    assert await peer.ask(b"G01 X1000.5 Y216.6666666666667 Z1000\x00") == b"ok X:1000.50 Y:216.67 Z:1000.00\r\n\x00"
    assert await peer.ask(b"G28\x00") == HOME3
    assert await peer.ask(b"G01 Z0\x00") == b"ok X:1000.00 Y:1000.00 Z:0.00\r\n\x00"
    assert await peer.ask(b"M20 \x00") == b'ok FS:"/0000001.txt-156;"\r\n\x00'


async def test_firmware1_integer_replies(lineus_sim, raw_peer) -> None:
    running = await lineus_sim(version=resolve_version("1"))
    peer = await raw_peer(running.port)
    assert await peer.ask(b"G01 X1200.4 Y0 Z1000\x00") == b"ok X:1200 Y:0 Z:1000\r\n\x00"


async def test_name_round_trip_and_next_hello(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    assert await peer.ask(b"M550\x00") == b"ok MACHINENAME:line-us\r\n\x00"
    assert (await peer.ask(b"M550 Pmy-bot\x00")).startswith(b"ok")
    assert (await peer.ask(b"M550 Pbad name!\x00")).startswith(b"error")
    second = await raw_peer(running.port, read_hello=False)
    assert b" NAME:my-bot " in await second.reply()


async def test_g54_is_per_connection(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    first = await raw_peer(running.port)
    assert (await first.ask(b"G54 X100 Y0 S2.5\x00")).startswith(b"ok")
    assert await first.ask(b"G01 X400 Y40 Z1000\x00") == b"ok X:1100.00 Y:100.00 Z:1000.00\r\n\x00"
    second = await raw_peer(running.port)
    assert await second.ask(b"G01 X1000 Y0 Z1000\x00") == b"ok X:1000.00 Y:0.00 Z:1000.00\r\n\x00"
    assert await first.ask(b"G01 X400 Y0\x00") == b"ok X:1100.00 Y:0.00 Z:1000.00\r\n\x00"


async def test_step_counts_set_move_durations(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    arm = running.sim.arm
    for wire in (b"G01 X1000 Y0 Z1000\x00", b"G01 Z0\x00", b"G94 S3\x00"):
        assert (await peer.ask(wire)).startswith(b"ok")
    await peer.ask(b"G01 X1100 Y100 Z0\x00")
    move = arm.moves[-1]
    assert move.finished - move.started == pytest.approx(34 * 0.010)
    await peer.ask(b"G94 S5\x00")
    await peer.ask(b"G01 X1000 Y0 Z0\x00")
    assert arm.moves[-1].finished - arm.moves[-1].started == pytest.approx(20 * 0.010)
    await peer.ask(b"G01 Z1000\x00")
    await peer.ask(b"G01 X1100 Y100\x00")
    assert arm.moves[-1].finished - arm.moves[-1].started == pytest.approx(7 * 0.010)


HELLO_WORLD = [(900, 300, 0), (900, -300, 0), (900, -300, 1000), (1200, 300, 0), (1200, -300, 0),
               (1200, -300, 1000), (900, 0, 0), (1200, 0, 0), (1200, 0, 1000), (1500, 150, 0), (1500, -300, 0),
               (1500, -300, 1000), (1500, 250, 0), (1500, 300, 0), (1500, 300, 1000)]


async def test_hello_world_golden_drawing(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    for x, y, z in HELLO_WORLD:
        assert (await peer.ask(f"G01 X{x} Y{y} Z{z}\x00".encode())).startswith(b"ok")
    assert running.sim.arm.strokes == [
        [(900, 300), (900, -300)], [(1200, 300), (1200, -300)], [(900, 0), (1200, 0)],
        [(1500, 150), (1500, -300)], [(1500, 250), (1500, 300)],
    ]


async def test_out_of_area_clamped_with_pen_lifted(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    reply = await peer.ask(b"G01 X0 Y0 Z0\x00")
    fields = dict(part.split(":") for part in reply[3:-3].decode().split())
    assert reply.startswith(b"ok ")
    assert fields["Z"] == "1000.00"
    assert kin.is_reachable(float(fields["X"]), float(fields["Y"]))
    assert await peer.ask(b"G01 X2500 Y0 Z0\x00") == b"ok X:1950.00 Y:0.00 Z:1000.00\r\n\x00"
    assert running.sim.arm.moves[-1].clamped
    assert running.sim.arm.strokes == []
    assert await peer.ask(b"G01 X1000 Y0 Z-100\x00") == b"ok X:1000.00 Y:0.00 Z:1000.00\r\n\x00"
    assert await peer.ask(b"G01 Z1500\x00") == b"ok X:1000.00 Y:0.00 Z:1000.00\r\n\x00"


async def test_line_across_the_body_notch_lifts_there(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    for wire in (b"G01 X500 Y100 Z1000\x00", b"G01 Z0\x00", b"G01 X800 Y-200 Z0\x00"):
        assert (await peer.ask(wire)).startswith(b"ok")
    [first, second] = running.sim.arm.strokes
    assert first[0] == (500, 100)
    assert first[1] == pytest.approx((600, 0), abs=3)
    assert second[0] == pytest.approx((700, -100), abs=3)
    assert second[1] == (800, -200)


async def test_commands_before_the_hello_is_read(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port, read_hello=False)
    await peer.send(b"M114\x00")
    assert await peer.reply() == HELLO3
    assert await peer.reply() == HOME3


async def test_rapid_move_sweeps_a_curve(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    for wire in (b"G01 X800 Y-800 Z0\x00", b"G00 X1600 Y800 Z0\x00"):
        assert (await peer.ask(wire)).startswith(b"ok")
    [curve] = running.sim.arm.strokes
    assert curve[0] == (800, -800)
    assert curve[-1] == (1600, 800)
    assert len(curve) > 2
    assert all(kin.is_reachable(x, y) for x, y in curve)


@pytest.mark.parametrize("wire", [b"G04 P100\x00", b"G01\x00", b"G01 Q5\x00", b"G01 X\x00", b"G01 X1e3\x00",
                                  b"G94 S31\x00", b"M28 S33\x00", b"\xff\xfe\x00", b"M29\x00", b"M30 S9\x00",
                                  b"M171\x00", b"M997\x00", b"M170\x00"])
async def test_bad_commands_get_error_info_and_change_nothing(lineus_sim, raw_peer, wire: bytes) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    reply = await peer.ask(wire)
    assert reply.startswith(b'error INFO:"')
    assert reply.endswith(b'"\r\n\x00')
    assert await peer.ask(b"M114\x00") == HOME3
    assert list(running.sim.arm.moves) == []


async def test_garbage_gets_one_error_per_line_and_the_link_survives(lineus_sim, raw_peer) -> None:
    import random

    from fabwire.lineus.protocol import CommandReader

    noise = bytes(random.Random(7).randrange(256) for _ in range(3000))
    expected = len(CommandReader().feed(noise + b"\x00"))
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    await peer.send(noise + b"\x00")
    replies = [await peer.reply() for _ in range(expected)]
    assert all(r.startswith((b"error INFO:", b"ok")) for r in replies)
    assert (await peer.ask(b"M114\x00")).startswith(b"ok X:")
    assert (await peer.ask(b"M115\x00")).startswith(b"ok CONNECTMODE:ST")


async def test_overlong_line_is_refused_and_link_survives(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    await peer.send(b"G01 X" + b"1" * 10_000)
    reply = await peer.ask(b"\x00")
    assert reply.startswith(b"error")
    assert await peer.ask(b"M114\x00") == HOME3


async def test_save_to_memory_records_without_moving(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    for wire in (b"M28 S2\x00", b"G01 X1200 Y0 Z0\x00", b"M30 S1\x00", b"M29\x00"):
        reply = await peer.ask(wire)
        assert reply.startswith(b"error" if wire.startswith(b"M30") else b"ok")
    assert list(running.sim.arm.moves) == []
    stored = "G01 X1200 Y0 Z0\n"
    assert await peer.ask(b"M20\x00") == f'ok FS:"/0000001.txt-156;/0000002.txt-{len(stored)};"\r\n\x00'.encode()
    assert running.sim.files[2] == stored
    assert (await peer.ask(b"M30 S2\x00")).startswith(b"ok")
    assert await peer.ask(b"M20\x00") == b'ok FS:"/0000001.txt-156;"\r\n\x00'
    usage = await peer.ask(b"M39\x00")
    assert usage.startswith(b"ok FSUsed:529 FSTotal:1953282 FSFree:1952753 FSPercent:0")


async def test_move_reply_held_until_modelled_completion(lineus_sim, raw_peer) -> None:
    speed = 20.0
    running = await lineus_sim(speed=speed)
    sim = running.sim
    peer = await raw_peer(running.port)
    for wire in (b"G01 X800 Y-500 Z1000\x00", b"G01 Z0\x00", b"G94 S5\x00"):
        assert (await peer.ask(wire)).startswith(b"ok")
    began = time.monotonic()
    await peer.send(b"G01 X800 Y500 Z0\x00M114\x00")
    move_reply = await peer.reply()
    position_reply = await peer.reply()
    elapsed = time.monotonic() - began
    assert move_reply == position_reply == b"ok X:800.00 Y:500.00 Z:0.00\r\n\x00"
    move = sim.arm.moves[-1]
    assert move.finished - move.started == pytest.approx(200 * 0.010)
    sent_at = {data: t for t, data in sim.sent}
    assert sent_at[move_reply] >= move.finished
    assert elapsed >= (move.finished - move.started) / speed * 0.9


async def test_reply_on_accept_answers_before_motion_ends(lineus_sim, raw_peer) -> None:
    running = await lineus_sim(speed=5.0, reply="accept")
    peer = await raw_peer(running.port)
    await peer.send(b"G01 X1000 Y-1000 Z1000\x00")
    assert await peer.reply() == b"ok X:1000.00 Y:-1000.00 Z:1000.00\r\n\x00"
    assert running.sim.sent[-1][0] < 134 * 0.010
    assert list(running.sim.arm.moves) == []  # still moving when the reply went out


async def test_lookahead_keeps_one_move_queued(lineus_sim, raw_peer) -> None:
    running = await lineus_sim(speed=10.0)
    peer = await raw_peer(running.port)
    await peer.send(b"G01 X1000 Y0\x00G01 X1000 Y-1000\x00M114\x00")
    replies = [await peer.reply() for _ in range(3)]
    assert replies[0] == b"ok X:1000.00 Y:0.00 Z:1000.00\r\n\x00"
    assert replies[1] == replies[2] == b"ok X:1000.00 Y:-1000.00 Z:1000.00\r\n\x00"
    first, second = running.sim.arm.moves
    assert second.started == pytest.approx(first.finished)


async def test_disconnect_mid_move_then_fresh_connection(lineus_sim, raw_peer) -> None:
    running = await lineus_sim(speed=10.0)
    peer = await raw_peer(running.port)
    await peer.send(b"G54 X100 Y0 S2\x00G01 X1000 Y-500 Z1000\x00")
    assert (await peer.reply()).startswith(b"ok")
    await peer.close()
    again = await raw_peer(running.port, read_hello=False)
    assert (await again.reply()).startswith(b"hello ")
    assert await again.ask(b"G01 X1000 Y0 Z1000\x00") == b"ok X:1000.00 Y:0.00 Z:1000.00\r\n\x00"


async def test_half_close_still_gets_replies(lineus_sim, raw_peer) -> None:
    running = await lineus_sim(speed=50.0)
    peer = await raw_peer(running.port)
    await peer.send(b"G01 X1200 Y0\x00M114\x00")
    peer.writer.write_eof()
    assert (await peer.reply()).startswith(b"ok X:1200.00")
    assert (await peer.reply()).startswith(b"ok X:1200.00")


async def test_info_commands(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    assert await peer.ask(b"M115\x00") == b"ok CONNECTMODE:ST MACHINENAME:line-us\r\n\x00"
    assert await peer.ask(b"M114 S\x00") == b"ok S:135.00 E:45.00 P:135.00\r\n\x00"
    assert await peer.ask(b"G31\x00") == b'ok ZMap:"0;100;300;200"\r\n\x00'
    assert (await peer.ask(b"G31 S0;10;20;30\x00")).startswith(b"ok")
    assert await peer.ask(b"G31\x00") == b'ok ZMap:"0;10;20;30"\r\n\x00'
    diag = await peer.ask(b"M122\x00")
    assert diag.startswith(b"ok ChipID:123456 ")
    assert b' ResetReason:"External System" ' in diag
    assert await peer.ask(b"M587\x00") == b"ok fabwire-lab:1 neighbours-wifi:2\r\n\x00"
    assert (await peer.ask(b'M587 S"cafe net" Ppw\x00')).startswith(b"ok")
    assert await peer.ask(b"M587\x00") == b'ok fabwire-lab:1 neighbours-wifi:2 "cafe net":3\r\n\x00'
    assert (await peer.ask(b"M588 S*\x00")).startswith(b"ok")
    assert await peer.ask(b"M587\x00") == b"ok fabwire-lab:2 neighbours-wifi:2\r\n\x00"
    for wire in (b"M23 S1\x00", b"M85 S3 P120\x00", b"M291 S2\x00", b"M552 S2 P1\x00", b"M280\x00", b"M374\x00"):
        assert (await peer.ask(wire)).startswith(b"ok"), wire
    assert b" MemDraw:1 Gestures:0 " in await peer.ask(b"M122\x00")
    assert (await peer.ask(b"M171 SSPIFFS\x00")).startswith(b"ok")
    assert await peer.ask(b"M20\x00") == b'ok FS:""\r\n\x00'


async def test_two_clients_share_one_arm(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    first = await raw_peer(running.port)
    second = await raw_peer(running.port)
    await first.ask(b"G01 X1200 Y0 Z1000\x00")
    assert await second.ask(b"M114\x00") == b"ok X:1200.00 Y:0.00 Z:1000.00\r\n\x00"


async def test_timed_demo_draws_the_start_of_a_stored_drawing(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    sim = running.sim
    assert await sim.play(sim.files[1], limit=1.0) >= 1.0
    assert sim.arm.strokes == [[(1100, -200), (1500, -200)]]
    assert sim.arm.position[2] == kin.Z_UP
    peer = await raw_peer(running.port)
    assert (await peer.ask(b"M85 S1 P0.05 K1\x00")).startswith(b"ok")
    await asyncio.sleep(0.3)
    assert len(sim.arm.strokes) == 1  # never while a client is connected
    await peer.close()
    await asyncio.wait_for(sim.wait_idle(), 5)
    await asyncio.sleep(0.5)
    assert len(sim.arm.strokes) > 1
    assert all(stroke == [(1100, -200), (1500, -200)] for stroke in sim.arm.strokes)


def test_options_validation() -> None:
    with pytest.raises(ValueError, match="speed factor"):
        SimOptions(speed=-1)
    with pytest.raises(ValueError, match="machine name"):
        SimOptions(name="bad name")
    with pytest.raises(ValueError, match="firmware version"):
        resolve_version("banana")
    for never in ("9.9.9", "4.0.0", "0.9.1", "3.2.1"):
        with pytest.raises(ValueError, match="never released"):
            resolve_version(never)
    for bad in ("3.2", "1.0.1\x00", "3.2.0\"x"):
        with pytest.raises(ValueError, match="firmware version"):
            resolve_version(bad)
    assert resolve_version("2.0.2Beta6 Sep 14 2018 22:17:02") == "2.0.2Beta6 Sep 14 2018 22:17:02"
    assert resolve_version("3.1.0") == "3.1.0"
    assert math.isinf(SimOptions(speed=0).speed)


async def test_in_process_simulator_url() -> None:
    from fabwire.lineus.client import LineUs

    async with asyncio.timeout(10):
        arm = await LineUs.open("sim://lineus?speed=inf&name=inproc&version=1.0.1")
        try:
            assert arm.hello.name == "inproc"
            assert arm.hello.firmware_major == 1
            assert (await arm.move(1200, 0)).x == 1200
        finally:
            await arm.close()


async def test_dots_are_recorded(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    wires = (b"G01 X1000 Y0 Z1000", b"G01 Z0", b"G01 Z1000",  # down and up in one place
             b"G01 X1200 Y0 Z0", b"G01 X1200 Y0 Z0", b"G01 Z1000",  # lands at the end of the hop, a stay in place
             b"G01 X1300 Y0 Z300", b"G01 X1400 Y0 Z300", b"G01 Z1000",  # a line at a lighter pen
             b"G01 X1500 Y100 Z0")  # left down at the end
    for wire in wires:
        assert (await peer.ask(wire + b"\x00")).startswith(b"ok")
    assert running.sim.arm.strokes == [[(1000, 0)], [(1200, 0)], [(1300, 0), (1400, 0)], [(1500, 100)]]


async def test_parameters_written_without_spaces(lineus_sim, raw_peer) -> None:
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    assert await peer.ask(b"G01X1200Y-10.5Z1000\x00") == b"ok X:1200.00 Y:-10.50 Z:1000.00\r\n\x00"
    assert await peer.ask(b"G1 X1300Y0\x00") == b"ok X:1300.00 Y:0.00 Z:1000.00\r\n\x00"
    assert (await peer.ask(b"G01 X1e3Y0\x00")).startswith(b"error")  # an exponent is not a parameter
    assert (await peer.ask(b"M550 Pbot2\x00")).startswith(b"ok")  # M values are text: never split
    assert running.sim.name == "bot2"


async def test_firmware1_reaches_the_body_notch_and_records_the_collision(lineus_sim, raw_peer) -> None:
    old = await lineus_sim(version=resolve_version("1.0.1"))
    peer = await raw_peer(old.port)
    assert await peer.ask(b"G01 X1200 Y-300 Z1000\x00") == b"ok X:1200 Y:-300 Z:1000\r\n\x00"
    assert not old.sim.arm.collisions
    assert await peer.ask(b"G01 X600 Y-300 Z0\x00") == b"ok X:600 Y:-300 Z:0\r\n\x00"  # no clamp: it goes there
    [(x, y)] = old.sim.arm.collisions
    assert 600 <= x < 700
    assert y == -300
    # Leaving it scrapes the body again, and a pen-up hop through the notch between two points outside it
    # hits the body too; one that passes the notch's corner does not.
    for wire in (b"G01 X600 Y200 Z1000\x00", b"G01 X800 Y-600 Z1000\x00", b"G01 X600 Y200\x00",
                 b"G01 X1000 Y-600\x00"):
        assert (await peer.ask(wire)).startswith(b"ok")
    assert len(old.sim.arm.collisions) == 4
    # Below x = 500 even firmware 1.0.1 clamps (and lifts the pen).
    reply = await peer.ask(b"G01 X300 Y-100 Z0\x00")
    assert reply.startswith(b"ok X:500 ")
    assert reply.endswith(b" Z:1000\r\n\x00")
    new = await lineus_sim()
    peer3 = await raw_peer(new.port)
    assert await peer3.ask(b"G01 X600 Y-300 Z0\x00") == b"ok X:700.00 Y:-300.00 Z:1000.00\r\n\x00"
    assert not new.sim.arm.collisions


async def test_clients_that_reset_before_the_hello_cost_a_few_log_lines(lineus_sim, raw_peer, caplog) -> None:
    import socket
    import struct

    from fabwire.transport.limits import BUSY_FOR

    running = await lineus_sim()
    caplog.set_level("DEBUG", logger="fabwire.lineus.sim")
    loop = asyncio.get_running_loop()

    def storm(count: int) -> None:
        for _ in range(count):
            with socket.create_connection(("127.0.0.1", running.port), timeout=5) as sock:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))

    await loop.run_in_executor(None, storm, 60)
    async with asyncio.timeout(10):
        await running.sim.wait_idle()
    said = b""
    for _ in range(10):  # the storm's last connections may hold every place for a moment: the client is told so
        peer = await raw_peer(running.port, read_hello=False)
        said = await peer.reply_line()
        if not said.startswith(b'error INFO:"simulator busy: '):
            break
        await asyncio.sleep(BUSY_FOR)
    assert said.startswith(b"hello")  # still serving
    went = [r for r in caplog.records if "went away" in r.getMessage()]
    assert 1 <= len(went) <= 5  # rate-limited, one line each while the budget lasts
    assert not [r for r in caplog.records if r.exc_info or r.levelno >= 40]


def test_rate_limited_log_counts_what_it_holds_back(caplog) -> None:
    import logging

    from fabwire.lineus.sim import RateLimitedLog

    caplog.set_level("INFO")
    # a logger outside "fabwire", whose handlers and propagation the CLI sets when a test runs it in-process
    limited = RateLimitedLog(logging.getLogger("rate-limited-log-test"), burst=2, window=10.0)
    sent = [limited.note(f"client {n} went away", now=n * 0.1) for n in range(5)]
    assert sent == [True, True, False, False, False]
    assert limited.note("client 5 went away", now=11.0)
    assert caplog.records[-1].getMessage() == "client 5 went away (3 similar message(s) suppressed)"


async def test_stored_drawings_cannot_outgrow_the_flash(lineus_sim, raw_peer) -> None:
    from fabwire.lineus.sim_handlers import FS_TOTAL

    line = "G01 X1200 Y0 Z0\n"
    big = line * ((FS_TOTAL - 2000) // len(line))  # leaves about 1.5 kB of flash
    running = await lineus_sim(files={1: big})
    peer = await raw_peer(running.port)
    assert (await peer.ask(b"M28 S2\x00")).startswith(b"ok")
    replies = [await peer.ask(b"G01 X1300 Y100 Z0\x00") for _ in range(200)]
    refused = [r for r in replies if r.startswith(b"error")]
    assert refused
    assert refused[0] == b'error INFO:"file system full: 1953282 bytes of flash, line not stored"\r\n\x00'
    assert replies.index(refused[0]) > 0
    assert all(r.startswith(b"error") for r in replies[replies.index(refused[0]):])
    assert (await peer.ask(b"M29\x00")).startswith(b"ok")
    usage = dict(f.split(b":") for f in (await peer.ask(b"M39\x00"))[3:-3].split())
    assert int(usage[b"FSUsed"]) <= FS_TOTAL
    # Rewriting a drawing frees its old bytes first.
    assert (await peer.ask(b"M28 S1\x00")).startswith(b"ok")
    assert await peer.ask(b"G01 X1200 Y0 Z0\x00") == b"ok\r\n\x00"
    assert (await peer.ask(b"M29\x00")).startswith(b"ok")
    assert running.sim.files[1] == "G01 X1200 Y0 Z0\n"


LONG_JUNK = st.tuples(st.text(alphabet='x9."é \x01', min_size=1, max_size=4), st.integers(1, 5000)).map(
    lambda t: t[0] * t[1])


@given(LONG_JUNK)
@example("x" * 5000)
def test_a_firmware_version_that_is_not_one_is_refused_in_one_short_line(text: str) -> None:
    message = ""
    try:
        resolve_version(text)
    except ValueError as e:
        message = str(e)
    assert len(message) <= 120


@given(LONG_JUNK)
@example("x" * 5000)
@example('"' * 5000)
def test_a_machine_name_or_serial_that_is_not_one_is_refused_in_one_short_line(text: str) -> None:
    for options in ({"name": text}, {"serial": text}):
        message = ""
        try:
            SimOptions(**options)
        except ValueError as e:
            message = str(e)
        assert len(message) <= 120
