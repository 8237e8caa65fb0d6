"""Talking to a Line-us: read the hello first, then one command in flight with its reply awaited.

The firmware holds a move's reply until the move is done, so every wait is sized to the move it covers
(`reply_timeout` plus the modelled move time). Firmware 3 can buffer a few commands; `lookahead=True` keeps
up to `window` in flight for smooth motion. Calibration, factory reset and firmware update need `confirm=True`.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import dataclasses
import logging
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Any, Self, TypeVar

from fabwire.config import LineUsSettings
from fabwire.devices import LINEUS
from fabwire.errors import DeviceError, FabwireError, InputError, LinkClosed, LinkTimeout, RemoteProtocolError, excerpt
from fabwire.lineus import kinematics as kin
from fabwire.lineus import protocol as p
from fabwire.lineus.interpreter import HOME3, Interpreter, Point3
from fabwire.opening import DeviceLink, DeviceTarget, Opening
from fabwire.transport import Transport
from fabwire.transport.limits import refusal
from fabwire.transport.peers import FirstBytes, name_peer, undecided, wrong_peer
from fabwire.units import json_key

if TYPE_CHECKING:
    from fabwire.lineus.sync import LineUsSync

T = TypeVar("T")
log = logging.getLogger("fabwire.lineus")

NOT_A_LINEUS = "a Line-us"
HELLO_TIMEOUT = 10.0
"""The hello can take a few seconds while the arm waves."""
REPLY_TIMEOUT = 5.0
_CLEAR = (kin.X_MIN_LOWER + 0.01, 0.01)
"""The body notch's corner with a hair's clearance, so rounding through G54 cannot put a point inside it."""
LOOKAHEAD_WINDOW = 3
MACHINE_UNITS = "machine_units"
"""The JSON key under which the firmware's own coordinates are kept as it reports them."""


@dataclass(frozen=True, slots=True)
class Position:
    x: float
    y: float
    z: float

    @property
    def pen_down(self) -> bool:
        return self.z < kin.PEN_DOWN_BELOW

    def as_dict(self) -> dict[str, Any]:
        """For JSON: `x_mm`, `y_mm` from the centre of the servo shafts (20 machine units a mm: Line-us README
        "Co-ordinate System", "100 units = 5mm"), `pen` "up" or "down", and under `machine_units` the firmware's own
        `x`, `y` (what `move` takes) and `z`, the pen height from 0 (down) to 1000 (up), which is no length."""
        return {json_key("x", "mm"): round(self.x / kin.UNITS_PER_MM, 3),
                json_key("y", "mm"): round(self.y / kin.UNITS_PER_MM, 3),
                "pen": "down" if self.pen_down else "up",
                MACHINE_UNITS: {"x": self.x, "y": self.y, "z": self.z}}

    def text(self) -> str:
        """For people: `X 1200  Y 0  Z 0  (pen down)`."""
        return f"X {self.x:g}  Y {self.y:g}  Z {self.z:g}  (pen {'down' if self.pen_down else 'up'})"

    @classmethod
    def from_reply(cls, reply: p.Reply) -> Position:
        """The X, Y, Z a motion or M114 reply carries. A reply without them does not show the arm went anywhere:
        RemoteProtocolError (a clear error, never a position made up by the client)."""
        fields = dict(reply.fields)
        try:
            return cls(float(fields["X"]), float(fields["Y"]), float(fields["Z"]))
        except (KeyError, ValueError):
            raise RemoteProtocolError(f"reply {excerpt(reply.text(), 40)} does not carry X, Y and Z") from None


@dataclass(frozen=True, slots=True)
class StoredDrawing:
    slot: int
    size: int
    path: str


@dataclass(frozen=True, slots=True)
class Network:
    ssid: str
    visible: bool
    known: bool


def parse_file_list(text: str) -> list[StoredDrawing]:
    """`/0000001.txt-9496;/0000002.txt-11323;` → drawings (system files such as /cal are left out)."""
    out = []
    for entry in filter(None, (part.strip() for part in text.split(";"))):
        path, sep, size = entry.rpartition("-")
        name = path.removeprefix("/").removesuffix(".txt")
        if not sep or not size.isdigit():
            raise RemoteProtocolError(f"file entry {excerpt(entry, 40)} is not /NNNNNNN.txt-SIZE")
        if name.isdigit() and path.endswith(".txt"):
            out.append(StoredDrawing(int(name), int(size), path))
    return out


