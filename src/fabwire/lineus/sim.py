"""A Line-us the official clients cannot tell from the robot.

One `LineUsSim` is one machine: an arm with a single motion queue (depth 1 behind the executing move) shared by
every connection, stored drawings, name and Wi-Fi lists. Each connection keeps its own G54 transform and M28
recording. Moves take the time `kinematics.MotionModel` gives them (divided by the speed factor), and by default
a move's reply is held until the move has finished, as the firmware does.

Like the robot, which takes a command off the socket only when its motion queue has room, a connection's commands
are taken a small window at a time and each connection may owe only a few replies. A client that goes away takes
the rest of what it sent with it: the move under way and the one queued behind it finish, and nothing else it sent
delays the next client (Line-us-Programming README, "Timing": at most one outstanding command).
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import dataclasses
import logging
import math
import time
from collections.abc import Coroutine
from pathlib import Path
from typing import Any, TypeVar

from fabwire.errors import LinkClosed, RemoteProtocolError
from fabwire.lineus import kinematics as kin
from fabwire.lineus import protocol as p
from fabwire.lineus.arm import Arm, Clock, Job
from fabwire.lineus.interpreter import HOME3, Ink, Interpreter, Motion, Point3, read_program
from fabwire.lineus.personality import DEFAULT_NAME, DEFAULT_SERIAL
from fabwire.lineus.personality import VERSIONS as VERSIONS
from fabwire.lineus.personality import SimOptions as SimOptions
from fabwire.lineus.personality import resolve_version as resolve_version
from fabwire.lineus.sim_handlers import FS_TOTAL, HANDLERS, ReplySource, Session, error_reply
from fabwire.transport import Transport, register_simulator, spawn_in_process

log = logging.getLogger("fabwire.lineus.sim")

DEFAULT_ZMAP = (0.0, 100.0, 300.0, 200.0)
SYSTEM_FILES = (("/cal", 29), ("/key", 344))
SAVE_BLOCKED = ("M30", "M171", "M374", "M997")
"""Codes the firmware refuses while an M28 recording is open."""

HISTORY = 10_000
"""Recent messages kept for instrumentation: bounded and small, so a long-running simulator reaches its size within
minutes (100,000 took hours of hostile traffic to fill, growing all the while)."""
INK_POINTS = 100_000
"""Points of ink kept for --record: a page of drawing."""
INPUT_WINDOW = p.MAX_LINE
"""Bytes taken off a connection at a time. The robot reads a command only when its motion queue can take it, and
what a client sent beyond that is lost when it disconnects; reading a small window keeps the simulator the same."""
REPLIES_OWED = 16
"""Replies a connection may owe before the simulator stops taking its commands (a client that does not read its
replies stops being served, not the machine)."""

T = TypeVar("T")


def sample_drawing() -> str:
    """The drawing a factory machine carries in slot 1: a small square with a diagonal."""
    points = [(1100, -200), (1500, -200), (1500, 200), (1100, 200), (1100, -200), (1500, 200)]
    lines = ["G54 X0 Y0 S1", f"G01 X{points[0][0]} Y{points[0][1]} Z1000"]
    lines += [f"G01 X{x} Y{y} Z0" for x, y in points]
    lines.append("G01 Z1000")
    return "".join(line + "\n" for line in lines)


class RateLimitedLog:
    """At most `burst` lines per `window` seconds; what was held back is counted in the next line that goes out, so
    a storm of misbehaving clients costs a few lines, not one each (and never blocks on a full stderr pipe)."""

    def __init__(self, logger: logging.Logger, *, burst: int = 5, window: float = 10.0,
                 level: int = logging.INFO) -> None:
        self._log, self._burst, self._window, self._level = logger, burst, window, level
        self._start = -math.inf
        self._sent = 0
        self.suppressed = 0

    def note(self, message: str, now: float | None = None) -> bool:
        """Log `message` unless the budget is spent; True if it went out."""
        moment = time.monotonic() if now is None else now
        if moment - self._start >= self._window:
            self._start, self._sent = moment, 0
        if self._sent >= self._burst:
            self.suppressed += 1
            return False
        self._sent += 1
        if self.suppressed:
            message += f" ({self.suppressed} similar message(s) suppressed)"
            self.suppressed = 0
        self._log.log(self._level, "%s", message)
        return True


class LineUsSim:
    """The machine. `serve(transport)` runs one connection; call it once per client."""

    def __init__(self, options: SimOptions | None = None, *, files: dict[int, str] | None = None) -> None:
        self.options = options or SimOptions()
        self.name = self.options.name
        self.clock = Clock(self.options.speed)
        guards = self.options.guards_body
        self.arm = Arm(self.clock, kin.MotionModel(step_time=self.options.step_time, pen_time=self.options.pen_time),
                       Ink(lift_over_notch=guards, detect_collisions=not guards, keep=INK_POINTS))
        self.files: dict[int, str] = {1: sample_drawing()} if files is None else dict(files)
        self.known_wifi: dict[str, str] = {"fabwire-lab": "lab-password"}
        self.visible_wifi: list[str] = ["fabwire-lab", "neighbours-wifi"]
        self.zmap = DEFAULT_ZMAP
        self.gestures = True
        self.memory_mode = 0
        self.demo: tuple[float, float, int | None] | None = None
        """M85: (seconds, period, drawing): every `period` s, draw the first `seconds` s of a stored drawing."""
        self.last_saved = 1
        self._demo_task: asyncio.Task[None] | None = None
        self.startup = (1, 1)
        self.servo_reverse = [0, 0, 1]
        self.calibration = (10.79735, -1.902405, 9.900639)
        self.connections = 0
        self._idle = asyncio.Event()
        self._idle.set()
        self.sent: collections.deque[tuple[float, bytes]] = collections.deque(maxlen=HISTORY)
        """Every message written, with the model time it went out (for tests and instrumentation)."""
        self.received: collections.deque[str] = collections.deque(maxlen=HISTORY)
        self._started = time.monotonic()
        self._peer_log = RateLimitedLog(log)
        self.decimals = self.options.decimals if self.options.decimals is not None else self.options.major >= 3
        self.lookahead = self.options.lookahead if self.options.lookahead is not None else self.options.major >= 3

    # -- connection -------------------------------------------------------------------------------------------------

    async def wait_idle(self) -> None:
        """Until no client is connected (a client's close reaches the simulator a little later)."""
        await self._idle.wait()

    def hello(self) -> p.Hello:
        return p.Hello(self.options.version, self.name, self.options.serial)

    def new_session(self) -> Session:
        return Session(Interpreter(x_min_lower=self.options.x_min_lower))

    async def serve(self, transport: Transport) -> None:
        """Run one connection until the client goes away; replies already owed are still sent. A client that
        goes away early (even before the hello) is a normal event: one rate-limited log line, no traceback."""
        try:
            await self._serve(transport)
        except (LinkClosed, ConnectionError) as exc:
            self._peer_log.note(f"lineus client {transport.peer} went away: {exc}")

    async def _serve(self, transport: Transport) -> None:
        first = self.connections == 0 and not self.arm.busy
        self.connections += 1
        self._idle.clear()
        session = self.new_session()
        queue: asyncio.Queue[tuple[ReplySource, asyncio.Future[None]] | None] = asyncio.Queue(REPLIES_OWED)
        writer = asyncio.create_task(self._write_replies(transport, queue, session), name="lineus-replies")
        reader = p.CommandReader()
        try:
            if first and self.arm.position != HOME3:
                # A fresh connection homes the arm (pen up) before the greeting, as the firmware does.
                job = await self.arm.submit("connect", HOME3, clamped=False, rapid=False)
                await job.done
            await self._send(transport, self.hello().encode())
            while not writer.done():
                try:
                    data = await transport.read(INPUT_WINDOW)
                except LinkClosed:
                    break
                if not await self._take(reader.feed(data), session, transport, queue, writer):
                    break
            if await self._unless_gone(queue.put(None), writer) is not None:
                with contextlib.suppress(LinkClosed):
                    await writer
        finally:
            self.connections -= 1
            if self.connections == 0:
                self._idle.set()
            if not writer.done():
                writer.cancel()
            with contextlib.suppress(asyncio.CancelledError, LinkClosed):
                await writer  # also collects a writer that ended when the client went away
            if session.saving is not None:
                self._close_file(session)
            log.debug("lineus client %s disconnected", transport.peer)

    async def _take(
        self, items: list[p.Line | p.BadLine], session: Session, transport: Transport,
        queue: asyncio.Queue[tuple[ReplySource, asyncio.Future[None]] | None], writer: asyncio.Task[None],
    ) -> bool:
        """Carry out one read's commands in order; False once the client has gone (the writer could not deliver a
        reply), so what it sent and the machine had not yet taken dies with the connection, as on the robot."""
        for item in items:
            if writer.done():
                return False
            action = self._dispatch(item, session) if isinstance(item, p.Line) else error_reply(item.reason)
            if not isinstance(action, Motion):
                source = action
            elif self.arm.has_room:
                source = await self._start_move(action)
            elif (started := await self._unless_gone(self._start_move(action), writer)) is not None:
                source = started.result()
            else:
                return False
            if session.backlog == 0 and (ready := self._ready(source)) is not None:
                await self._send(transport, ready)  # nothing owed before it: answer now
                continue
            session.backlog += 1
            written: asyncio.Future[None] = asyncio.get_running_loop().create_future()
            if not queue.full():
                queue.put_nowait((source, written))
            elif await self._unless_gone(queue.put((source, written)), writer) is None:
                return False
            if not self.lookahead:
                await asyncio.wait([written, writer], return_when=asyncio.FIRST_COMPLETED)
        return True

    @staticmethod
    async def _unless_gone(step: Coroutine[Any, Any, T], writer: asyncio.Task[None]) -> asyncio.Task[T] | None:
        """`step` run to its end (its task, finished), or None with `step` abandoned if the client goes away while it
        waits: a gone client's next move must not wait for the arm, nor its next reply for room to be owed."""
        task = asyncio.ensure_future(step)
        await asyncio.wait({task, writer}, return_when=asyncio.FIRST_COMPLETED)
        if task.done():
            return task
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        return None

    async def _send(self, transport: Transport, data: bytes) -> None:
        self.sent.append((self.clock.now(), data))
        await transport.write(data)

    def _ready(self, source: ReplySource) -> bytes | None:
        """The reply's bytes if it is due now, None if it waits for its move."""
        if isinstance(source, Job):
            if not source.done.done():
                return None
            x, y, z = source.done.result().end
            return p.encode_position(x, y, z, self.decimals)
        return (source if isinstance(source, p.Reply) else source()).encode()

    async def _write_replies(
        self, transport: Transport, queue: asyncio.Queue[tuple[ReplySource, asyncio.Future[None]] | None],
        session: Session,
    ) -> None:
        """Writes each reply whole, in command order, as soon as it is due."""
        while (entry := await queue.get()) is not None:
            source, written = entry
            if isinstance(source, Job):
                x, y, z = (await source.done).end
                data = p.encode_position(x, y, z, self.decimals)
            else:
                data = (source if isinstance(source, p.Reply) else source()).encode()
            await self._send(transport, data)
            session.backlog -= 1
            if not written.done():
                written.set_result(None)

    # -- commands -----------------------------------------------------------------------------------------------

    def _dispatch(self, line: p.Line, session: Session) -> ReplySource | Motion:
        self.received.append(line.text)
        if session.saving is not None:
            return self._record(line.text, session)
        try:
            command = p.parse_command(line.text)
        except RemoteProtocolError as exc:
            return error_reply(str(exc))
        if isinstance(command, p.Move | p.Home | p.RawMove):
            return self._motion(command, session, line.text)
        handler = HANDLERS.get(type(command))
        if handler is None:
            return error_reply(f"{command.text()} is not supported")
        try:
            return handler(self, command, session)
        except Exception as exc:  # a simulator bug must cost one reply, never the connection
            log.exception("lineus simulator failed on %r", line.text)
            return error_reply(f"internal error: {exc}")

    def _record(self, text: str, session: Session) -> p.Reply:
        code = text.split(maxsplit=1)[0].upper() if text.split() else ""
        if code in ("M29",):
            self._close_file(session)
            return p.Reply(True)
        if code in SAVE_BLOCKED:
            return error_reply(f"{code} is not allowed while saving a drawing")
        if code == "M28":
            return error_reply("already saving a drawing; send M29 first")
        size = len(text) + 1
        if self.fs_used(but=session.saving) + session.saved_bytes + size > FS_TOTAL:
            return error_reply(f"file system full: {FS_TOTAL} bytes of flash, line not stored")
        session.saved.append(text)
        session.saved_bytes += size
        return p.Reply(True)

    def _close_file(self, session: Session) -> None:
        assert session.saving is not None
        self.files[session.saving] = "".join(line + "\n" for line in session.saved)
        self.last_saved = session.saving
        session.saving, session.saved, session.saved_bytes = None, [], 0

    def position_reply(self, where: Point3) -> p.Reply:
        dec = self.decimals
        return p.Reply(True, tuple((axis, p.format_coordinate(v, dec)) for axis, v in zip("XYZ", where, strict=True)))

    def _motion(self, command: p.Move | p.Home | p.RawMove, session: Session, text: str) -> Motion:
        motion = session.interpreter.motion(command, self.arm.planned, text)
        if motion.clamped:
            log.info("lineus target of %r is outside the drawing area: moved to (%g, %g), pen lifted",
                     text, motion.target[0], motion.target[1])
        return motion

    async def _start_move(self, pending: Motion) -> ReplySource:
        job = await self.arm.submit(pending.command, pending.target, clamped=pending.clamped, rapid=pending.rapid)
        if self.options.reply == "accept":
            return self.position_reply(job.target)
        return job

    # -- state reports ---------------------------------------------------------------------------------------------

    def file_listing(self) -> str:
        return "".join(f"/{slot:07d}.txt-{len(text.encode())};" for slot, text in sorted(self.files.items()))

    def fs_used(self, *, but: int | None = None) -> int:
        """Flash bytes in use (leaving out drawing `but`, which an open M28 is rewriting)."""
        drawings = sum(len(t.encode()) for slot, t in self.files.items() if slot != but)
        return drawings + sum(size for _, size in SYSTEM_FILES)

    def diagnostics(self) -> p.Reply:
        used = self.fs_used()
        up = int(time.monotonic() - self._started)
        days, rest = divmod(up, 86400)
        hours, rest = divmod(rest, 3600)
        fs = self.file_listing() + "".join(f"{path}-{size};" for path, size in SYSTEM_FILES) + " "
        fields = (
            ("ChipID", self.options.serial), ("WifiMode", "1"), ("WifiModeSet", "0"),
            ("WifisConfigured", str(len(self.known_wifi))), ("MemDraw", "1" if self.memory_mode == 1 else "0"),
            ("Gestures", "1" if self.gestures else "0"), ("ContinuousDrawing", "0"),
            ("DrawingCount", str(len(self.files))), ("name", self.name), ("mac", "5C:3A:E8:18:0A:60"),
            ("FlashChipID", "0x1640ef"), ("FlashChipMode", "0"), ("FlashChipSpeed", "40000000"),
            ("FreeHeap", "25728"), ("ResetReason", "External System"),
            ("Uptime", f"{days}d{hours}h{rest // 60}m{rest % 60}s"),
            ("Time", time.strftime("%a %b %d %H:%M:%S %Y", time.gmtime())),
            ("FSUsed", str(used)), ("FSTotal", str(FS_TOTAL)), ("FSFree", str(FS_TOTAL - used)),
            ("FSPercent", str(used * 100 // FS_TOTAL)), ("FS", fs), ("Serial", "ikdBW+"),
            ("Cal", ",".join(str(v) for v in self.calibration)),
            ("ZMap", ";".join(p.format_number(v) for v in self.zmap)),
            ("ServoReverse", ",".join(str(v) for v in self.servo_reverse)),
        )
        return p.Reply(True, fields, quoted=frozenset({"FS"}))

    def wifi_list(self) -> p.Reply:
        pairs = [(ssid, "1" if ssid in self.known_wifi else "2") for ssid in self.visible_wifi]
        pairs += [(ssid, "3") for ssid in self.known_wifi if ssid not in self.visible_wifi]
        return p.Reply(True, tuple(pairs))

    def factory_reset(self, wipe_files: bool) -> None:
        self.name = self.options.name
        self.known_wifi.clear()
        self.zmap = DEFAULT_ZMAP
        self.gestures = True
        self.memory_mode = 0
        self.set_demo(None)
        self.arm.model = dataclasses.replace(self.arm.model, draw_step=5.0, travel_step=15.0)
        if wipe_files:
            self.files.clear()
            self.calibration = (0.0, 0.0, 0.0)

    def write_record(self, path: str | Path) -> Path:
        """Save what the arm drew (pen-down strokes, pen-up travel) as SVG or PNG."""
        from fabwire.lineus.render import write_drawing

        return write_drawing(path, self.arm.strokes, self.arm.travel, title=f"{self.name} (simulated)")

    def set_demo(self, demo: tuple[float, float, int | None] | None) -> None:
        self.demo = demo
        if self._demo_task is not None:
            self._demo_task.cancel()
            self._demo_task = None
        if demo is not None:
            self._demo_task = asyncio.create_task(self._run_demo(*demo), name="lineus-demo")

    async def _run_demo(self, seconds: float, period: float, slot: int | None) -> None:
        """The timed demo runs while nobody is connected, so it never moves the arm under a client."""
        while True:
            await self.clock.sleep(period)
            if self.connections or self.arm.busy:
                continue
            text = self.files.get(slot if slot is not None else self.last_saved)
            if text:
                await self.play(text, limit=seconds)

    async def play(self, text: str, *, limit: float = math.inf) -> float:
        """Run a stored drawing's moves (with its own G54) for up to `limit` model seconds, then lift the pen.

        Returns the modelled time spent; lines that are not moves or G54 are skipped, as the firmware's
        memory drawing only replays motion."""
        session = self.new_session()
        spent = 0.0
        for line in read_program(text, strict=False).lines:
            if spent >= limit:
                break
            command = line.command
            if isinstance(command, p.SetOrigin):
                session.interpreter.set_origin(command)
            elif isinstance(command, p.Move | p.Home | p.RawMove):
                move = self._motion(command, session, line.text)
                job = await self.arm.submit(move.command, move.target, clamped=move.clamped, rapid=move.rapid)
                record = await job.done
                spent += record.finished - record.started
        x, y, z = self.arm.position
        if z < kin.PEN_DOWN_BELOW:
            await (await self.arm.submit("M85 lift", (x, y, kin.Z_UP), clamped=False, rapid=False)).done
        return spent

    async def close(self) -> None:
        task = self._demo_task
        self.set_demo(None)
        if task is not None:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        await self.arm.close()


# -- in-process registration --------------------------------------------------------------------------------


def farewell(reason: str) -> bytes:
    """What the simulator sends a client its connection limit closes: an `error INFO:"reason"` reply, ended by
    `\r\n\0` like every message (Line-us-Programming README, "Responses"; the INFO key is how clients show an
    error's words, lineus.md 1.4), so a client waiting for a reply gets this one and shows why."""
    return error_reply(reason).encode()


def options_from(values: dict[str, str]) -> SimOptions:
    """`sim://lineus?speed=inf&version=1.0.1&name=bot&serial=42&reply=accept&step_time=0.01` options, read by the
    one table of simulator options (`fabwire.transport.simaddress.LINEUS_OPTIONS`)."""
    from fabwire.transport.simaddress import read_options

    given = read_options("lineus", values)
    return SimOptions(version=given.get("version", VERSIONS["3"]), name=given.get("name", DEFAULT_NAME),
                      serial=given.get("serial", DEFAULT_SERIAL), speed=given.get("speed", math.inf),
                      reply=given.get("reply", "complete"), step_time=given.get("step_time", 0.010))


async def _factory(values: dict[str, str]) -> Transport:
    sim = LineUsSim(options_from(values))
    return await spawn_in_process("lineus", sim.serve, sim.close)


register_simulator("lineus", _factory)
