"""The client against the simulator over TCP and fault-injecting links, and against hosts that are not a Line-us."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from fabwire.errors import DeviceError, InputError, LinkClosed, LinkTimeout, LocalProtocolError, RemoteProtocolError
from fabwire.lineus import protocol as p
from fabwire.lineus.arm import MoveRecord
from fabwire.lineus.client import LineUs, Network, Position, StoredDrawing, parse_file_list
from fabwire.lineus.sim import LineUsSim, SimOptions, resolve_version
from fabwire.lineus.sync import LineUsSync
from fabwire.transport import FaultPlan, FaultyTransport, Transport, memory_pair, open_tcp, serve_tcp
from fabwire.transport.tap import TapTransport, TraceWriter, read_trace
from robustness.fakeclock import run_on_fake_clock


@contextlib.asynccontextmanager
async def connected(port: int, *, plan: FaultPlan | None = None, **kwargs: object) -> AsyncIterator[LineUs]:
    async with asyncio.timeout(30):
        transport: Transport = await open_tcp("127.0.0.1", port)
        if plan is not None:
            transport = FaultyTransport(transport, plan)
        arm = await LineUs.connect(transport, **kwargs)  # type: ignore[arg-type]
        try:
            yield arm
        finally:
            await arm.close()


async def test_every_command(lineus_sim) -> None:
    running = await lineus_sim()
    async with connected(running.port) as arm:
        assert arm.hello == p.Hello("3.2.0 Nov 17 2019 17:54:57", "line-us", "123456")
        assert arm.hello.firmware_major == 3
        assert await arm.position() == Position(1000, 1000, 1000)
        assert await arm.move(1200, 0) == Position(1200, 0, 1000)
        assert (await arm.pen_down()).pen_down
        assert await arm.move(1300, 0) == Position(1300, 0, 0)
        assert not (await arm.pen_up()).pen_down
        assert await arm.rapid(1000, -500) == Position(1000, -500, 1000)
        await arm.set_origin(100, 0, 2)
        assert await arm.move(500, 0) == Position(1100, 0, 1000)
        assert await arm.move_uncalibrated(1200, 100, keep="xy") == Position(1200, 100, 1000)
        assert await arm.home() == Position(1000, 1000, 1000)
        await arm.set_speed(3, 20)
        assert arm.model.draw_step == 3
        assert arm.model.travel_step == 20
        assert await arm.servo_angles() == {"S": 135.0, "E": 45.0, "P": 135.0}
        assert await arm.capabilities() == {"CONNECTMODE": "ST", "MACHINENAME": "line-us"}
        diag = await arm.diagnostics()
        assert diag["ChipID"] == "123456"
        assert diag["ResetReason"] == "External System"
        assert await arm.name() == "line-us"
        await arm.set_name("studio-arm")
        assert await arm.name() == "studio-arm"
        expected = [Network("fabwire-lab", True, True), Network("neighbours-wifi", True, False)]
        assert await arm.wifi_networks() == expected
        await arm.add_wifi("cafe net", "pass word")
        assert Network("cafe net", False, True) in await arm.wifi_networks()
        await arm.forget_wifi("cafe net")
        with pytest.raises(DeviceError, match="no stored network"):
            await arm.forget_wifi("cafe net")
        await arm.forget_wifi()
        assert all(not n.known for n in await arm.wifi_networks())
        assert await arm.list_drawings() == [StoredDrawing(1, 156, "/0000001.txt")]
        assert await arm.save_drawing(5, ["G54 X0 Y0 S1", "", "G01 X1200 Y0 Z0", "G01 Z1000"]) == 3
        assert running.sim.files[5] == "G54 X0 Y0 S1\nG01 X1200 Y0 Z0\nG01 Z1000\n"
        assert [d.slot for d in await arm.list_drawings()] == [1, 5]
        await arm.delete_drawing(5)
        with pytest.raises(DeviceError, match="no drawing 5"):
            await arm.delete_drawing(5)
        usage = await arm.storage()
        assert usage["FSTotal"] == 1953282
        assert await arm.zmap() == (0, 100, 300, 200)
        await arm.set_zmap((0, 50, 60, 70))
        assert await arm.zmap() == (0, 50, 60, 70)
        await arm.set_zmap(None)
        assert await arm.zmap() == (0, 0, 0, 0)
        await arm.gestures(False)
        await arm.memory_drawing(1)
        await arm.timed_demo(3, 120, 1)
        with pytest.raises(InputError, match="confirm"):
            await arm.calibrate()
        await arm.calibrate(confirm=True)
        with pytest.raises(InputError, match="confirm"):
            await arm.factory_reset()
        with pytest.raises(InputError, match="confirm"):
            await arm.firmware_update()
        with pytest.raises(DeviceError, match="unreachable"):
            await arm.firmware_update(confirm=True)
        await arm.factory_reset(wipe_files=True, confirm=True)
        assert await arm.list_drawings() == []
        assert await arm.name() == "line-us"
        with pytest.raises(LocalProtocolError):
            await arm.set_name("no spaces allowed")
        with pytest.raises(LocalProtocolError):
            await arm.move(float("nan"), 0)


async def test_clamped_move_reports_clamped_point(lineus_sim) -> None:
    running = await lineus_sim()
    async with connected(running.port) as arm:
        await arm.move(1200, 0, 0)
        assert await arm.move(2500, 0) == Position(1950, 0, 1000)


async def test_firmware1_personality(lineus_sim) -> None:
    running = await lineus_sim(version=resolve_version("1.0.1"))
    async with connected(running.port, lookahead=True) as arm:
        assert arm.hello.firmware == (1, 0, 1)
        assert not arm.lookahead  # firmware 1 cannot buffer a second command
        assert await arm.move(1200.4, 10.6) == Position(1200, 11, 1000)


async def test_reply_awaited_no_earlier_than_the_move(lineus_sim) -> None:
    running = await lineus_sim(speed=20.0)
    async with connected(running.port) as arm:
        await arm.move(1000, -800)
        loop = asyncio.get_running_loop()
        began = loop.time()
        await arm.move(1000, 800)
        elapsed = loop.time() - began
        move = running.sim.arm.moves[-1]
        assert elapsed >= (move.finished - move.started) / 20.0 * 0.9


def wire_log(transport: Transport, path: Path) -> Transport:
    """`transport` with what crosses it recorded in order to the capture at `path` (see `wire`)."""
    return TapTransport(transport, TraceWriter.to_file(path, url=transport.url, peer=transport.peer), log=False)


def wire(path: Path) -> list[tuple[str, bytes]]:
    """A capture's chunks in order: `('>', bytes written)` and `('<', bytes read)`."""
    return [(r.direction, r.data) for r in read_trace(path) if r.direction is not None]


