"""A da Vinci printer on the wire: serial framing on a pty, Wi-Fi framing on TCP 9100, or in-process (`sim://xyz`).

The link decides the framing (`$` terminators, config acks, action progress lines), as on the real machines;
the printer itself (printer.py) is shared by every connection, so a client may poll on one connection while
another uploads.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from fabwire.errors import InputError, LinkClosed, excerpt
from fabwire.simspeed import checked_speed
from fabwire.transport import Transport, register_simulator, spawn_in_process
from fabwire.xyz import protocol as p
from fabwire.xyz.personas import personality
from fabwire.xyz.printer import FileVerdict, Printer
from fabwire.xyz.protocol import Block, DeviceDecoder, Garbage, Link, Received, UploadStalled

log = logging.getLogger(__name__)

PC_COMMUNICATION_ERROR = 0x0201
BUSY_REPLY = 3
BAD_COMMAND_REPLY = 1


COMMAND_HISTORY = 1000
"""Commands remembered for tests and users (the oldest are forgotten)."""
UPLOAD_HISTORY = 8
"""Finished uploads remembered; an abandoned one keeps its size, not its bytes."""
MAX_UPLOAD = 256 << 20
"""Largest declared upload taken (bytes); a larger one is refused before any block is buffered."""


@dataclass
class UploadRecord:
    """What a client sent: kept so tests and users can compare it with the source file."""

    name: str
    declared: int
    data: bytes
    firmware: bool
    crc_checked: int
    complete: bool
    received: int = 0
    """Bytes that arrived (an abandoned upload's data is dropped, so this is all that is left of it)."""


@dataclass
class _Session:
    command: p.Upload | p.FirmwareUpload
    data: bytearray
    next_index: int = 0
    crc_checked: int = 0


class XYZSimulator:
    """One printer, served on any number of links."""

    def __init__(
        self, model: str = "dv1MW0A000", *, speed: float = 1.0, faults: tuple[str, ...] = (),
        state_file: Path | None = None, store: Path | None = None, strict: bool = False,
        link: Link | None = None, gap: float = 0.03, upload_idle: float = 30.0, serial: str | None = None,
        clock: Callable[[], float] = time.monotonic, close_after_reply: bool | None = None, control: bool = True,
        max_upload: int = MAX_UPLOAD,
    ) -> None:
        speed = checked_speed(speed)
        self.printer = Printer(personality(model, serial=serial), state_file=state_file, faults=faults)
        self.speed = speed
        self.store = store
        self.strict = strict
        self.link = link
        self.gap = gap
        self.upload_idle = upload_idle
        self.clock = clock
        self.control = control
        """Answer `XYZv3/simctl=…` (in-band fault triggers); off, it is refused like any unknown command."""
        hangs_up = self.printer.persona.model.model_number == "dvF110B000"
        self.close_after_reply = hangs_up if close_after_reply is None else close_after_reply
        """Close a TCP connection after each reply, as the da Vinci 1.1 Plus does."""
        self._t0 = clock()
        self.max_upload = max_upload
        self.uploads: deque[UploadRecord] = deque(maxlen=UPLOAD_HISTORY)
        self.completed_uploads = 0
        self.commands: deque[str] = deque(maxlen=COMMAND_HISTORY)
        self.uploading: object | None = None
        """The connection whose upload is under way: a printer takes one file at a time."""
        self.outbox_owner: object | None = None
        """The connection that started the running flow: only it is sent the flow's later progress lines."""
        self.connections = 0
        self.busy_replies = 0
        if store is not None:
            try:
                store.mkdir(parents=True, exist_ok=True)
            except (OSError, ValueError) as exc:  # ValueError: a NUL in the name
                raise InputError(f"cannot keep received files in {excerpt(str(store), 60)}: "
                                 f"{getattr(exc, 'strerror', None) or exc}") from None

    # ------------------------------------------------------------------------------------- control API

    def inject(self, fault: str, on: bool = True) -> None:
        """Turn a fault on or off while running (see printer.FAULTS)."""
        self.printer.inject(fault, on)

    def control_command(self, op: str) -> str:
        """The in-band control plane (`XYZv3/simctl=…`): `fault:<name>:on|off`, `clear`, `faults`.

        Returns the reply line `simctl:<faults now active, + separated>` or `simctl:E<reason>`."""
        if op == "clear":
            for fault in list(self.printer.faults):
                self.printer.inject(fault, False)
        elif op.startswith("fault:"):
            _, name, state = op.split(":")
            try:
                self.inject(name, state == "on")
            except InputError as exc:
                return f"simctl:E {exc}"
        return "simctl:" + "+".join(sorted(self.printer.faults))

    def printer_time(self) -> float:
        return (self.clock() - self._t0) * self.speed

    def sync(self) -> None:
        self.printer.advance(self.printer_time())

    def link_for(self, transport: Transport) -> Link:
        if self.link is not None:
            return self.link
        return Link.WIFI if transport.url.startswith("tcp://") else Link.SERIAL

    def received(self, name: str) -> bytes | None:
        """The last complete upload stored under `name`."""
        for record in reversed(self.uploads):
            if record.name == name and record.complete:
                return record.data
        return None

    async def serve(self, transport: Transport) -> None:
        """Run the device side of one connection until the peer goes away."""
        self.connections += 1
        connection = _Connection(self, transport, self.link_for(transport))
        try:
            await connection.run()
        except LinkClosed as exc:  # this side hung up (1.1 Plus style, or an injected link drop)
            log.info("connection closed: %s", exc)
        finally:
            self.connections -= 1
            if self.outbox_owner is connection:
                self.outbox_owner = None


class _Connection:
    def __init__(self, sim: XYZSimulator, transport: Transport, link: Link) -> None:
        self.sim = sim
        self.printer = sim.printer
        self.transport = transport
        self.link = link
        self.decoder = DeviceDecoder(gap=sim.gap, upload_idle=sim.upload_idle)
        self.session: _Session | None = None

    def _wait(self) -> float | None:
        deadline = self.decoder.next_deadline()
        wait = None if deadline is None else max(0.0, deadline - self.sim.clock())
        if self.link is Link.SERIAL and (self.printer.flow or self.printer.job or self.printer.outbox):
            wait = 0.05 if wait is None else min(wait, 0.05)
        return wait

    async def run(self) -> None:
        while True:
            wait = self._wait()
            try:
                if wait is None:
                    data = await self.transport.read()
                else:
                    async with asyncio.timeout(wait):
                        data = await self.transport.read()
            except TimeoutError:
                await self._guarded(self.decoder.poll(self.sim.clock()))
                continue
            except LinkClosed:
                # Execute what arrived before the close (fire-and-forget clients), then stop.
                with contextlib.suppress(LinkClosed):
                    await self._guarded(self.decoder.eof(self.sim.clock()), closing=True)
                self._abandon("the link closed")
                return
            await self._guarded(self.decoder.feed(data, self.sim.clock()))

    async def _guarded(self, events: list[p.DeviceEvent], *, closing: bool = False) -> None:
        """Handle events; a fault in handling one client's bytes is logged in one line, and the printer goes on
        answering (a dead handler would leave a serial printer deaf for everyone)."""
        try:
            await self._handle(events, closing=closing)
        except (LinkClosed, asyncio.CancelledError):
            raise
        except Exception as exc:  # the boundary where a client's bytes meet the device
            log.warning("ignored what a client sent: %s: %s", type(exc).__name__, str(exc)[:200])
            self._abandon("the upload could not be handled")

    async def _handle(self, events: list[p.DeviceEvent], *, closing: bool = False) -> None:
        out = bytearray()
        for event in events:
            if isinstance(event, Block):
                out += self._block(event)
            elif isinstance(event, Received):
                self.sim.commands.append(event.command.body)
                out += await self._command(event.command)
            elif isinstance(event, UploadStalled):
                self._abandon(f"no data for {self.sim.upload_idle:g} s")
            elif isinstance(event, Garbage) and self.session is not None:
                self._fail_upload("an upload block larger than the printer takes")
                out += p.reply_lines([p.error_line(BAD_COMMAND_REPLY)], dollar=False)
            elif isinstance(event, Garbage) and self.link is Link.SERIAL and event.raw.strip():
                out += p.reply_lines([p.error_line(BAD_COMMAND_REPLY)], dollar=False)
        self.sim.sync()
        if self.printer.outbox and self.sim.outbox_owner in (None, self):
            if self.link is Link.SERIAL:  # a flow's later lines go to the client that started it, nobody else
                for line in self.printer.outbox:
                    out += p.reply_lines([line], dollar=True)
            self.printer.outbox.clear()
        if out and not closing:
            await self._write(bytes(out))
        hang_up = self.sim.close_after_reply and self.link is Link.WIFI and self.session is None
        if hang_up and any(isinstance(e, Received) for e in events) and not self.decoder.uploading:
            await self.transport.close()
            raise LinkClosed("closed after the reply (1.1 Plus behaviour)")

    async def _write(self, data: bytes) -> None:
        if self.link is Link.SERIAL:
            # Nobody may be reading a pty; never let a full buffer freeze the printer.
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(5):
                    await self.transport.write(data)
        else:
            await self.transport.write(data)

    # --------------------------------------------------------------------------------------- commands

    async def _command(self, command: p.Command) -> bytes:
        serial = self.link is Link.SERIAL
        self.sim.sync()
        if isinstance(command, p.Upload | p.FirmwareUpload):
            return self._start_upload(command)
        if isinstance(command, p.UploadDidFinish):
            return await self._finish_upload()
        if isinstance(command, p.Query):
            return self._query(command)
        if isinstance(command, p.SimControl) and self.sim.control:
            return p.reply_lines([self.sim.control_command(command.op)], dollar=True)
        if isinstance(command, p.UnknownCommand | p.SimControl):
            return p.reply_lines([p.error_line(BAD_COMMAND_REPLY)], dollar=False) if serial else b""
        refusal = self.printer.refusal(command)
        if refusal is not None:
            answered = serial or command.expects(self.link) is not p.Expect.NOTHING
            return p.reply_lines([p.error_line(refusal)], dollar=False) if answered else b""
        if isinstance(command, p.Flow | p.Home | p.Jog | p.PrintControl) and self.sim.outbox_owner is not self:
            self.printer.outbox.clear()  # what is left belongs to the flow another client started
            self.sim.outbox_owner = self
        lines = self.printer.execute(command)
        expect = command.expects(self.link)
        if expect is p.Expect.NOTHING or not lines:
            return b""
        if expect is p.Expect.LINE:
            return p.reply_lines(lines[:1], dollar=False)
        return p.reply_lines(lines, dollar=True)

    def _query(self, query: p.Query) -> bytes:
        busy = self.printer.busy_reply()
        if busy is not None:
            self.sim.busy_replies += 1
            return p.reply_lines([p.error_line(busy)], dollar=False)
        status = self.printer.status(scan="W" in query.wanted)
        if not query.wanted:
            return p.reply_lines(status.lines(), dollar=True)
        lines = status.lines("".join(sorted(query.wanted)))
        return p.reply_lines(lines, dollar=self.link is Link.SERIAL)

    def _ok(self, *, command_ack: bool = False) -> bytes:
        return b"ok \n" if command_ack and self.link is Link.WIFI else b"ok\n"

    # ---------------------------------------------------------------------------------------- uploads

    def _start_upload(self, command: p.Upload | p.FirmwareUpload) -> bytes:
        refusal = self.printer.refusal(command)
        if refusal is None and command.size > self.sim.max_upload:
            log.info("upload of %s refused: %d bytes declared, the printer takes at most %d",
                     command.name, command.size, self.sim.max_upload)
            refusal = BAD_COMMAND_REPLY
        elif refusal is None and self.sim.uploading not in (None, self):
            log.info("upload of %s refused: another client's upload is under way", command.name)
            refusal = BUSY_REPLY
        if refusal is not None:
            self.decoder.cancel_upload()
            return p.reply_lines([p.error_line(refusal)], dollar=False)
        self._abandon("a new upload started")
        self.session = _Session(command, bytearray())
        self.sim.uploading = self
        return self._ok(command_ack=True)

    def _block(self, block: Block) -> bytes:
        session = self.session
        if session is None:
            return b""
        if block.index != session.next_index:
            self._fail_upload(f"block {block.index} arrived, expected {session.next_index}")
            return p.reply_lines([p.error_line(BAD_COMMAND_REPLY)], dollar=False)
        if self.sim.strict and (block.trailer == 0 or not block.crc_ok):
            self._fail_upload(f"block {block.index} CRC-32 does not match")
            return p.reply_lines([p.error_line(BAD_COMMAND_REPLY)], dollar=False)
        session.data += block.data
        session.next_index += 1
        session.crc_checked += block.trailer != 0
        if "link-drop" in self.printer.faults and len(session.data) * 2 >= session.command.size:
            self._abandon("link dropped on demand")
            raise LinkClosed("link dropped mid-upload (injected fault)")
        return self._ok()

    def _fail_upload(self, why: str) -> None:
        log.info("upload refused: %s", why)
        self.decoder.cancel_upload()
        self._abandon(why)
        if PC_COMMUNICATION_ERROR not in self.printer.errors:
            self.printer.errors.append(PC_COMMUNICATION_ERROR)

    def _abandon(self, why: str) -> None:
        session, self.session = self.session, None
        if self.sim.uploading is self:
            self.sim.uploading = None
        if session is not None:
            log.info("upload of %s abandoned after %d bytes: %s", session.command.name, len(session.data), why)
            self.sim.uploads.append(UploadRecord(session.command.name, session.command.size, b"",
                                                 isinstance(session.command, p.FirmwareUpload),
                                                 session.crc_checked, complete=False, received=len(session.data)))

    async def _finish_upload(self) -> bytes:
        session, self.session = self.session, None
        if self.sim.uploading is self:
            self.sim.uploading = None
        reply = b"ok\n" + (b"ok\n" if self.link is Link.WIFI else b"")
        if session is None:
            return reply
        data = bytes(session.data)
        firmware = isinstance(session.command, p.FirmwareUpload)
        record = UploadRecord(session.command.name, session.command.size, data, firmware, session.crc_checked,
                              complete=len(data) == session.command.size, received=len(data))
        self.sim.uploads.append(record)
        self.sim.completed_uploads += record.complete
        self._store(record)
        if firmware:
            self.printer.firmware_images.append(data)
            return reply
        verdict = await asyncio.to_thread(self.printer.check_file, data) if record.complete else None
        if verdict is None:
            verdict = FileVerdict(False, reason=f"short upload: {len(data)} of {session.command.size} bytes")
        self.sim.sync()
        self.printer.start_job(session.command.name, data, verdict)
        return reply

    def _store(self, record: UploadRecord) -> None:
        if self.sim.store is None:
            return
        name = Path(record.name).name or "upload.bin"
        with contextlib.suppress(OSError):
            (self.sim.store / name).write_bytes(record.data)


def simulator_from_options(options: dict[str, str]) -> XYZSimulator:
    """Build a simulator from `sim://xyz?model=…&speed=…&link=serial|wifi&fault=…&strict=1&control=0`, read by the
    one table of simulator options (`fabwire.transport.simaddress.XYZ_OPTIONS`)."""
    from fabwire.transport.simaddress import read_options

    given = read_options("xyz", options)
    return XYZSimulator(
        given.get("model", "dv1MW0A000"), speed=given.get("speed", 1.0), faults=given.get("fault", ()),
        link=Link(given.get("link", "serial")), strict=given.get("strict", False),
        state_file=Path(given["state"]) if "state" in given else None,
        store=Path(given["store"]) if "store" in given else None, serial=given.get("serial"),
        control=given.get("control", True),
    )


async def _factory(options: dict[str, str]) -> Transport:
    return await spawn_in_process("xyz", simulator_from_options(options).serve)


register_simulator("xyz", _factory)
