"""The printer's side of the MMU3 link, as Prusa's printer firmware runs it — sans-IO, time as an input.

`HostLogic` does the handshake (S0-S3 with a version check, init register writes, `f`), the Q0 heartbeat after
1 s of silence with five register reads after each reply, the 2 s link timeout, restart after a protocol error,
the drop-out filter, immediate re-send on `R`, `f` updates and bounded automatic Retry. It emits typed events;
`fabwire.mmu.client` turns them into awaitable operations.
"""

from __future__ import annotations

import enum
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Literal

from fabwire.errors import LocalProtocolError
from fabwire.mmu import codes
from fabwire.mmu.errors import ErrorInfo, describe_error
from fabwire.mmu.protocol import (
    Accepted,
    ButtonPress,
    ButtonPressed,
    CommandError,
    DecodeError,
    Finished,
    FSensorState,
    Processing,
    Query,
    Read,
    Rejected,
    Request,
    Reset,
    Response,
    ResponseDecoder,
    Version,
    Write,
    encode_request,
    make_request,
)

HEARTBEAT = 1.0
LINK_TIMEOUT = 2.0
DROP_OUT_LIMIT = 10
VERSION_RETRIES = 6
AUTO_RETRIES = 3
REJECT_LIMIT = 20
"""Our bound on the firmware's resend-on-R loop, so a permanently busy MMU ends in a clear failure."""
IMMEDIATE_RESENDS = 3
"""Re-sends on R go out at once (as the printer does) this many times, then one per heartbeat."""
POLL_REGISTERS = (0x08, 0x1B, 0x1C, 0x04, 0x1A)
INIT_REGISTERS = ((0x0B, 5), (0x14, 20))
SUPPORTED = frozenset({(3, 0, 2), (3, 0, 3), (3, 0, 4)})
BUSY_CODES = "KELMTUH"
"""Echoed codes that mean 'the MMU is running a command'. The printer firmware leaves out H and then treats the
idle reply `H0 F0` as a protocol error; we include it so a Home does not trigger endless re-handshakes."""


class Link(enum.Enum):
    CONNECTING = "connecting"
    READY = "ready"
    RESTARTING = "restarting"
    FAILED = "failed"
    """Version mismatch: the link is stopped until `start` is called again."""


@dataclass(frozen=True, slots=True)
class Status:
    command: str = ""
    """The command the MMU echoes in Q0 replies, e.g. 'T1' (X0 after boot)."""
    kind: str = ""
    """'P' running, 'E' error, 'F' finished, 'B' button."""
    value: int = 0
    finda: bool | None = None
    selector: int | None = None
    idler: int | None = None
    drive_errors: int | None = None
    pulley: int | None = None

    @property
    def words(self) -> str:
        if self.kind == "P":
            return codes.progress_words(self.value)
        if self.kind == "E":
            return describe_error(self.value).meaning
        if self.kind == "F":
            return "finished" if self.value == 0 else "cancelled"
        if self.kind == "B":
            return f"{codes.BUTTON_WORDS.get(self.value, self.value)} button pressed"
        return ""


# ------------------------------------------------------------------------------------------------ events


@dataclass(frozen=True, slots=True)
class LinkUp:
    version: codes.FirmwareVersion


@dataclass(frozen=True, slots=True)
class LinkLost:
    reason: str
    drop_outs: int


@dataclass(frozen=True, slots=True)
class LinkFailed:
    """Surfaced after the drop-out filter (or at once for a version mismatch)."""

    code: int
    info: ErrorInfo
    detail: str = ""


@dataclass(frozen=True, slots=True)
class ProgressChanged:
    command: str
    code: int

    @property
    def name(self) -> str:
        return codes.progress_name(self.code)

    @property
    def words(self) -> str:
        return codes.progress_words(self.code)


@dataclass(frozen=True, slots=True)
class ErrorRaised:
    command: str
    code: int
    info: ErrorInfo
    auto_retry: bool
    """The host is pressing Retry by itself; when False a person (or the caller) must act."""
    retries_left: int


@dataclass(frozen=True, slots=True)
class CommandFinished:
    command: str
    result: int