@pytest.mark.parametrize("lookahead", [True, False])
def test_lookahead_pipelines_moves(lookahead: bool, tmp_path: Path) -> None:
    """With look-ahead the next move is on the wire before the reply to the one ahead of it, and each move starts
    the instant the one before finishes; without it, strictly one at a time. On a fake clock, so that load on the
    machine cannot delay a send: the order on the wire and the arm's record are what is checked."""

    async def main() -> tuple[list[object], list[MoveRecord]]:
        sim = LineUsSim(SimOptions(speed=20.0))
        host, device = memory_pair("lineus")
        tapped = wire_log(host, tmp_path / "wire.jsonl")
        server = asyncio.create_task(sim.serve(device))
        arm = await LineUs.connect(tapped, lookahead=lookahead)
        try:
            replies = await arm.run([p.Move(1000 + 20 * i, -300 + 40 * i, 0) for i in range(15)])
        finally:
            await arm.close()
            await server
            await sim.close()
        return [r.get("Y") for r in replies], list(sim.arm.moves)

    ys, moves = run_on_fake_clock(main())
    assert ys == [f"{-300 + 40 * i:.2f}" for i in range(15)]
    assert [m.end[:2] for m in moves[-15:]] == [(1000 + 20 * i, -300 + 40 * i) for i in range(15)]
    assert all(b.started == a.finished > a.started for a, b in itertools.pairwise(moves[-15:]))
    sent = replied = 0
    ahead: list[int] = []  # moves on the wire beyond the one whose reply comes next, as each reply arrives
    for direction, data in wire(tmp_path / "wire.jsonl"):
        if direction == ">":
            sent += data.count(b"G01")
        else:
            for _ in range(data.count(b"ok X:")):  # a move's reply
                ahead.append(sent - replied - 1)
                replied += 1
    assert replied == 15
    if lookahead:
        assert min(ahead[:-1]) >= 1  # every reply but the last found the next move already sent
    else:
        assert set(ahead) == {0}


