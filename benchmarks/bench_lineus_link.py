"""Line-us link: client ↔ simulator command round trips on loopback TCP with motion delays off, and G-code files
read through the machine's interpreter (what `preview`/`draw` of a .gcode file and `files save` cost)."""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections.abc import Iterator

from common import Figure
from fabwire.lineus import protocol as p
from fabwire.lineus.client import LineUs
from fabwire.lineus.interpreter import trace_text
from fabwire.lineus.sim import LineUsSim, SimOptions
from fabwire.transport import open_tcp, serve_tcp

MOVES = 6_000
OFFICIAL_MOVES = 2_000
TRIALS = 3
"""Best of several runs: the machine is shared, and the least-disturbed run is the link's own speed."""
TARGET = 5_000.0
GCODE_LINES = 100_000
GCODE_TARGET = 10_000.0
"""Lines per second: a 100k-line drawing file previews in under 10 s on a loaded machine."""


def _targets(count: int) -> list[tuple[float, float]]:
    return [(1000.0 + (i % 50) * 4, -200.0 + (i % 37) * 8) for i in range(count)]


@contextlib.contextmanager
def _simulator_thread() -> Iterator[tuple[int, LineUsSim, asyncio.AbstractEventLoop]]:
    """A simulator (motion delays off) on loopback TCP, on its own event loop in its own thread: a Line-us is a
    machine of its own, and the official module is measured against the same setup (port, simulator, loop)."""
    loop = asyncio.new_event_loop()
    sim = LineUsSim(SimOptions(speed=float("inf")))
    server = loop.run_until_complete(serve_tcp(sim.serve, "127.0.0.1", 0))
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    try:
        yield server.sockets[0].getsockname()[1], sim, loop
    finally:

        async def shut() -> None:
            server.close()
            await sim.close()

        asyncio.run_coroutine_threadsafe(shut(), loop).result(5)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(5)
        loop.close()


async def _drive(port: int, lookahead: bool) -> float:
    """fabwire's client: MOVES G01 moves, one in flight or with look-ahead; moves/s."""
    arm = await LineUs.connect(await open_tcp("127.0.0.1", port), lookahead=lookahead)
    try:
        targets = _targets(MOVES)
        start = time.perf_counter()
        if lookahead:
            await arm.run(p.Move(x, y, 0) for x, y in targets)
        else:
            for x, y in targets:
                await arm.move(x, y, 0)
        return MOVES / (time.perf_counter() - start)
    finally:
        await arm.close()


def _threaded_rate() -> float:
    """One in flight against a simulator on its own thread, the setup the official module is measured in."""
    with _simulator_thread() as (port, sim, loop):
        rate = asyncio.run(_drive(port, lookahead=False))
        asyncio.run_coroutine_threadsafe(asyncio.wait_for(sim.wait_idle(), 5), loop).result(6)
        assert len(sim.arm.moves) >= MOVES
    return rate


async def _client_rate(lookahead: bool) -> float:
    """Client and simulator on one event loop, so each move costs the client's work plus the simulator's."""
    sim = LineUsSim(SimOptions(speed=float("inf")))
    server = await serve_tcp(sim.serve, "127.0.0.1", 0)
    try:
        rate = await _drive(server.sockets[0].getsockname()[1], lookahead)
        assert len(sim.arm.moves) >= MOVES
        async with asyncio.timeout(5):
            await sim.wait_idle()
        return rate
    finally:
        server.close()
        await server.wait_closed()
        await sim.close()


def _official_rate() -> float | None:
    """The official `lineus` module (one recv per byte) against the same simulator, for comparison."""
    try:
        import lineus
    except ImportError:
        return None
    with _simulator_thread() as (port, _, _):
        arm = lineus.LineUs()
        arm._default_port = port
        if not arm.connect("127.0.0.1"):
            return None
        start = time.perf_counter()
        for x, y in _targets(OFFICIAL_MOVES):
            arm.g01(x, y, 0)
        elapsed = time.perf_counter() - start
        arm.disconnect()
        arm.zeroconf.close()
        return OFFICIAL_MOVES / elapsed


def _gcode_rate() -> float:
    lines = ["G54 X0 Y0 S1"]
    lines += [f"G01 X{1000 + i % 400} Y{-200 + (i % 300) * 0.5:.2f} Z{0 if i % 50 else 1000}"
              for i in range(GCODE_LINES)]
    text = "\n".join(lines)
    start = time.perf_counter()
    traced = trace_text(text)
    elapsed = time.perf_counter() - start
    assert traced.ink.strokes
    return GCODE_LINES / elapsed


def run() -> list[Figure]:
    officials: list[float] = []
    serials: list[float] = []
    threaded: list[float] = []
    for _ in range(TRIALS):  # interleaved, so load that comes and goes weighs on every setup alike
        if (rate := _official_rate()) is not None:
            officials.append(rate)
        serials.append(asyncio.run(_client_rate(lookahead=False)))
        threaded.append(_threaded_rate())
    official, serial, apart = max(officials, default=None), max(serials), max(threaded)
    pipelined = max(asyncio.run(_client_rate(lookahead=True)) for _ in range(TRIALS))
    gcode = max(_gcode_rate() for _ in range(3))
    target = f"> {TARGET:,.0f}"
    return [
        Figure(f"lineus G01 round trips, one in flight (loopback TCP, speed inf, best of {TRIALS})", serial,
               "moves/s", target, serial > TARGET, official, "official lineus module"),
        Figure(f"lineus G01 round trips, one in flight, simulator on its own thread as for the official module "
               f"(best of {TRIALS})", apart, "moves/s", "", None, official, "official lineus module"),
        # Look-ahead hides Wi-Fi latency on a real robot; with both ends on one event loop there is none to hide,
        # so this figure is for comparison only.
        Figure(f"lineus G01 moves, look-ahead window 3 (best of {TRIALS})", pipelined, "moves/s", "", None,
               serial, "one in flight"),
        Figure(f"lineus G-code file read through the interpreter ({GCODE_LINES:,} lines, best of 3)", gcode,
               "lines/s", f"> {GCODE_TARGET:,.0f}", gcode > GCODE_TARGET),
    ]


if __name__ == "__main__":
    for figure in run():
        extra = f" (baseline {figure.baseline:,.0f} {figure.baseline_name})" if figure.baseline else ""
        print(f"{figure.name}: {figure.value:,.0f} {figure.unit}  target {figure.target}{extra}")
