"""The printer's side of the MMU3 link, as Prusa's printer firmware runs it — sans-IO, time as an input.

`HostLogic` does the handshake (S0-S3 with a version check, init register writes, `f`), the Q0 heartbeat after
1 s of silence with five register reads after each reply, the 2 s link timeout, the drop-out filter, `f` updates
and bounded automatic Retry (reference §6). It emits typed events (`fabwire.mmu.events`); `fabwire.mmu.client`
turns them into awaitable operations.

Where the printer re-handshakes after every garbled reply or timeout, this host resynchronises: it waits for a
short quiet gap, drains its decoder and asks again, keeping the handshake stage and the command it tracks; only
a run of drop-outs with no good reply (as when the MMU reboots) restarts the handshake. A command whose
acknowledgement was lost, or that the MMU rejected as busy, is looked up with Q0 first: when the MMU reports
it running, the host adopts it instead of sending it again.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import replace
from typing import Literal

from fabwire.errors import LocalProtocolError
from fabwire.mmu import codes
from fabwire.mmu.errors import describe_error
from fabwire.mmu.events import (
    ButtonPushed,
    ButtonSent,
    CommandFinished,
    CommandInterrupted,
    CommandRejected,
    ErrorRaised,
    HostEvent,
    Link,
    LinkFailed,
    LinkLost,
    LinkUp,
    ProgressChanged,
    RegisterRead,
    RegisterWritten,
    Status,
    StatusUpdated,
)
from fabwire.mmu.handshake import Handshake
from fabwire.mmu.linkrules import (
    AUTO_FSENSOR_OFF,
    AUTO_FSENSOR_ON,
    AUTO_RETRIES,
    BUSY_CODES,
    DROP_OUT_LIMIT,
    HEARTBEAT,
    IMMEDIATE_RESENDS,
    INIT_REGISTERS,
    LINK_TIMEOUT,
    POLL_REGISTERS,
    REJECT_LIMIT,
    REPLY_LIMIT,
    RESTART_AFTER,
    RESYNC_GAP,
    SILENT_RESTART,
    SUPPORTED,
    FSensorMode,
)
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
from fabwire.mmu.timing import TimingCheck

__all__ = [  # the events are re-exported: callers need them with the logic
    "HEARTBEAT", "INIT_REGISTERS", "LINK_TIMEOUT", "POLL_REGISTERS", "SUPPORTED", "ButtonPushed", "ButtonSent",
    "CommandFinished", "CommandInterrupted", "CommandRejected", "ErrorRaised", "FSensorMode", "HostEvent",
    "HostLogic", "Link", "LinkFailed", "LinkLost", "LinkUp", "ProgressChanged", "RegisterRead", "RegisterWritten",
    "Status", "StatusUpdated"
]

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
        self.resync_gap = RESYNC_GAP / time_scale
        self.auto_retries = auto_retries
        self.link = Link.CONNECTING
        self.version: codes.FirmwareVersion | None = None
        self.status = Status()
        self.drop_outs = 0
        """Drop-outs since the last good reply (the printer's DropOutFilter)."""
        self.timing = TimingCheck(time_scale)
        self.last_drop_out = ""
        self._now = 0.0
        self._decoder = ResponseDecoder()
        self._out = bytearray()
        self._events: list[HostEvent] = []
        self._inflight: Request | None = None
        self._lost: Request | None = None
        self._last_activity = 0.0
        self._sent_at = 0.0
        self._silent = 0
        self._scope: Literal["start", "idle", "command", "resync", "stopped"] = "stopped"
        self._resume: Literal["start", "idle", "command"] = "start"
        self._hs = Handshake(self.accepted)
        self._startup: deque[Request] = deque()
        self._followups: deque[Request] = deque()
        self._planned: deque[Request] = deque()
        self._command: Request | None = None
        self._command_sent = self._own = False
        """`_own`: sent by this host — only then does it press Retry by itself (not on someone else's error)."""
        self._last_sent: Request | None = None
        self._command_acked = False  # the MMU took it: it said A, or Q0 showed it running
        self._probe = False  # ask Q0 before (re)sending the command: the MMU may already be running it
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
        if self._scope == "resync":
            return self._last_activity + (self.resync_gap if self.version is not None else self.heartbeat)
        if self._inflight is not None:
            return min(self._last_activity + self.link_timeout, self._sent_at + REPLY_LIMIT * self.link_timeout)
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

    @property
    def retrying(self) -> bool:
        """This host's automatic Retry for the reported error is on its way."""
        return self._retry_pending

    # ----------------------------------------------------------------------------------------- inputs

    def start(self, now: float) -> None:
        """(Re)start the link: handshake from S0."""
        self._restart(now)

    def receive(self, data: bytes, now: float) -> None:
        if not data or self._scope == "stopped":
            return
        self._last_activity = self._now = now
        self._silent = 0
        if self._scope == "resync":
            return  # the rest of a garbled burst: drained when the line goes quiet
        for event in self._decoder.feed(data):
            if isinstance(event, DecodeError):
                # firmware 1.x answers the handshake 'ok'; once the version is known the two letters are noise
                if b"ok" in data and self.version is None:
                    self._version_mismatch("the MMU answered 'ok': firmware 1.x")
                else:
                    self._protocol_error(now, event.reason)
                return
            self._on_response(event, now)
            if self._scope in ("resync", "stopped"):
                return
        self._pump(now)

    def handle_timer(self, now: float) -> None:
        if self._scope == "stopped":
            return
        if self._scope == "resync":
            deadline = self.next_deadline()
            if deadline is not None and now >= deadline:
                self._recover(now)
            return
        if self._inflight is not None:
            silent = now >= self._last_activity + self.link_timeout
            if silent or now >= self._sent_at + REPLY_LIMIT * self.link_timeout:
                self._lost, self._inflight = self._inflight, None
                self._resume = self._scope
                self._silent += silent
                self._drop_out(f"timeout: no reply within {self.link_timeout:.3g} s" if silent else
                               f"timeout: no complete reply within {REPLY_LIMIT * self.link_timeout:.3g} s")
                self._recover(now)
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
        self._command_sent = self._command_acked = False
        self._own = True
        self._probe = False
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

    def reset(self, now: float, erase: bool = False) -> None:
        """Reboot the MMU with X0 (X2a also erases its EEPROM); no reply comes, so the link times out and
        re-handshakes."""
        self._command = None
        self._followups.clear()
        self._planned.clear()
        self._planned.appendleft(Reset(42 if erase else 0))
        self._pump(now)

    def abandon(self) -> None:
        """Stop tracking the current command (the MMU may still be running it; the next Q0 adopts it again)."""
        self._command = None
        self._command_sent = False
        if self._scope == "command":
            self._scope = "idle"

    # ----------------------------------------------------------------------------------------- link

    def _send(self, request: Request, now: float, poll: bool = False) -> None:
        self._out += encode_request(request)
        self._inflight = request
        self._inflight_poll = poll
        self._last_activity = self._sent_at = now
        if request.code == "f":
            self._fsensor_reported = request.value

    def _restart(self, now: float) -> None:
        self._decoder.reset()
        self._inflight = None
        self._lost = None
        self._followups.clear()
        self._hs = Handshake(self.accepted)
        self._scope = "start"
        self.link = Link.CONNECTING if self.version is None else Link.RESTARTING
        self._announced = False
        self._unsent(self._command is not None and not self._command_acked)
        self._send(Version(0), now)

    def _unsent(self, lost: bool) -> None:
        """The command may never have reached the MMU: look it up with Q0 first, then send it again."""
        if lost:
            self._command_sent = False
            self._probe = True

    def _drop_out(self, reason: str) -> None:
        self.last_drop_out = reason
        self.drop_outs += 1
        self._events.append(LinkLost(reason, self.drop_outs))
        if self.drop_outs % DROP_OUT_LIMIT == 0:
            code = 0x802D if reason.startswith("protocol") else 0x802E
            self._events.append(LinkFailed(code, describe_error(code), reason))

    def _protocol_error(self, now: float, reason: str) -> None:
        self._lost, self._inflight = self._inflight, None
        if self._scope != "resync":
            self._resume = self._scope  # type: ignore[assignment]
        self._drop_out(f"protocol error: {reason}")
        self._scope = "resync"
        self._last_activity = now

    def _recover(self, now: float) -> None:
        """After a drop-out: drain, then ask again where we were — or start over after a run of them."""
        self._decoder.reset()
        lost, self._lost = self._lost, None
        self._unsent(lost is not None and lost is self._command)
        if lost is not None and self._resume != "start" and (
                (lost.code in "RW" and not self._inflight_poll) or (lost.code == "B" and not self._retry_pending)):
            self._planned.appendleft(lost)  # asked for by the caller: ask again, after a restart too
        rebooting = self._silent >= SILENT_RESTART or (lost is not None and lost.code == "X")
        if (self.version is None and self._resume != "start") or self.drop_outs >= RESTART_AFTER or rebooting:
            self._restart(now)
            return
        self._scope = self._resume
        self._followups.clear()  # the next heartbeat polls again
        if lost is not None:
            if self._scope == "start":
                self._send(lost, now)
                return
            if lost is self._command:
                self._unsent(True)
            elif lost.code == "f":
                self._fsensor_reported = None
        if lost is not None and (lost.code == "Q" or self._scope == "command"):
            self._send(Query(0), now)  # where is the MMU now?
            return
        self._pump(now)

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
            elif now >= self._last_activity + self.heartbeat:
                self._restart(now)  # nothing left to ask (its reply was lost between steps): start over
            return
        if self._planned and self._planned[0].code == "X":
            self._send(self._planned.popleft(), now)
            return
        if self._scope == "command" and self._fsensor_reported != self.fsensor:
            self._send(FSensorState(self.fsensor), now)
            return
        if self._planned and self._planned[0].code == "B":
            self._send(self._planned.popleft(), now)  # a button answers an error: before the status reads
            return
        if self._followups:
            self._send(self._followups.popleft(), now, poll=True)
            return
        if self._command is not None and not self._command_sent and now >= self._resend_at:
            if self._probe:
                self._send(Query(0), now)
                return
            self._scope = "command"
            self._command_sent = True
            self._last_sent = self._command
            self._send(self._command, now)
            return
        if self._planned:
            self._send(self._planned.popleft(), now)
            return
        if now >= self._last_activity + self.heartbeat:
            self._send(Query(0), now)

    def _queue_reads(self, with_fsensor: bool) -> None:
        if with_fsensor:
            self._followups.append(FSensorState(self.fsensor))
        self._followups.extend(Read(a) for a in POLL_REGISTERS)

    # ----------------------------------------------------------------------------------------- replies

    def _on_response(self, response: Response, now: float) -> None:
        sent = self._inflight
        if sent is None:
            self._protocol_error(now, "reply with no request outstanding")
            return
        self._inflight = None
        if (sent.code == "Q") != (response.param in "PEFB"):
            self._protocol_error(now, f"reply {response} does not answer {sent}")
            return
        if self._scope == "start":
            self._on_startup_reply(sent, response, now)
            return
        if sent.code == "Q":
            self.drop_outs = 0
            self._on_query_reply(response, now)
        elif not response.answers(sent):
            self._protocol_error(now, f"reply {response} does not answer {sent}")
        elif sent is self._command:
            self.drop_outs = 0
            self._on_command_ack(response, now)
        else:
            self.drop_outs = 0
            self._on_plain_reply(sent, response)

    def _on_startup_reply(self, sent: Request, response: Response, now: float) -> None:
        if sent.code == "S":
            if response.answers(sent) and isinstance(response, Accepted):
                self.drop_outs = 0
            step = self._hs.step(response)
            if isinstance(step, str):
                self._version_mismatch(step)
            elif isinstance(step, Version):
                self._send(step, now)  # the next stage, or the same one asked again
            else:
                self.version = step
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
        code, kind = response.request_code, response.param
        self.status = replace(self.status, command=response.command, kind=kind, value=response.number)
        command = self._command
        ours = command is not None and response.answers(command)
        running = kind in "PEB"
        if command is not None and not self._command_sent:
            self._probe = False
            if ours and running:
                self._command_sent = self._command_acked = True  # the MMU runs it already (an earlier send)
                self._scope = "command"
            else:
                self._scope = "idle"
                self._queue_reads(False)  # ours goes out next
                return
        elif command is None:
            if code in BUSY_CODES and running:
                self._command = make_request(code, response.request_value)  # adopt what the MMU is doing
                self._command_sent = self._command_acked = True
                self._own = self._command == self._last_sent  # ours from before (given up on, or a restart)
                self._scope = "command"
            else:
                self._scope = "idle"
                if code == "X" or code in BUSY_CODES:
                    self._report(response)
                    self._queue_reads(False)
                else:
                    self._protocol_error(now, f"unexpected Q0 reply {response}")
                return
        elif not ours:
            self._interrupted(response)  # the MMU rebooted or runs something else: ours is gone
            self._queue_reads(False)
            return
        if isinstance(response, Finished):
            self._finished(response)
            self._queue_reads(False)
            return
        self._scope = "command"
        self._report(response)
        self._queue_reads(True)

    def _report(self, response: Response) -> None:
        if isinstance(response, Processing):
            self._progress(response.number)
        elif isinstance(response, CommandError):
            self._error(response.number)
        elif isinstance(response, ButtonPressed):
            self._events.append(ButtonPushed(response.command, response.number))
            if self._last_report is not None and self._last_report[0] == "E":
                # a press on the MMU while it shows its own error is the person's answer: the printer hands it back
                # (MK3 mmu2.cpp CheckUserInput, reference §5.3); at other times the printer ignores it
                self._planned.append(ButtonPress(response.number))

    def _progress(self, code: int) -> None:
        command = self.status.command
        if self._last_report != ("P", code):
            self._last_report = ("P", code)
            self._retry_pending = False
            self._events.append(ProgressChanged(command, code))
        if self.fsensor_mode == "auto":
            if code in AUTO_FSENSOR_ON:
                self.fsensor = int(codes.FSensor.AT_FSENSOR)
            elif code in AUTO_FSENSOR_OFF:
                self.fsensor = int(codes.FSensor.NOT_PRESENT)

    def _error(self, code: int) -> None:
        if self._last_report == ("E", code) and not self._retry_acked:
            middle = ButtonPress(int(codes.Button.MIDDLE))
            if self._retry_pending and middle not in self._planned and self._inflight != middle:
                self._planned.appendleft(middle)  # our Retry was lost on the line
            return
        self._last_report = ("E", code)
        self._retry_acked = False
        if self.fsensor_mode == "auto" and code == 0x8004:
            self.fsensor = int(codes.FSensor.NOT_PRESENT)  # the printer retracts to help the unload
        info = describe_error(code)
        auto = info.retryable and self._retries_left > 0 and self._command is not None and self._own
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
            self._command_acked = True
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
            self._command_sent = False
            self._probe = True  # busy — perhaps with ours, if an earlier send got through
            self._resend_at = now if self._rejects <= IMMEDIATE_RESENDS else now + self.heartbeat
            self._send(Query(0), now)
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
            self._last_report = None  # after a press, the same error again is news
            if sent.value == codes.Button.MIDDLE and self._retry_pending and self._retries_left > 0:
                self._retries_left -= 1
                self._retry_pending = False
                self._retry_acked = True
            self._events.append(ButtonSent(sent.value))

    def _status_complete(self) -> None:
        r = self._reads
        pulley = r.get(0x1A)
        if pulley is not None:
            pulley = codes.REGISTERS[0x1A].meant(pulley)  # the firmware's int32 millimetres, truncated to 16 bits
        self.status = replace(self.status, finda=bool(r.get(0x08)), selector=r.get(0x1B), idler=r.get(0x1C),
                              drive_errors=r.get(0x04), pulley=pulley)
        self.timing.observe(self._now, pulley)
        if not self._announced and self.version is not None:
            self._announced = True
            self.link = Link.READY
            self._events.append(LinkUp(self.version))
        self._events.append(StatusUpdated(self.status))