@pytest.mark.parametrize("plan", [FaultPlan(chunk=1, seed=1), FaultPlan(chunk=3, delay=0.002, seed=2)])
async def test_over_split_and_delayed_links(lineus_sim, plan: FaultPlan) -> None:
    running = await lineus_sim()
    async with connected(running.port, plan=plan) as arm:
        assert arm.hello.name == "line-us"
        for i in range(5):
            assert await arm.move(1100 + 10 * i, 0, 0) == Position(1100 + 10 * i, 0, 0)
        assert (await arm.diagnostics())["name"] == "line-us"
    assert running.sim.arm.strokes == [[(1100, 0), (1110, 0), (1120, 0), (1130, 0), (1140, 0)]]


async def test_corrupted_replies_end_in_a_clear_error(lineus_sim) -> None:
    running = await lineus_sim()
    outcomes: list[str] = []
    for seed in range(4):
        plan = FaultPlan(corrupt=0.01, side="read", seed=seed)
        try:
            async with connected(running.port, plan=plan, reply_timeout=0.3, hello_timeout=1.0) as arm:
                for i in range(20):  # short moves near home keep each reply's time limit short
                    await arm.move(1000 + 5 * i, 1000)
            outcomes.append("ok")
        except (RemoteProtocolError, LinkTimeout, DeviceError) as exc:
            outcomes.append(type(exc).__name__)
    assert any(outcome != "ok" for outcome in outcomes)


async def test_disconnect_mid_drawing_is_a_clear_error() -> None:
    sim = LineUsSim(SimOptions(speed=5.0))

    async def cut_after_a_few_replies(transport: Transport) -> None:
        await sim.serve(FaultyTransport(transport, FaultPlan(disconnect_after=200, side="write")))

    server = await serve_tcp(cut_after_a_few_replies, "127.0.0.1", 0)
    try:
        async with connected(server.sockets[0].getsockname()[1]) as arm:
            async def draw() -> None:
                for i in range(50):
                    await arm.move(1000 + 10 * i, 0, 0)

            with pytest.raises(LinkClosed, match="unanswered"):
                await draw()
            with pytest.raises(LinkClosed):
                await arm.position()
    finally:
        server.close()
        await sim.close()


@contextlib.asynccontextmanager
async def impostor(greeting: bytes | None, *, close: bool = False) -> AsyncIterator[int]:
    async def handler(transport: Transport) -> None:
        if greeting:
            await transport.write(greeting)
        if close:
            return
        with contextlib.suppress(LinkClosed):
            while True:
                await transport.read()

    server = await serve_tcp(handler, "127.0.0.1", 0)
    try:
        yield server.sockets[0].getsockname()[1]
    finally:
        server.close()


@pytest.mark.parametrize(("greeting", "close", "error", "match"), [
    (b"SSH-2.0-OpenSSH_9.6\r\n", False, RemoteProtocolError, "not a Line-us"),
    (b"ok X:1 Y:2 Z:3\r\n\x00", False, RemoteProtocolError, "not a Line-us"),
    (None, False, LinkTimeout, "no hello"),
    (b"hel", True, LinkClosed, "before greeting"),
    (b"SS", False, RemoteProtocolError, "not a Line-us: it greeted with b'SS'"),  # the start of SSH, then silence
    (b"HTTP/1.1 400 Bad Request\r\n", True, RemoteProtocolError, "not a Line-us: it is a web server"),
])
async def test_host_that_is_not_a_lineus(greeting: bytes | None, close: bool, error: type[Exception],
                                         match: str) -> None:
    async with impostor(greeting, close=close) as port, asyncio.timeout(10):
        transport = await open_tcp("127.0.0.1", port)
        with pytest.raises(error, match=match):
            await LineUs.connect(transport, hello_timeout=0.5)
        assert transport.closed