@dataclass(frozen=True, slots=True)
class CommandRejected:
    command: str
    attempts: int


@dataclass(frozen=True, slots=True)
class CommandInterrupted:
    """The MMU reported a different command finished (e.g. `X0 F0` after it rebooted)."""

    command: str
    reported: str


@dataclass(frozen=True, slots=True)
class ButtonPushed:
    command: str
    button: int


@dataclass(frozen=True, slots=True)
class RegisterRead:
    address: int
    value: int | None
    """None when the MMU rejected the read."""


@dataclass(frozen=True, slots=True)
class RegisterWritten:
    address: int
    value: int
    accepted: bool


@dataclass(frozen=True, slots=True)
class ButtonSent:
    button: int


@dataclass(frozen=True, slots=True)
class StatusUpdated:
    status: Status


HostEvent = (LinkUp | LinkLost | LinkFailed | ProgressChanged | ErrorRaised | CommandFinished | CommandRejected
             | CommandInterrupted | ButtonPushed | RegisterRead | RegisterWritten | ButtonSent | StatusUpdated)

FSensorMode = Literal["auto", "manual"]


@dataclass
class _Handshake:
    stage: int = 0
    version: list[int] = field(default_factory=list)
    retries: int = VERSION_RETRIES


class HostLogic:
    """Sans-IO printer-side protocol logic. Feed `receive`/`handle_timer` with `now`; read `data_to_send` and
    `events`; ask `next_deadline` when to call `handle_timer` again."""

    def __init__(self, *, accepted: Iterable[tuple[int, int, int]] = SUPPORTED,
                 init_registers: Iterable[tuple[int, int]] = INIT_REGISTERS, fsensor: int = 0,
                 fsensor_mode: FSensorMode = "auto", time_scale: float = 1.0,
                 auto_retries: int = AUTO_RETRIES) -> None:
        if not time_scale > 0:
            raise LocalProtocolError("time_scale must be positive")
        self.accepted = frozenset(accepted)
        self.init_registers = tuple(init_registers)
        self.fsensor = fsensor
        self.fsensor_mode = fsensor_mode
        self.heartbeat = HEARTBEAT / time_scale
        self.link_timeout = LINK_TIMEOUT / time_scale
        self.auto_retries = auto_retries
        self.link = Link.CONNECTING
        self.version: codes.FirmwareVersion | None = None
        self.status = Status()
        self.drop_outs = 0
        self._decoder = ResponseDecoder()
        self._out = bytearray()
        self._events: list[HostEvent] = []
        self._inflight: Request | None = None
        self._last_activity = 0.0
        self._scope: Literal["start", "idle", "command", "restart", "stopped"] = "stopped"
        self._hs = _Handshake()
        self._startup: deque[Request] = deque()
        self._followups: deque[Request] = deque()
        self._planned: deque[Request] = deque()
        self._command: Request | None = None
        self._command_sent = False
        self._rejects = 0
        self._fsensor_reported: int | None = None
        self._retries_left = auto_retries
        self._retry_pending = False
        self._last_report: tuple[str, int] | None = None
        self._reads: dict[int, int] = {}
        self._announced = False
        self._inflight_poll = False
        self._retry_acked = False
        self._resend_at = 0.0

    # ----------------------------------------------------------------------------------------- outputs

    def data_to_send(self) -> bytes:
        out = bytes(self._out)
        self._out.clear()
        return out

    def events(self) -> list[HostEvent]:
        events, self._events = self._events, []
        return events

    def next_deadline(self) -> float | None:
        if self._scope == "stopped":
            return None
        if self._scope == "restart":
            return self._last_activity + self.heartbeat
        if self._inflight is not None:
            return self._last_activity + self.link_timeout
        heartbeat = self._last_activity + self.heartbeat
        if self._command is not None and not self._command_sent:
            return min(heartbeat, self._resend_at)
        return heartbeat

    @property
    def busy(self) -> bool:
        """A command is planned or running."""
        return self._command is not None

    @property
    def command(self) -> Request | None:
        return self._command

    # ----------------------------------------------------------------------------------------- inputs

    def start(self, now: float) -> None:
        """(Re)start the link: handshake from S0."""
        self._restart(now)

    def receive(self, data: bytes, now: float) -> None:
        if not data or self._scope == "stopped":
            return
        self._last_activity = now
        if self._scope == "restart":
            return  # drained when the restart happens
        for event in self._decoder.feed(data):
            if isinstance(event, DecodeError):
                if b"ok" in data:
                    self._version_mismatch("the MMU answered 'ok': firmware 1.x")
                else:
                    self._protocol_error(now, event.reason)
                return
            self._on_response(event, now)
            if self._scope in ("restart", "stopped"):
                return
        self._pump(now)

    def handle_timer(self, now: float) -> None:
        if self._scope == "stopped":
            return
        if self._scope == "restart":
            if now - self._last_activity >= self.heartbeat:
                self._restart(now)
            return
        if self._inflight is not None:
            if now - self._last_activity >= self.link_timeout:
                self._drop_out(now, f"timeout: no reply within {self.link_timeout:.3g} s")
                self._restart(now)
            return
        self._pump(now)

    def plan_command(self, request: Request, now: float) -> None:
        """Run T, L, U, E, K, H or M; progress and the outcome arrive as events."""
        if request.code not in "TLUEKHM":
            raise LocalProtocolError(f"{request} is not an MMU command")
        if self._command is not None:
            raise LocalProtocolError(f"the MMU is already running {self._command}")
        self._retries_left = self.auto_retries
        self._last_report = None
        self._retry_pending = False
        self._rejects = 0
        self._resend_at = now
        self._command = request
        self._command_sent = False
        self._pump(now)

    def press(self, button: int, now: float) -> None:
        self._planned.append(ButtonPress(button))
        self._pump(now)

    def read_register(self, address: int, now: float) -> None:
        self._planned.append(Read(address))
        self._pump(now)

    def write_register(self, address: int, value: int, now: float) -> None:
        self._planned.append(Write(address, value))
        self._pump(now)

    def set_fsensor(self, state: int, now: float) -> None:
        """The printer's filament sensor changed; sent at once while a command runs (the MMU waits for it)."""
        self.fsensor = state
        self._pump(now)

    def reset(self, now: float) -> None:
        """Reboot the MMU with X0; there is no reply, so the link times out and re-handshakes."""
        self._command = None
        self._followups.clear()
        self._planned.clear()
        self._planned.appendleft(Reset(0))
        self._pump(now)

    def abandon(self) -> None:
        """Stop tracking the current command (the MMU may still be running it; the next Q0 adopts it again)."""
        self._command = None
        self._command_sent = False
        if self._scope == "command":
            self._scope = "idle"

    # ----------------------------------------------------------------------------------------- internals

    def _send(self, request: Request, now: float, poll: bool = False) -> None:
        self._out += encode_request(request)
        self._inflight = request
        self._inflight_poll = poll
        self._last_activity = now
        if request.code == "f":
            self._fsensor_reported = request.value

    def _restart(self, now: float) -> None:
        self._decoder.reset()
        self._inflight = None
        self._followups.clear()
        self._hs = _Handshake()
        self._scope = "start"
        self.link = Link.CONNECTING if self.version is None else Link.RESTARTING
        self._announced = False
        self._send(Version(0), now)

    def _drop_out(self, now: float, reason: str) -> None:
        self.drop_outs += 1
        self._events.append(LinkLost(reason, self.drop_outs))
        if self.drop_outs % DROP_OUT_LIMIT == 0:
            code = 0x802D if reason.startswith("protocol") else 0x802E
            self._events.append(LinkFailed(code, describe_error(code), reason))

    def _protocol_error(self, now: float, reason: str) -> None:
        self._drop_out(now, f"protocol error: {reason}")
        self._inflight = None
        self._scope = "restart"
        self.link = Link.RESTARTING
        self._last_activity = now

    def _version_mismatch(self, detail: str) -> None:
        self._scope = "stopped"
        self.link = Link.FAILED
        self._inflight = None
        self._events.append(LinkFailed(0x802C, describe_error(0x802C), detail))

    def _pump(self, now: float) -> None:
        """Send the next request if none is outstanding."""
        if self._inflight is not None or self._scope not in ("idle", "command", "start"):
            return
        if self._scope == "start":
            if self._startup:
                self._send(self._startup.popleft(), now)
            return
        if self._planned and self._planned[0].code == "X":
            self._send(self._planned.popleft(), now)
            return
        if self._scope == "command" and self._fsensor_reported != self.fsensor:
            self._send(FSensorState(self.fsensor), now)
            return
        if self._followups:
            self._send(self._followups.popleft(), now, poll=True)
            return
        if self._command is not None and not self._command_sent and now >= self._resend_at:
            self._scope = "command"
            self._command_sent = True
            self._send(self._command, now)
            return
        if self._planned:
            self._send(self._planned.popleft(), now)
            return
        if now - self._last_activity >= self.heartbeat:
            self._send(Query(0), now)

    def _queue_reads(self, with_fsensor: bool) -> None:
        if with_fsensor:
            self._followups.append(FSensorState(self.fsensor))
        self._followups.extend(Read(a) for a in POLL_REGISTERS)

    def _on_response(self, response: Response, now: float) -> None:
        sent = self._inflight
        if sent is None:
            self._protocol_error(now, "reply with no request outstanding")
            return
        self._inflight = None
        if self._scope == "start":
            self._on_startup_reply(sent, response, now)
        elif sent.code == "Q":
            self._on_query_reply(response, now)
        elif not response.answers(sent):
            self._protocol_error(now, f"reply {response} does not answer {sent}")
        elif sent is self._command:
            self._on_command_ack(response, now)
        else:
            self._on_plain_reply(sent, response)

    def _on_startup_reply(self, sent: Request, response: Response, now: float) -> None:
        hs = self._hs
        if sent.code == "S":
            if not response.answers(sent) or not isinstance(response, Accepted):
                self._send(sent, now)  # not the answer to what we asked: ask again, no penalty
                return
            self.drop_outs = 0
            value = response.number
            if hs.stage < 3:
                wanted = {v[hs.stage] for v in self.accepted if list(v[: hs.stage]) == hs.version}
                if value not in wanted:
                    hs.retries -= 1
                    if hs.retries <= 0:
                        got = ".".join(str(v) for v in [*hs.version, value])
                        self._version_mismatch(f"MMU firmware {got}… is not one of "
                                               f"{', '.join('.'.join(map(str, v)) for v in sorted(self.accepted))}")
                        return
                    self._send(sent, now)
                    return
                hs.version.append(value)
                hs.stage += 1
                self._send(Version(hs.stage), now)
                return
            major, minor, revision = hs.version
            self.version = codes.FirmwareVersion(major, minor, revision, value)
            self._startup = deque(Write(a, v) for a, v in self.init_registers)
            self._fsensor_reported = self.fsensor
            self._startup.append(FSensorState(self.fsensor))
            self._startup.append(Query(0))
            self._send(self._startup.popleft(), now)
            return
        if sent.code == "Q":
            self._scope = "idle"
            self._on_query_reply(response, now)
            self._pump(now)
            return
        self._pump(now)  # W and f replies are not checked during start-up

    def _on_query_reply(self, response: Response, now: float) -> None:
        code = response.request_code
        kind = response.param
        self.status = replace(self.status, command=response.command, kind=kind, value=response.number)
        command = self._command
        matches = command is not None and self._command_sent and response.answers(command)
        if self._scope == "idle":
            if code in BUSY_CODES and kind != "F":
                if command is not None and not self._command_sent:
                    self._queue_reads(False)  # ours goes out next; the MMU answers it with R while busy
                    return
                if not matches:
                    command = self._command = make_request(code, response.request_value)
                    self._command_sent = True
                    matches = True
                self._scope = "command"
            elif code in BUSY_CODES and matches:
                self._scope = "command"
            elif code == "X":
                if kind == "F" and command is not None and self._command_sent:
                    self._interrupted(response)
                elif kind == "P":
                    self._progress(response.number)
                elif kind == "E":
                    self._error(response.number)
                elif kind == "B":
                    self._events.append(ButtonPushed(response.command, response.number))
                self._queue_reads(False)
                return
            elif code not in BUSY_CODES:
                self._protocol_error(now, f"unexpected Q0 reply {response}")
                return
            else:
                self._queue_reads(False)
                return
        # command scope
        if isinstance(response, Finished):
            if matches:
                self._finished(response)
            else:
                self._interrupted(response)
        elif not matches:
            if command is not None and not self._command_sent:
                self._queue_reads(True)  # still ours to send; the reply is about an older command
                return
            self._protocol_error(now, f"Q0 reply {response} is about another command than {command}")
            return
        elif isinstance(response, Processing):
            self._progress(response.number)
        elif isinstance(response, CommandError):
            self._error(response.number)
        elif isinstance(response, ButtonPressed):
            self._events.append(ButtonPushed(response.command, response.number))
        self._queue_reads(True)

    def _progress(self, code: int) -> None:
        command = self.status.command
        if self._last_report != ("P", code):
            self._last_report = ("P", code)
            self._retry_pending = False
            self._events.append(ProgressChanged(command, code))
        if self.fsensor_mode == "auto":
            if code == codes.Progress.FEEDING_TO_FSENSOR:
                self.fsensor = int(codes.FSensor.AT_FSENSOR)
            elif code == codes.Progress.UNLOADING_TO_FINDA:
                self.fsensor = int(codes.FSensor.NOT_PRESENT)

    def _error(self, code: int) -> None:
        if self._last_report == ("E", code) and not self._retry_acked:
            return
        self._last_report = ("E", code)
        self._retry_acked = False
        info = describe_error(code)
        auto = info.retryable and self._retries_left > 0 and self._command is not None
        if auto and not self._retry_pending:
            self._retry_pending = True
            self._planned.appendleft(ButtonPress(int(codes.Button.MIDDLE)))
        self._events.append(ErrorRaised(self.status.command, code, info, auto, self._retries_left))

    def _finished(self, response: Finished) -> None:
        self._events.append(CommandFinished(response.command, response.number))
        self._command = None
        self._command_sent = False
        self._retries_left = self.auto_retries
        self._scope = "idle"

    def _interrupted(self, response: Response) -> None:
        command = self._command
        self._command = None
        self._command_sent = False
        self._scope = "idle"
        self._events.append(CommandInterrupted(str(command) if command else "", response.command))

    def _on_command_ack(self, response: Response, now: float) -> None:
        if isinstance(response, Accepted):
            return
        if isinstance(response, Rejected):
            self._rejects += 1
            if self._rejects >= REJECT_LIMIT:
                command = self._command
                self._command = None
                self._command_sent = False
                self._scope = "idle"
                self._events.append(CommandRejected(str(command), self._rejects))
                return
            assert self._command is not None
            if self._rejects <= IMMEDIATE_RESENDS:
                self._send(self._command, now)
            else:
                self._command_sent = False
                self._resend_at = now + self.heartbeat
            return
        self._protocol_error(now, f"unexpected reply {response} to a command")

    def _on_plain_reply(self, sent: Request, response: Response) -> None:
        if sent.code == "R":
            value = response.number if isinstance(response, Accepted) else None
            if self._inflight_poll:
                if value is not None:
                    self._reads[sent.value] = value
                if sent.value == POLL_REGISTERS[-1]:
                    self._status_complete()
                return
            self._events.append(RegisterRead(sent.value, value))
        elif sent.code == "W":
            self._events.append(RegisterWritten(sent.value, sent.value2, isinstance(response, Accepted)))
        elif sent.code == "B" and isinstance(response, Accepted):
            if sent.value == codes.Button.MIDDLE and self._retry_pending and self._retries_left > 0:
                self._retries_left -= 1
                self._retry_pending = False
                self._retry_acked = True
            self._events.append(ButtonSent(sent.value))

    def _status_complete(self) -> None:
        r = self._reads
        self.status = replace(self.status, finda=bool(r.get(0x08)), selector=r.get(0x1B), idler=r.get(0x1C),
                              drive_errors=r.get(0x04), pulley=r.get(0x1A))
        if not self._announced and self.version is not None:
            self._announced = True
            self.link = Link.READY
            self._events.append(LinkUp(self.version))
        self._events.append(StatusUpdated(self.status))
