"""`MMU`: the host logic on a real link, as awaitable operations (`fabwire.mmu.sync.SyncMMU` for plain scripts).

    async with MMU(transport) as mmu:
        await mmu.tool_change(1, on_event=print)
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Callable, Iterable
from types import TracebackType
from typing import TYPE_CHECKING, Any, Self, TypeVar

from fabwire.config import MMUSettings
from fabwire.devices import MMU as MMU_KIND
from fabwire.errors import (
    DeviceBusy,
    DeviceError,
    InputError,
    LinkClosed,
    LinkError,
    LinkTimeout,
    RemoteProtocolError,
    closest,
    excerpt,
)
from fabwire.mmu import codes, units
from fabwire.mmu.errors import MMUError, describe_error, reset_line
from fabwire.mmu.evidence import end_state
from fabwire.mmu.host import (
    INIT_REGISTERS,
    SUPPORTED,
    ButtonSent,
    CommandFinished,
    CommandInterrupted,
    CommandRejected,
    ErrorRaised,
    FSensorMode,
    HostEvent,
    HostLogic,
    Link,
    LinkFailed,
    LinkLost,
    LinkUp,
    RegisterRead,
    RegisterWritten,
    Status,
    StatusUpdated,
)
from fabwire.mmu.protocol import Cut, Eject, Home, Load, Mode, Request, ToolChange, Unload, make_request
from fabwire.opening import DeviceLink, DeviceTarget, Opening
from fabwire.transport import Transport
from fabwire.transport.limits import refusal
from fabwire.transport.peers import FirstBytes, name_peer, wrong_peer

if TYPE_CHECKING:
    from fabwire.mmu.sync import SyncMMU

log = logging.getLogger("fabwire.mmu")
T = TypeVar("T")
CONNECT_SECONDS = 5.0
"""Default time for the handshake, in MMU seconds: an MMU that is up answers S0 at once; one that is booting
needs ≈4 s (reference §1)."""
EventCallback = Callable[[HostEvent], None]
NOT_AN_MMU = "a Prusa MMU3"


def check_slot(slot: int) -> int:
    if not isinstance(slot, int) or isinstance(slot, bool) or not 0 <= slot <= 4:
        raise InputError(f"filament slot must be 0 to 4, not {slot!r}")
    return slot


def resolve_register(register: int | str, *, for_write: bool = False,
                     version: tuple[int, int, int] = (3, 0, 4)) -> codes.Register:
    found = codes.find_register(str(register)) if not isinstance(register, int) else (
        codes.REGISTERS[register] if 0 <= register < codes.REGISTER_COUNT else None)
    if found is None:
        hint = closest(str(register)[:100].lower(), list(codes.REGISTERS_BY_NAME)) if isinstance(register, str) else ""
        raise InputError(f"unknown MMU register {excerpt(str(register), 40)}{hint}: use a name such as "
                         f"'bowden_length' or an address from 0x00 to 0x{codes.REGISTER_COUNT - 1:02x} "
                         "(`fabwire mmu registers` lists them)")
    if for_write and not found.writable(version):
        raise InputError(f"register 0x{found.address:02x} ({found.name}) is read-only"
                         + (" on this firmware" if found.access is codes.Access.RW_304 else ""))
    return found


def error_for(event: ErrorRaised) -> MMUError:
    return MMUError(event.code, command=event.command)


MOVING_REGISTERS = frozenset({0x1B, 0x1C})
"""Selector and idler slot: a write plans a move, which ends later."""
MOVE_SETTLE = 10.0
"""MMU seconds a written slot has to show: the longest selector move (1.8 s) after a homing (3-6 s), §5.5."""


class MMU:
    """An MMU3 on `transport`, driven the way a Prusa printer drives it (heartbeat, retries, restarts)."""

    def __init__(self, transport: Transport, *, accepted: Iterable[tuple[int, int, int]] = SUPPORTED,
                 init_registers: Iterable[tuple[int, int]] = INIT_REGISTERS, fsensor_mode: FSensorMode = "auto",
                 time_scale: float = 1.0, auto_retries: int = 3, connect_timeout: float = 30.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.transport = transport
        self.logic = HostLogic(accepted=accepted, init_registers=init_registers, fsensor_mode=fsensor_mode,
                               time_scale=time_scale, auto_retries=auto_retries)
        self.connect_timeout = connect_timeout
        self._clock = clock
        self._listeners: list[EventCallback] = []
        self._wake = asyncio.Event()
        self._write_lock = asyncio.Lock()
        self._tasks: list[asyncio.Task[None]] = []
        self._failure: BaseException | None = None
        self._first = FirstBytes()
        """The first bytes the peer sent: what names a peer that is no MMU."""
        self._ready = asyncio.Event()
        self._kick = asyncio.Event()
        self.owns_transport = False
        """Opened by `open`: closing the client also closes the link."""
        self.commands = "fabwire mmu"
        """The command line that messages name for what to do next (`fabwire mmu reset` …); the CLI sets the one it
        was run with, device and link options included, so that the advice works as typed."""

    @classmethod
    def open(cls, target: DeviceTarget = None, **options: Any) -> Opening[MMU]:
        """`async with MMU.open("/dev/ttyACM0") as mmu` (or `await` it): opens the link and completes the handshake.

        `target` and the common options are described in `fabwire.opening`; the MMU's settings are
        `fabwire.config.MMUSettings` (speed, accept, connect_timeout, auto_retries).
        """
        return Opening(MMU_KIND, target, options, cls._on_link)

    @classmethod
    def open_sync(cls, target: DeviceTarget = None, **options: Any) -> SyncMMU:
        """`with MMU.open_sync("sim://mmu", speed=50) as mmu: mmu.load(2)` for plain scripts."""
        from fabwire.mmu.sync import SyncMMU

        return SyncMMU(target, **options)

    @classmethod
    async def _on_link(cls, transport: Transport, opened: DeviceLink) -> MMU:
        s = opened.settings
        assert isinstance(s, MMUSettings)
        accepted = {(int(a), int(b), int(c)) for a, b, c in (v.split(".") for v in s.accept)} or SUPPORTED
        speed = s.speed
        endpoint = opened.endpoint
        if speed == 1.0 and endpoint is not None and endpoint.scheme == "sim" and "speed" in endpoint.options:
            with contextlib.suppress(ValueError):
                speed = float(endpoint.options["speed"])  # the simulator's own time scale
        mmu = cls(transport, accepted=accepted, time_scale=speed, auto_retries=s.auto_retries,
                  connect_timeout=s.connect_timeout or max(s.timeout, CONNECT_SECONDS / speed))
        mmu.owns_transport = True
        await mmu.connect()
        return mmu

    # ------------------------------------------------------------------------------------------ lifecycle

    async def __aenter__(self) -> Self:
        await self.connect()
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                        tb: TracebackType | None) -> None:
        await self.close()

    async def connect(self) -> None:
        """Start the link and wait for the handshake and first status poll."""
        self._listeners.append(self._watch_link)
        self.logic.start(self._clock())
        await self._flush()
        self._tasks = [asyncio.create_task(self._reader(), name="mmu-reader"),
                       asyncio.create_task(self._timer(), name="mmu-timer")]
        try:
            async with asyncio.timeout(self.connect_timeout):
                await self._until(lambda: self._ready.is_set())
        except TimeoutError:
            await self.close()
            if (named := await self._name_peer()) is not None:
                raise named from None
            if self._failure is not None:
                raise self._failure from None
            raise LinkTimeout(f"the MMU on {self.transport.peer or self.transport.url} did not complete the "
                              f"handshake within {self.connect_timeout:g} s ({self._silence_words()}): "
                              "check the address, power and cable") from None
        except (LinkClosed, LinkTimeout) as exc:
            await self.close()
            if (named := await self._name_peer()) is not None:
                raise named from exc
            raise
        except BaseException:
            await self.close()
            raise

    async def _name_peer(self) -> LinkError | RemoteProtocolError | None:
        """Why a peer never heard as an MMU gave no firmware version: the error naming what it is (from its first
        bytes, or from its answer to a probe when it said nothing), or None when nothing names it."""
        if self.logic.version is not None:
            return None
        if not self._first:  # free the peer's connection slot for the probes (a bridge may have only one)
            await self.transport.close()
        return await name_peer(self._first.data, self.transport.url, NOT_AN_MMU, MMU_KIND.name,
                               self.transport.peer or self.transport.url)

    def _silence_words(self) -> str:
        reason = self.logic.last_drop_out
        if reason.startswith("timeout") or not reason:
            return f"no reply within {self.logic.link_timeout:g} s, {max(1, self.logic.drop_outs)} times"
        return f"its replies do not decode: {reason}"

    async def close(self) -> None:
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(BaseException):
                await task
        self._tasks = []
        if self.owns_transport:
            await self.transport.close()

    def _watch_link(self, event: HostEvent) -> None:
        if isinstance(event, LinkUp | LinkLost | LinkFailed | ErrorRaised | CommandFinished):
            log.info("%s", event)
        if isinstance(event, LinkUp):
            self._ready.set()
        elif isinstance(event, LinkFailed) and event.code == 0x802C:
            self._fail(MMUError(0x802C, detail=event.detail))
        elif isinstance(event, LinkFailed) and not self._ready.is_set():
            where = self.transport.peer or self.transport.url
            self._fail(LinkTimeout(event.info.explained(detail=f"no link to {where} ({event.detail})")))

    def _fail(self, exc: BaseException) -> None:
        if self._failure is None:
            self._failure = exc
        self._wake.set()

    # ------------------------------------------------------------------------------------------ plumbing

    def _dispatch(self) -> None:
        for event in self.logic.events():
            for listener in list(self._listeners):
                listener(event)
        self._wake.set()

    async def _flush(self) -> None:
        async with self._write_lock:
            data = self.logic.data_to_send()
            if data:
                await self.transport.write(data)

    async def _reader(self) -> None:
        try:
            while True:
                data = await self.transport.read(4096)
                if self.logic.version is None:
                    self._first.feed(data)
                    said, where = self._first.data, self.transport.peer or self.transport.url
                    if (wrong := refusal(said, where) or wrong_peer(said, NOT_AN_MMU, MMU_KIND.name, where)):
                        self._fail(wrong)
                        return
                self.logic.receive(data, self._clock())
                self._dispatch()
                await self._flush()
        except LinkClosed as exc:
            self._fail(exc)
        except Exception as exc:
            self._fail(LinkClosed(f"link to the MMU failed: {exc!r}"))

    async def _timer(self) -> None:
        try:
            while True:
                deadline = self.logic.next_deadline()
                delay = None if deadline is None else max(0.0, deadline - self._clock())
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(delay):
                        await self._kick.wait()
                self._kick.clear()
                self.logic.handle_timer(self._clock())
                self._dispatch()
                await self._flush()
        except LinkClosed as exc:
            self._fail(exc)
        except Exception as exc:  # a task that dies quietly would leave every operation waiting out its timeout
            self._fail(LinkClosed(f"link to the MMU failed: {exc!r}"))

    async def _until(self, done: Callable[[], bool]) -> None:
        while not done():
            if self._failure is not None:
                raise self._failure
            self._wake.clear()
            await self._wake.wait()

    async def _operate(self, start: Callable[[float], None], outcome: Callable[[HostEvent], Any],
                       on_event: EventCallback | None, timeout: float | None) -> Any:
        """Run `start`, then wait for the first event `outcome` maps to a value (or raises on)."""
        result: list[Any] = []
        errors: list[BaseException] = []

        def listen(event: HostEvent) -> None:
            if on_event is not None:
                on_event(event)
            if result or errors:
                return
            try:
                value = outcome(event)
            except BaseException as exc:  # the outcome says this event is a failure
                errors.append(exc)
                return
            if value is not None:
                result.append(value)
            elif isinstance(event, LinkFailed):  # ten drop-outs in a row: no reply will come to this either
                errors.append(LinkTimeout(event.info.explained(detail=f"link failed ({event.detail})")))

        self._listeners.append(listen)
        try:
            if self._failure is not None:
                raise self._failure
            start(self._clock())
            self._kick.set()
            await self._flush()
            async with asyncio.timeout(timeout):
                await self._until(lambda: bool(result or errors))
        except TimeoutError:
            raise LinkTimeout(f"the MMU did not finish within {timeout:g} s") from None
        finally:
            self._listeners.remove(listen)
        if errors:
            raise errors[0]
        return result[0]

    # ------------------------------------------------------------------------------------------ operations

    async def status(self) -> Status:
        """The MMU's state as its last status poll (Q0 and the register reads, each heartbeat) left it; `refresh`
        waits for the next poll instead."""
        return self.logic.status

    async def version(self) -> codes.FirmwareVersion:
        """The firmware version the handshake read (S0-S3)."""
        version = self.logic.version
        if version is None:
            raise LinkClosed("the MMU link is not up: no firmware version was read")
        return version

    def subscribe(self, callback: EventCallback) -> Callable[[], None]:
        """Call `callback` for every host event; returns the unsubscribe function."""
        self._listeners.append(callback)
        return lambda: self._listeners.remove(callback) if callback in self._listeners else None

    async def run(self, request: Request, *, on_event: EventCallback | None = None,
                  timeout: float | None = None, confirm_eject: bool = True) -> CommandFinished:
        """Run one command to its end; an error the host cannot retry away raises DeviceError."""
        if request.code in "TLEK":
            check_slot(request.value)
        if self.logic.busy and self.logic.command == request:  # running already (an earlier link, another client)
            return await self.follow(on_event=on_event, timeout=timeout, confirm_eject=confirm_eject)
        if self.logic.busy:
            raise self.busy_error()
        outcome = self._command_outcome(str(request), confirm_eject)
        try:
            finished: CommandFinished = await self._operate(lambda now: self.logic.plan_command(request, now),
                                                            outcome, on_event, timeout)
        except LinkTimeout:
            self.logic.abandon()  # the caller gave up on it: a later command must not be refused as "already running"
            raise
        return await self._confirmed(request, finished, timeout)

    def busy_error(self) -> DeviceError | DeviceBusy:
        """Why a new command cannot start: the one the MMU runs, or the error it stopped in and what answers it
        (reference §5.1: every command is refused until the running one ends or its error is answered)."""
        status = self.logic.status
        command = status.command if status.command[:1] in "TLUEKHM" else str(self.logic.command)
        if status.kind == "E":
            info = describe_error(status.value)
            return DeviceError("", f"the MMU stopped in {info} during {command}",  # its code is in the words
                               action=f"answer it with {info.answers(self.commands)}")
        return DeviceBusy(f"the MMU is still busy with {command} ({status.words}): let it finish "
                          f"(`{self.commands} monitor`), or {reset_line(self.commands)}")

    async def _confirmed(self, request: Request | None, finished: CommandFinished,
                         timeout: float | None) -> CommandFinished:
        """`finished`, once the registers show the end state of `request` (`fabwire.mmu.evidence`); an MMU that
        says `F0` but shows the state from before is a DeviceError, not a success."""
        if request is None or finished.result != 0 or finished.command != str(request):
            return finished
        expects, settle = end_state(request)
        end = self._clock() + settle / self.logic.timing.time_scale
        while expects:
            read: dict[int, int] = {}
            for expect in expects:
                if expect.address not in read:
                    read[expect.address] = await self.read_register(expect.address, timeout or 10.0)
            wrong = [e for e in expects if not e.holds(read[e.address])]
            if not wrong:
                break
            if self._clock() >= end:
                raise DeviceError("not done", f"the MMU reported {request} finished, but it shows "
                                  + ", ".join(e.shown(read[e.address]) for e in wrong) + " (a finished "
                                  + f"{request} leaves " + ", ".join(e.wanted for e in wrong) + ")",
                                  action="the command did not take effect: check the MMU with "
                                         f"`{self.commands} status`")
            await asyncio.sleep(min(0.05, settle / 20 / self.logic.timing.time_scale))
        return finished

    def _command_outcome(self, expected: str | None,
                         confirm_eject: bool) -> Callable[[HostEvent], CommandFinished | None]:
        """What ends a command: its F (`expected`, or whichever the MMU runs when None), or an error."""

        def outcome(event: HostEvent) -> CommandFinished | None:
            if isinstance(event, CommandFinished) and (expected is None or event.command == expected):
                return event
            if isinstance(event, ErrorRaised) and not event.auto_retry:
                if confirm_eject and event.code == 0x800C:
                    self.logic.press(int(codes.Button.MIDDLE), self._clock())
                    self._kick.set()
                    return None
                self.logic.abandon()
                raise self._explained(error_for(event))
            if isinstance(event, CommandRejected):
                raise DeviceError("rejected", f"the MMU rejected {event.command} {event.attempts} times "
                                  "(busy, in an error state, or the filament state does not allow it)",
                                  action=f"check `{self.commands} status`, resolve any error, then try again")
            if isinstance(event, CommandInterrupted):
                raise RemoteProtocolError(f"{event.command} was interrupted: the MMU reported {event.reported} "
                                          "(it probably rebooted)")
            if isinstance(event, LinkFailed):
                raise LinkTimeout(event.info.explained(detail=f"link failed ({event.detail})"))
            return None

        return outcome

    def _explained(self, error: MMUError) -> MMUError:
        """An error that a wrong time scale can cause says so when the MMU was seen moving too fast."""
        factor = self.logic.timing.too_fast
        if factor is not None:
            error.args = (f"{error.args[0]} — but the MMU moved {factor:.0f}× faster than this host assumes: "
                          f"its timing does not fit (give --speed {factor:.0f}, or the device's speed)",)
        return error

    async def follow(self, *, on_event: EventCallback | None = None, timeout: float | None = None,
                     confirm_eject: bool = False) -> CommandFinished:
        """Follow the command the MMU is running (as adopted from its Q0 answer) to its end."""
        if not self.logic.busy:
            status = self.logic.status
            raise DeviceError("idle", f"the MMU runs no command (it reports {status.command} {status.words})")
        request = self.logic.command
        start: Callable[[float], None] = lambda now: None  # noqa: E731
        status = self.logic.status
        if status.kind == "E" and status.command == str(request) and not self.logic.retrying:
            # reported before we listened, and reported only once: waiting for it again would wait out `timeout`
            if not (confirm_eject and status.value == 0x800C):
                self.logic.abandon()
                raise self._explained(MMUError(status.value, command=status.command))
            start = lambda now: self.logic.press(int(codes.Button.MIDDLE), now)  # noqa: E731
        finished: CommandFinished = await self._operate(start, self._command_outcome(None, confirm_eject),
                                                        on_event, timeout)
        return await self._confirmed(request, finished, timeout)

    def dialog_button(self, choice: str) -> int | None:
        """The button (0 Right, 1 Middle, 2 Left) the printer's dialog sends for `choice` ('Retry', 'Continue',
        'Stop', …) on the pending error: each error's dialog has its own (Continue is Middle on most, Right on
        04501 and Left on the TMC warnings: the table `fabwire.mmu.errors`, after the printer firmware's
        mmu2_error_converter.cpp). None for Stop where the dialog's Stop print is the printer's alone (no button is
        sent). InputError when no error is pending or its dialog does not offer `choice`."""
        word = self.logic.status.value if self.logic.status.kind == "E" else None
        if word is None:
            status = self.logic.status
            raise InputError(f"no error is pending: the MMU reports {status.command} {status.words}")
        info = describe_error(word)
        button = info.button_for(choice)
        if button is None and choice.lower() == "stop":
            return None
        if not isinstance(button, int):
            offered = ", ".join(c.label for c in info.choices)
            then = (f"reset the MMU ({reset_line(self.commands)})" if button == "reset"
                    else f"answer with one of: {offered}")
            raise InputError(f"{info} offers {offered}, not {choice}: {then}")
        return button

    async def answer(self, choice: str, *, on_event: EventCallback | None = None,
                     timeout: float | None = None) -> CommandFinished | None:
        """Answer the MMU's pending error as the printer's dialog does (Retry, Continue, Stop…), then follow the
        command to its end. None when the choice ends nothing (Stop). Raises DeviceError when no error is
        pending or the dialog does not offer `choice`."""
        button = self.dialog_button(choice)
        if button is None:
            self.logic.abandon()
            return None
        command = self.logic.status.command
        await self.press(button, timeout=timeout)
        await self.refresh(timeout=timeout)  # this poll may have been under way before the press: take the next
        status = await self.refresh(timeout=timeout)  # a running command is adopted from this poll
        end = None if timeout is None else self._clock() + timeout
        while not self.logic.busy and status.command == command and status.kind in "PB":
            if end is not None and self._clock() >= end:
                raise LinkTimeout(f"the MMU still reports {status.command} {status.words} {timeout:g} s after "
                                  f"the {choice} press")
            status = await self.refresh(timeout=timeout)  # X0 (homing after boot) cannot be adopted: watch it
        if self.logic.busy:
            return await self.follow(on_event=on_event, timeout=timeout, confirm_eject=False)
        if status.kind == "E":
            raise self._explained(MMUError(status.value, command=status.command))
        if status.kind == "F" and status.command == command:
            known = len(command) > 1 and command[0] in "TLUEKHM"
            request = make_request(command[0], int(command[1:], 16)) if known else None
            return await self._confirmed(request, CommandFinished(command, status.value), timeout)
        return None

    async def tool_change(self, slot: int, **kwargs: Any) -> CommandFinished:
        return await self.run(ToolChange(check_slot(slot)), **kwargs)

    async def load(self, slot: int, **kwargs: Any) -> CommandFinished:
        return await self.run(Load(check_slot(slot)), **kwargs)

    async def unload(self, **kwargs: Any) -> CommandFinished:
        return await self.run(Unload(0), **kwargs)

    async def eject(self, slot: int, **kwargs: Any) -> CommandFinished:
        return await self.run(Eject(check_slot(slot)), **kwargs)

    async def cut(self, slot: int, **kwargs: Any) -> CommandFinished:
        return await self.run(Cut(check_slot(slot)), **kwargs)

    async def home(self, **kwargs: Any) -> CommandFinished:
        return await self.run(Home(0), **kwargs)

    async def set_mode(self, stealth: bool, **kwargs: Any) -> CommandFinished:
        return await self.run(Mode(int(stealth)), **kwargs)

    async def press(self, button: int | str, timeout: float | None = 10.0) -> None:
        """Press an MMU button from the printer: 0 or right, 1 or middle, 2 or left. To answer an error as the
        printer's dialog does (Retry, Continue, Stop), see `answer` and `dialog_button`."""
        if isinstance(button, str):
            if button.lower() not in codes.BUTTON_ALIASES:
                raise InputError(f"unknown button {button!r}: use left, middle or right (or answer the error with "
                                 "retry, continue or stop)")
            button = codes.BUTTON_ALIASES[button.lower()]
        if button not in (0, 1, 2):
            raise InputError(f"button must be 0, 1 or 2, not {button!r}")
        number = int(button)

        def outcome(event: HostEvent) -> bool | None:
            return True if isinstance(event, ButtonSent) and event.button == number else None

        await self._operate(lambda now: self.logic.press(number, now), outcome, None, timeout)

    async def read_register(self, register: int | str, timeout: float | None = 10.0) -> int:
        address = resolve_register(register).address

        def outcome(event: HostEvent) -> int | None:
            if isinstance(event, RegisterRead) and event.address == address:
                if event.value is None:
                    raise DeviceError("R", f"the MMU rejected the read of register 0x{address:02x}")
                return event.value
            return None

        value: int = await self._operate(lambda now: self.logic.read_register(address, now), outcome, None,
                                         timeout)
        return value

    async def write_register(self, register: int | str, value: int, timeout: float | None = 10.0) -> int:
        """Write `value` and return what the register then reads: the firmware's conversion of it (300 mm/s² of
        pulley acceleration reads 299). DeviceError when the MMU refuses or does not carry out the write."""
        version = self.logic.version.triple if self.logic.version else (3, 0, 4)
        found = resolve_register(register, for_write=True, version=version)
        limit = (1 << found.bits) - 1
        if not isinstance(value, int) or not 0 <= value <= 0xFFFF:
            raise InputError(f"register value must be 0 to 65535, not {value!r}")
        if value > limit:
            raise InputError(f"register 0x{found.address:02x} ({found.name}) holds {found.bits} bits: "
                             f"0 to {limit}, not {value}")

        def outcome(event: HostEvent) -> bool | None:
            if isinstance(event, RegisterWritten) and event.address == found.address:
                if not event.accepted:
                    raise DeviceError("R", f"the MMU refused the write to register 0x{found.address:02x}")
                return True
            return None

        await self._operate(lambda now: self.logic.write_register(found.address, value, now), outcome, None,
                            timeout)
        return await self._check_written(found, value, timeout)

    async def _check_written(self, register: codes.Register, value: int, timeout: float | None) -> int:
        """The MMU answers `A` even to a write it does not carry out (a selector move refused while FINDA is
        pressed, reference §register 0x1b): the register is read back and compared with what the firmware makes
        of `value` (`fabwire.mmu.units`: 300 mm/s² of pulley acceleration reads 299); a value that never shows is
        a DeviceError. Writes that move an axis get the time the move (and a homing before it) takes."""
        expected = units.readbacks(register, value)
        settle = (MOVE_SETTLE if register.address in MOVING_REGISTERS else 0.0) / self.logic.timing.time_scale
        end = self._clock() + settle
        while True:
            now = await self.read_register(register.address, timeout)
            if now in expected:
                return now
            if self._clock() >= end:
                wanted = " or ".join(str(v) for v in sorted(expected))
                raise DeviceError("not applied", f"the MMU accepted {value} for register 0x{register.address:02x} "
                                  f"({register.name}) but it reads {now}, not {wanted}",
                                  action="nothing was changed")
            await asyncio.sleep(min(0.05, settle / 20))

    async def refresh(self, timeout: float | None = 10.0) -> Status:
        """Wait for the next heartbeat's status poll."""

        def outcome(event: HostEvent) -> Status | None:
            return event.status if isinstance(event, StatusUpdated) else None

        status: Status = await self._operate(lambda now: None, outcome, None, timeout)
        return status

    async def reset(self, timeout: float | None = 30.0, *, erase: bool = False) -> codes.FirmwareVersion:
        """Reboot the MMU (X0; X2a with `erase`, which also wipes its EEPROM) and wait until the link is back."""
        self._ready.clear()

        def outcome(event: HostEvent) -> codes.FirmwareVersion | None:
            return event.version if isinstance(event, LinkUp) else None

        version: codes.FirmwareVersion = await self._operate(lambda now: self.logic.reset(now, erase=erase),
                                                             outcome, None, timeout)
        if self.logic.status.command != "X0":  # a rebooted MMU reports its start-up command first (reference §5.2)
            raise DeviceError("not reset", f"the MMU answers again but still reports {self.logic.status.command} "
                              f"{self.logic.status.words}, not the start-up command X0: it did not reboot",
                              action="power-cycle the MMU")
        return version

    async def events(self) -> AsyncIterator[HostEvent]:
        """Every host event as it happens, until the link fails."""
        queue: asyncio.Queue[HostEvent] = asyncio.Queue(maxsize=1000)

        def put(event: HostEvent) -> None:
            with contextlib.suppress(asyncio.QueueFull):
                queue.put_nowait(event)

        unsubscribe = self.subscribe(put)
        try:
            while True:
                if self._failure is not None and queue.empty():
                    raise self._failure
                getter = asyncio.ensure_future(queue.get())
                waker = asyncio.ensure_future(self._wait_failure())
                done, _ = await asyncio.wait({getter, waker}, return_when=asyncio.FIRST_COMPLETED)
                waker.cancel()
                if getter in done:
                    yield getter.result()
                else:
                    getter.cancel()
        finally:
            unsubscribe()

    async def _wait_failure(self) -> None:
        while self._failure is None:
            self._wake.clear()
            await self._wake.wait()

    @property
    def link_state(self) -> Link:
        return self.logic.link