async def test_wedged_device_times_out() -> None:
    hello = p.Hello("3.2.0", "line-us", "1").encode()
    async with impostor(hello) as port, connected(port, reply_timeout=0.3) as arm:
        with pytest.raises(LinkTimeout, match="no reply to 'M114'"):
            await arm.position()
        with pytest.raises(LinkTimeout):
            await arm.position()


async def test_cancelling_a_wait_is_a_cancellation_not_a_timeout() -> None:
    """A caller that cancels its own wait gets CancelledError (the reply timer only turns its own cancels into
    LinkTimeout), and the wait's deadline passing later ends nothing."""
    hello = p.Hello("3.2.0", "line-us", "1").encode()
    async with impostor(hello) as port, connected(port, reply_timeout=0.3) as arm:
        waiting = asyncio.create_task(arm.position())
        await asyncio.sleep(0.05)
        waiting.cancel()
        with pytest.raises(asyncio.CancelledError):
            await waiting
        await asyncio.sleep(0.5)
        assert arm._failure is None
        assert not arm._deadlines
        assert not arm._expired


async def test_each_wait_times_out_at_its_own_deadline() -> None:
    """Two tasks waiting at once (look-ahead) with different limits: the shorter runs out first, and a wait that
    ends in time leaves no timer behind that could cancel its task later."""
    hello = p.Hello("3.2.0", "line-us", "1").encode()
    async with impostor(hello) as port, connected(port, reply_timeout=5.0, lookahead=True) as arm:
        short = asyncio.create_task(arm.send(p.GetPosition(), timeout=0.2))
        long = asyncio.create_task(arm.send(p.GetPosition(), timeout=0.6))
        with pytest.raises(LinkTimeout, match=r"within 0\.2 s"):
            await short
        with pytest.raises((LinkTimeout, LinkClosed)):
            await long
        assert not arm._deadlines
        assert not arm._expired


def test_file_list_parsing() -> None:
    assert parse_file_list("/0000001.txt-109291;/cal-29;/key-344; ") == [StoredDrawing(1, 109291, "/0000001.txt")]
    assert parse_file_list("") == []
    with pytest.raises(RemoteProtocolError):
        parse_file_list("/0000001.txt;")


async def test_sync_facade(lineus_sim) -> None:
    running = await lineus_sim()

    def script() -> tuple[Position, Position, list[StoredDrawing]]:
        with LineUs.open_sync(running.address) as arm:
            assert isinstance(arm, LineUsSync)
            assert arm.hello.name == "line-us"
            moved = arm.move(1200, 0, 0)
            arm.pen_up()
            return moved, arm.position(), arm.list_drawings()

    moved, where, drawings = await asyncio.wait_for(asyncio.to_thread(script), 20)
    assert moved == Position(1200, 0, 0)
    assert where == Position(1200, 0, 1000)
    assert drawings[0].slot == 1


async def test_move_wait_is_sized_in_machine_units_under_g54(lineus_sim) -> None:
    running = await lineus_sim(speed=float("inf"))
    arm = await LineUs.open(running.address)
    try:
        await arm.move(1000, 0, 1000)
        unscaled = arm._timeout_for(arm._span(p.Move(900, 0))[0])
        await arm.set_origin(0, 0, 2.0)
        # Under scale 2 the drawing-unit move to X900 ends at machine X1800: eight times as far.
        assert arm._span(p.Move(900, 0)) == (800, (1800, 0, 1000))
        assert arm._timeout_for(arm._span(p.Move(900, 0))[0]) > unscaled
        assert await arm.move(900, 0) == Position(1800, 0, 1000)
    finally:
        await arm.close()