def _greeting_error(said: bytes | bytearray, where: str, *, final: bool = False) -> FabwireError | None:
    """The error the first bytes of a greeting (`said`, as gathered so far) already show: another peer they name,
    or a start that can be neither a hello nor another peer's words; None while they may still be either (unless
    `final`: no more will come) or are the start of a hello."""
    if not said or said[:5] == b"hello"[: len(said[:5])]:
        return None
    if (wrong := refusal(said, where) or wrong_peer(said, NOT_A_LINEUS, LINEUS.name, where, final=final)):
        return wrong
    if not final and undecided(said, LINEUS.name):
        return None
    return RemoteProtocolError(f"{where} is not {NOT_A_LINEUS}: it greeted with {excerpt(bytes(said), 40)} instead of "
                               "'hello …'")


async def _silence_error(first: FirstBytes, url: str, where: str) -> FabwireError | None:
    """Why no hello came before the wait ended or the peer closed the link: what its first bytes show, or, when it
    said nothing, what its answer to a probe names; None when nothing does."""
    if first:
        return _greeting_error(first.data, where, final=True)
    return await name_peer(first.data, url, NOT_A_LINEUS, LINEUS.name, where)


class LineUs:
    """An open connection to one Line-us (or its simulator)."""

    def __init__(self, transport: Transport, hello: p.Hello, reader: p.ReplyReader, *, lookahead: bool,
                 window: int = LOOKAHEAD_WINDOW, reply_timeout: float = REPLY_TIMEOUT) -> None:
        self.transport = transport
        self.hello = hello
        self.lookahead = lookahead
        self.reply_timeout = reply_timeout
        self.model = kin.MotionModel()
        self._reader = reader
        self._window = window if lookahead else 1
        self._slots = asyncio.Semaphore(self._window)
        self._waiting: collections.deque[tuple[str, asyncio.Future[p.Reply]]] = collections.deque()
        self.guard_body = hello.firmware_major <= 1
        """Firmware 1.x lets the arm into the body notch (x < 700 below y = 0, README "CAUTION"): keep out of it
        here, clamping targets and routing moves round the notch's corner with the pen lifted."""
        self._interpreter = Interpreter(x_min_lower=kin.X_MIN_LOWER_FW1 if self.guard_body else kin.X_MIN_LOWER)
        """This connection's G54 and the machine's area rule, so targets (and the wait for them) are known in
        machine units as the firmware will see them."""
        self._aim: Point3 = HOME3
        """Where the last motion command sent will leave the arm."""
        self._spans: dict[asyncio.Future[p.Reply], float] = {}
        """Per move in flight: its longest axis travel in machine units (what its reply wait is sized by)."""
        self.notices: list[str] = []
        """What the client changed on the way (clamped targets, detours), for the caller to show."""
        self._failure: BaseException | None = None
        self._deadlines: dict[asyncio.Task[Any], float] = {}
        """Per task waiting for a reply: the loop time its wait runs out."""
        self._expired: set[asyncio.Task[Any]] = set()
        self._watchdog: asyncio.TimerHandle | None = None
        """One timer for every wait: it fires at the earliest deadline it knows of, cancels the waits past theirs and
        sets itself for the rest, so a reply that comes in time costs no timer of its own."""
        self._read_task = asyncio.create_task(self._read_loop(), name="lineus-replies") if lookahead else None
        """With one command in flight the waiting caller reads its own reply (no task hop per command)."""

    # -- connecting -----------------------------------------------------------------------------------------------

    @classmethod
    async def connect(cls, transport: Transport, *, lookahead: bool = False, hello_timeout: float = HELLO_TIMEOUT,
                      reply_timeout: float = REPLY_TIMEOUT, window: int = LOOKAHEAD_WINDOW) -> LineUs:
        """Read the hello (firmware 1 needs it read before anything is sent), then return the connection."""
        reader = p.ReplyReader(max_size=4096)
        where = transport.peer or transport.url
        first = FirstBytes()
        try:
            async with asyncio.timeout(hello_timeout):
                while True:
                    data = await transport.read()
                    first.feed(data)
                    reader.feed(data)
                    if (wrong := _greeting_error(first.data, where)) is not None:
                        raise wrong
                    message = reader.next_message()
                    if message is None:
                        continue
                    if not isinstance(message, p.Hello):
                        raise RemoteProtocolError(
                            f"{where} is not a Line-us: first message {excerpt(message.text(), 40)}")
                    break
        except TimeoutError:
            await transport.close()
            if (wrong := await _silence_error(first, transport.url, where)) is not None:
                raise wrong from None
            raise LinkTimeout(
                f"no hello from {where} within {hello_timeout:g} s: either not a Line-us, or a wedged one "
                "(accepts TCP but sends no greeting: power-cycle it)") from None
        except LinkClosed:
            await transport.close()
            if (wrong := await _silence_error(first, transport.url, where)) is not None:
                raise wrong from None
            raise LinkClosed(f"{where} closed the connection before greeting: not a Line-us?") from None
        except BaseException:
            await transport.close()
            raise
        # Firmware before 3.0 cannot buffer a second command: look-ahead is only used where it is safe.
        lookahead = lookahead and message.firmware_major >= 3
        return cls(transport, message, reader, lookahead=lookahead, window=window, reply_timeout=reply_timeout)

    @classmethod
    def open(cls, target: DeviceTarget = None, **options: Any) -> Opening[LineUs]:
        """`async with LineUs.open("line-us.local") as arm` (or `await` it): the one way to open a Line-us.

        `target` and the common options are described in `fabwire.opening`; the arm's settings are
        `fabwire.config.LineUsSettings` (lookahead, hello_timeout, reply_timeout). A `name.local` address is
        looked up by mDNS, with the port the machine advertises (`fabwire.lineus.link`).
        """
        return _LocalNameOpening(LINEUS, target, options, cls._on_link)

    @classmethod
    def open_sync(cls, target: DeviceTarget = None, **options: Any) -> LineUsSync:
        """`with LineUs.open_sync("line-us.local") as arm: arm.move(1000, 0)` for plain scripts."""
        from fabwire.lineus.sync import LineUsSync

        return LineUsSync(target, **options)

    @classmethod
    async def _on_link(cls, transport: Transport, opened: DeviceLink) -> LineUs:
        settings = opened.settings
        assert isinstance(settings, LineUsSettings)
        return await cls.connect(transport, lookahead=settings.lookahead, reply_timeout=settings.reply_timeout,
                                 hello_timeout=settings.hello_timeout or max(settings.timeout, 2.0))

    async def close(self) -> None:
        await self.detach()
        await self.transport.close()

    async def detach(self) -> None:
        """Stop using the transport but leave it open (for a caller that owns and closes it)."""
        if self._read_task is not None:
            self._read_task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._read_task
        if self._watchdog is not None:
            self._watchdog.cancel()
            self._watchdog = None
        self._fail(LinkClosed("the connection to the Line-us is closed"))

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                        tb: TracebackType | None) -> None:
        await self.close()

    # -- the one exchange -------------------------------------------------------------------------------------------

    async def _read_loop(self) -> None:
        while self._failure is None:
            await self._pump()

    async def _pump(self) -> None:
        """Read once and hand each complete reply to the command waiting for it; a failure ends the link."""
        try:
            data = await self.transport.read()
            self._reader.feed(data)
            while (message := self._reader.next_message()) is not None:
                if isinstance(message, p.Reply) and not message.ok and (
                        gone := refusal(message.info.encode(), self.transport.peer or self.transport.url)):
                    self._fail(gone)  # the simulator's connection limit closed us: its reason, not a reply's
                    return
                if not self._waiting:
                    raise RemoteProtocolError(f"unexpected message from the Line-us: {excerpt(message.text(), 40)}")
                _, future = self._waiting.popleft()
                if not future.done():
                    if isinstance(message, p.Hello):
                        future.set_exception(RemoteProtocolError("a second hello arrived instead of a reply"))
                    else:
                        future.set_result(message)
        except LinkClosed:
            pending = [text for text, _ in self._waiting]
            if pending:
                self._fail(LinkClosed(
                    f"the Line-us closed the connection with {len(pending)} command(s) unanswered "
                    f"(first: {pending[0]!r})"))
            else:
                self._fail(LinkClosed("the Line-us closed the connection"))
        except RemoteProtocolError as exc:
            self._fail(exc)

    def _settled(self, future: asyncio.Future[p.Reply]) -> None:
        """Free the command's slot and mark its exception retrieved: a reply nobody waits for any more (after a
        timeout or an interrupt) must not end the program with "Future exception was never retrieved"."""
        self._slots.release()
        self._spans.pop(future, None)
        if not future.cancelled():
            future.exception()

    def _fail(self, exc: BaseException) -> None:
        if self._failure is None:
            self._failure = exc
        while self._waiting:
            _, future = self._waiting.popleft()
            if not future.done():
                future.set_exception(exc)

    async def send(self, command: p.Command, *, timeout: float | None = None) -> p.Reply:
        """Send one command and wait for its reply (ok or error: the reply is returned either way).

        On firmware 1.x a move into (or through) the body notch is changed first: see `guard_body`."""
        *before, command = self._guarded(command)
        for step in before:
            await self.request(step)
        future = await self._submit(command)
        return await self._await_reply(command, future, timeout)

    async def request(self, command: p.Command, *, timeout: float | None = None) -> p.Reply:
        """Like `send`, but an `error` reply raises DeviceError with the device's INFO text."""
        return _checked(command, await self.send(command, timeout=timeout))

    async def _submit(self, command: p.Command) -> asyncio.Future[p.Reply]:
        if self._failure is not None:
            raise self._failure
        await self._slots.acquire()
        future: asyncio.Future[p.Reply] = asyncio.get_running_loop().create_future()
        future.add_done_callback(self._settled)
        text = command.text()
        self._waiting.append((text, future))
        if isinstance(command, p.SetOrigin):
            self._interpreter.set_origin(command)
        elif isinstance(command, p.Move | p.Home | p.RawMove):
            self._spans[future], self._aim = self._span(command)
        try:
            await self.transport.write(text.encode("ascii") + p.COMMAND_TERMINATOR)
        except LinkClosed as exc:
            self._fail(LinkClosed(f"lost the Line-us while sending {text!r}: {exc}"))
        return future

    async def _await_reply(self, command: p.Command, future: asyncio.Future[p.Reply], timeout: float | None) -> p.Reply:
        """The reply `future` will hold, within `timeout` (default: sized to the move); LinkTimeout ends the link.
        Like `asyncio.timeout`, a wait that runs out cancels the waiting task and turns that cancellation (and only
        that one) into the timeout, but through one shared timer (`_watchdog`) instead of one per command."""
        limit = timeout if timeout is not None else self._timeout_for(self._spans.get(future))
        task = asyncio.current_task()
        if task is None:
            raise RuntimeError("a Line-us connection is used from asyncio tasks")
        loop = asyncio.get_running_loop()
        cancelling = task.cancelling()
        deadline = self._deadlines[task] = loop.time() + limit
        if self._watchdog is None or self._watchdog.when() > deadline:
            if self._watchdog is not None:
                self._watchdog.cancel()
            self._watchdog = loop.call_at(deadline, self._watch)
        try:
            if self._read_task is None:
                while not future.done():
                    await self._pump()
            return future.result() if future.done() else await asyncio.shield(future)
        except asyncio.CancelledError:
            if task in self._expired and task.uncancel() <= cancelling:
                exc = LinkTimeout(f"no reply to {command.text()!r} within {limit:.1f} s: the Line-us may be wedged")
                self._fail(exc)
                raise exc from None
            raise
        finally:
            del self._deadlines[task]
            self._expired.discard(task)

    def _watch(self) -> None:
        """The shared reply timer: cancel each wait past its deadline, then set the timer for the next one."""
        self._watchdog = None
        loop = asyncio.get_running_loop()
        now = loop.time()
        for task, deadline in self._deadlines.items():
            if deadline <= now and task not in self._expired:
                self._expired.add(task)
                task.cancel()
        later = [deadline for task, deadline in self._deadlines.items() if task not in self._expired]
        if later:
            self._watchdog = loop.call_at(min(later), self._watch)

    def _span(self, command: p.Move | p.Home | p.RawMove) -> tuple[float, Point3]:
        """How far (longest axis, machine units) the move goes from where the moves sent so far leave the arm,
        and where it ends."""
        end = self._interpreter.motion(command, self._aim).target
        return max(abs(end[0] - self._aim[0]), abs(end[1] - self._aim[1])), end

    def _timeout_for(self, span: float | None) -> float:
        """Room for a move spanning `span` units (and the one ahead of it with look-ahead) on top of the link's
        slack; None for a command that does not move."""
        if span is None:
            return self.reply_timeout
        # Bound the move by the smallest step the firmware allows (1 unit), in case G94 was set elsewhere,
        # and double it: the step period is modelled, not measured. With look-ahead the move ahead counts too.
        worst = math.ceil(span) * self.model.step_time + 2 * self.model.pen_time
        return self.reply_timeout + (2 if self.lookahead else 1) * 2 * worst

    async def run(self, commands: Iterable[p.Command]) -> list[p.Reply]:
        """Send many commands, keeping as many in flight as the mode allows; the first `error` raises."""
        futures: list[tuple[p.Command, asyncio.Future[p.Reply]]] = []
        replies = []
        window = self._window
        try:
            for command in (step for given in commands for step in self._guarded(given)):
                futures.append((command, await self._submit(command)))
                while futures and (futures[0][1].done() or len(futures) >= window):
                    done_cmd, done_future = futures.pop(0)
                    replies.append(_checked(done_cmd, await self._await_reply(done_cmd, done_future, None)))
            for done_cmd, done_future in futures:
                replies.append(_checked(done_cmd, await self._await_reply(done_cmd, done_future, None)))
        finally:
            for _, future in futures:
                if not future.done():
                    future.cancel()
        return replies

    def _guarded(self, command: p.Command) -> list[p.Command]:
        """The commands to send for `command`: itself, or on firmware 1.x (which lets the pen screw hit the body
        in the notch x < 700 below y = 0) a target clamped out of the notch with the pen lifted, and a move that
        would cross the notch split at its corner (700, 0) with the pen lifted over it."""
        if not self.guard_body or not isinstance(command, p.Move | p.RawMove):
            return [command]
        scaled = isinstance(command, p.Move)
        aim = self._aim
        target = self._interpreter.motion(command, aim).target
        out: list[p.Command] = []
        x, y, z = target
        if kin.in_body_zone(x, y):
            safe = kin.clamp_target(x, y)
            self._notice(f"({x:g}, {y:g}) is in the body notch that firmware {self.hello.firmware_label} does "
                         f"not keep out of: moved to ({safe.x:g}, {safe.y:g}) with the pen lifted")
            x, y, z = max(safe.x, _CLEAR[0]) if safe.y < 0 else safe.x, safe.y, kin.Z_UP
            command = self._move_to(x, y, z, scaled, command)
        if kin.crosses_body_zone((aim[0], aim[1]), (x, y)):
            corner = _CLEAR
            self._notice(f"the move from ({aim[0]:g}, {aim[1]:g}) to ({x:g}, {y:g}) would cross the body notch: "
                         f"going round by {corner} with the pen lifted")
            if aim[2] < kin.PEN_DOWN_BELOW:
                out.append(p.Move(z=kin.Z_UP))
            out.append(self._move_to(*corner, kin.Z_UP, scaled, command))
            command = self._move_to(x, y, z, scaled, command)  # the pen as asked at the end (a drop lands there)
        out.append(command)
        return out

    def _move_to(self, x: float, y: float, z: float, scaled: bool, like: p.Command) -> p.Command:
        """A move to machine point (x, y, z) in the frame `like` uses (through this connection's G54 or not)."""
        if not scaled:
            return p.RawMove(x, y, z, like.keep if isinstance(like, p.RawMove) else None)
        ox, oy, scale = self._interpreter.origin
        if scale == 0:
            raise InputError("cannot keep the arm out of the body notch while G54 scale is 0")
        rapid = isinstance(like, p.Move) and like.rapid
        return p.Move(round((x - ox) / scale, 6), round((y - oy) / scale, 6), z, rapid=rapid)

    def _notice(self, text: str) -> None:
        self.notices.append(text)
        log.info("%s", text)

    # -- motion ---------------------------------------------------------------------------------------------------

    def _position(self, reply: p.Reply) -> Position:
        return Position.from_reply(reply)

    async def move(self, x: float | None = None, y: float | None = None, z: float | None = None) -> Position:
        """G01 to (x, y, z); omitted axes stay. Returns where the arm reports it ended (clamped if outside)."""
        return self._position(await self.request(p.Move(x, y, z)))

    async def rapid(self, x: float | None = None, y: float | None = None, z: float | None = None) -> Position:
        """G00: every servo at full speed; the path is a curve and may clip the body."""
        return self._position(await self.request(p.Move(x, y, z, rapid=True)))

    async def move_uncalibrated(self, x: float | None = None, y: float | None = None, z: float | None = None,
                                keep: str | None = None) -> Position:
        """G40: ignore G54 and calibration (`keep` = "xy" or "z" re-applies that part)."""
        if keep not in (None, "xy", "z"):
            raise InputError("keep is 'xy' or 'z'")
        return self._position(await self.request(p.RawMove(x, y, z, keep)))  # type: ignore[arg-type]

    async def pen_up(self) -> Position:
        return await self.move(z=kin.Z_UP)

    async def pen_down(self, z: float = kin.Z_DOWN) -> Position:
        return await self.move(z=z)

    async def lift_after_stop(self) -> Position:
        """After an interrupt (Ctrl-C, a cancelled job): wait for the replies the Line-us still owes (a move it
        has taken cannot be called back), then lift the pen, so the last thing the connection sends is a pen-up.
        LinkError or LinkTimeout when the link is gone or the owed replies do not come."""
        waits = [self._timeout_for(self._spans.get(future)) for _, future in self._waiting if not future.done()]
        if waits:
            try:
                async with asyncio.timeout(sum(waits)):
                    while self._failure is None and any(not future.done() for _, future in self._waiting):
                        if self._read_task is None:
                            await self._pump()
                        else:
                            await asyncio.wait([future for _, future in self._waiting])
            except TimeoutError:
                self._fail(LinkTimeout("the Line-us did not finish its last move: the pen may still be down"))
        return await self.pen_up()

    async def home(self) -> Position:
        return self._position(await self.request(p.Home()))

    async def position(self) -> Position:
        return self._position(await self.request(p.GetPosition()))

    async def servo_angles(self) -> dict[str, float]:
        reply = await self.request(p.GetPosition(servos=True))
        try:
            return {key: float(value) for key, value in reply.fields}
        except ValueError:
            raise RemoteProtocolError(f"servo angles {excerpt(reply.text(), 40)} are not numbers") from None

    async def set_origin(self, x: float = 0.0, y: float = 0.0, scale: float = 1.0) -> None:
        """G54 for this connection: machine = drawing × scale + (x, y)."""
        await self.request(p.SetOrigin(x, y, scale))

    async def set_speed(self, draw: float | None = None, travel: float | None = None) -> None:
        """G94: the largest interpolation step while drawing (S) and travelling (P); smaller is slower."""
        await self.request(p.SetSpeed(draw, travel))
        self.model = dataclasses.replace(
            self.model, draw_step=draw if draw is not None else self.model.draw_step,
            travel_step=travel if travel is not None else self.model.travel_step)

    # -- machine information ----------------------------------------------------------------------------------------

    async def capabilities(self) -> dict[str, str]:
        return (await self.request(p.Capabilities())).as_dict()

    async def diagnostics(self) -> dict[str, str]:
        return (await self.request(p.Diagnostics())).as_dict()

    async def name(self) -> str:
        reply = await self.request(p.MachineName())
        return reply.get("MACHINENAME") or ""

    async def set_name(self, name: str) -> None:
        """M550: takes effect for mDNS (<name>.local) and the next hello."""
        await self.request(p.MachineName(name))

    async def storage(self) -> dict[str, int]:
        reply = await self.request(p.StorageUsage())
        try:
            return {key: int(value) for key, value in reply.fields}
        except ValueError:
            raise RemoteProtocolError(f"storage figures {excerpt(reply.text(), 40)} are not numbers") from None

    async def zmap(self) -> tuple[float, ...]:
        reply = await self.request(p.ZMap())
        try:
            return tuple(float(v) for v in (reply.get("ZMap") or "").split(";") if v.strip())
        except ValueError:
            raise RemoteProtocolError(f"Z map {excerpt(reply.text(), 40)} is not four numbers") from None

    async def set_zmap(self, corners: tuple[float, float, float, float] | None) -> None:
        """G31 with four corner offsets (TL, TR, BR, BL), or None to clear the map."""
        await self.request(p.ZMap(corners) if corners is not None else p.ZMap(clear=True))

    async def gestures(self, on: bool) -> None:
        await self.request(p.Gestures(on))

    # -- Wi-Fi ------------------------------------------------------------------------------------------------------

    async def wifi_networks(self) -> list[Network]:
        """M587: K=1 visible with a known password, 2 visible, 3 known but not in range."""
        reply = await self.request(p.Wifi())
        out = []
        for ssid, kind in reply.fields:
            if kind not in ("1", "2", "3"):
                raise RemoteProtocolError(f"Wi-Fi entry {ssid}:{kind} has an unknown state")
            out.append(Network(ssid, visible=kind in ("1", "2"), known=kind in ("1", "3")))
        return out

    async def add_wifi(self, ssid: str, password: str | None = None) -> None:
        """M587 S P: store a network (in setup mode the machine then leaves to join it)."""
        await self.request(p.Wifi(ssid, password))

    async def forget_wifi(self, ssid: str = "*") -> None:
        await self.request(p.ForgetWifi(ssid))

    # -- stored drawings ------------------------------------------------------------------------------------------

    async def list_drawings(self) -> list[StoredDrawing]:
        reply = await self.request(p.ListFiles())
        return parse_file_list(reply.get("FS") or "")

    async def save_drawing(self, slot: int, gcode: Sequence[str]) -> int:
        """Store G-code lines as drawing `slot` (M28 … M29); returns the lines stored."""
        lines = [line.strip() for line in gcode if line.strip()]
        for line in lines:
            if any(ch in line for ch in "\r\n\x00") or not line.isascii() or len(line) >= p.MAX_LINE:
                raise InputError(f"line {excerpt(line, 40)} cannot be stored: ASCII text under {p.MAX_LINE} characters")
        await self.request(p.StartSave(slot))
        try:
            for line in lines:
                reply = await self.send(_RawLine(line))
                if not reply.ok:
                    raise DeviceError("", f"the Line-us refused to store {line!r}" + _why(reply))
        finally:
            if self._failure is None:
                await self.request(p.EndSave())
        return len(lines)

    async def delete_drawing(self, slot: int) -> None:
        await self.request(p.DeleteFile(slot))

    async def memory_drawing(self, mode: int, channel: str | None = None) -> None:
        """M23: 0 default, 1 draw from memory (Blue mode button), 2 follow, 3 unfollow."""
        await self.request(p.MemoryDrawing(mode, channel))

    async def timed_demo(self, seconds: float, period: float, drawing: int | None = None) -> None:
        """M85: every `period` s draw the first `seconds` s of the last (or the given) stored drawing."""
        await self.request(p.TimedDemo(seconds, period, drawing))

    # -- guarded ----------------------------------------------------------------------------------------------------

    async def calibrate(self, *, clear: bool = False, confirm: bool = False) -> None:
        """M374: store the arm's current point as the XY calibration point (or clear it)."""
        _guard(confirm, "calibration overwrites the stored XY calibration")
        await self.request(p.SaveCalibration(clear))

    async def factory_reset(self, *, wipe_files: bool = False, confirm: bool = False) -> None:
        what = "a factory reset forgets the name and Wi-Fi networks" + (" and wipes drawings" if wipe_files else "")
        _guard(confirm, what)
        await self.request(p.FactoryReset(wipe_files))

    async def firmware_update(self, *, confirm: bool = False) -> None:
        _guard(confirm, "a firmware update downloads new firmware and restarts the machine")
        await self.request(p.FirmwareUpdate(), timeout=120.0)


class _LocalNameOpening(Opening[LineUs]):
    """`LineUs.open` for an address, a configured name or the default device: a `.local` host is resolved by mDNS
    before the link opens, so hosts without a system mDNS resolver reach the machine too."""

    async def open(self) -> LineUs:
        from fabwire.lineus.link import resolve_local

        if self._target is None or isinstance(self._target, str):
            self._target, self._options = await resolve_local(self._target, self._options)
        return await super().open()


@dataclass(frozen=True, slots=True)
class _RawLine(p.Command):
    """A stored-drawing line, sent verbatim (the device records it instead of running it)."""

    line: str = ""

    def text(self) -> str:
        return self.line


def _guard(confirm: bool, what: str) -> None:
    if not confirm:
        raise InputError(f"{what}; pass confirm=True (--yes) to go ahead")


def _checked(command: p.Command, reply: p.Reply) -> p.Reply:
    if not reply.ok:
        raise DeviceError("", f"the Line-us refused {command.text()!r}" + _why(reply))
    return reply


def _why(reply: p.Reply) -> str:
    """The reason a refusal gives, if any (firmware 3.x words it, 1.x answers a bare `error`)."""
    return f": {reply.info}" if reply.info else ""