def _zone_commands(received: object) -> list[str]:
    """Move commands a simulator received whose machine target lies in the body notch (no G54 in use)."""
    bad = []
    for text in received:  # type: ignore[attr-defined]
        command = p.parse_command(text)
        if (isinstance(command, p.Move | p.RawMove) and command.x is not None and command.y is not None
                and command.x < 700 and command.y < 0):
            bad.append(text)
    return bad


async def test_firmware1_target_in_the_body_notch_is_clamped_with_the_pen_up(lineus_sim) -> None:
    running = await lineus_sim(version=resolve_version("1.0.1"))
    async with connected(running.port) as arm:
        assert arm.guard_body
        where = await arm.move(600, -300, 0)
        assert where.z == 1000
        assert where.x >= 700
        assert where.y == -300
        assert arm.notices
        assert "body notch" in arm.notices[0]
        reply = await arm.send(p.parse_command("G01 X650 Y-1000 Z0"))  # raw G-code goes through the same guard
        assert reply.ok
    assert _zone_commands(running.sim.received) == []
    assert running.sim.arm.collisions == []


async def test_firmware1_moves_across_the_notch_go_round_its_corner(lineus_sim) -> None:
    running = await lineus_sim(version=resolve_version("1.0.1"))
    async with connected(running.port) as arm:
        await arm.move(550, 300, 0)
        await arm.move(550, 100)  # pen down, still outside the notch
        await arm.move(1000, -600)  # would cut the notch with the pen down
        assert len(arm.notices) == 1
        assert "cross the body notch" in arm.notices[0]
        assert await arm.position() == Position(1000, -600, 0)  # the requested pen state at the end
        await arm.set_origin(500, -500, 2.0)  # the same through G54: drawing (50, 300) is machine (600, 100)
        await arm.move(50, 300, 1000)
        await arm.move(250, 0)  # machine (1000, -500)
    assert running.sim.arm.collisions == []
    assert "G01 Z1000" in running.sim.received  # lifted before going round
    corners = [text for text in running.sim.received if text.startswith("G01 X700.01 Y0.01")]
    assert corners  # the first detour, in machine units
    assert any(text.startswith("G01 X100.005 Y250.005") for text in running.sim.received)  # the second, via G54


async def test_firmware3_keeps_out_of_the_notch_itself(lineus_sim) -> None:
    running = await lineus_sim()
    async with connected(running.port) as arm:
        assert not arm.guard_body
        assert await arm.move(600, -300, 0) == Position(700, -300, 1000)  # the firmware clamps
        assert arm.notices == []
    assert "G01 X600 Y-300 Z0" in running.sim.received


async def test_a_reply_that_never_comes_leaves_no_unretrieved_exception(caplog) -> None:
    import gc

    hello = p.Hello("3.2.0", "line-us", "1").encode()
    caplog.set_level("ERROR", logger="asyncio")
    async with impostor(hello) as port, connected(port, reply_timeout=0.2, lookahead=True) as arm:
        with pytest.raises(LinkTimeout):
            await arm.run([p.GetPosition(), p.GetPosition(), p.GetPosition()])
    gc.collect()
    await asyncio.sleep(0)
    assert not [r for r in caplog.records if "never retrieved" in r.getMessage()]


async def test_saving_past_the_flash_reports_the_machines_answer(lineus_sim) -> None:
    from fabwire.lineus.sim_handlers import FS_TOTAL

    line = "G01 X1200 Y0 Z0\n"
    running = await lineus_sim(files={1: line * ((FS_TOTAL - 1000) // len(line))})
    async with connected(running.port) as arm:
        with pytest.raises(DeviceError, match="file system full"):
            await arm.save_drawing(2, ["G01 X1300 Y100 Z0"] * 200)
        assert [d.slot for d in await arm.list_drawings()] == [1, 2]  # closed with what fitted
        usage = await arm.storage()
        assert usage["FSUsed"] <= usage["FSTotal"] == FS_TOTAL
