"""`XYZPrinter`: status, printing and job control of a da Vinci over serial or Wi-Fi (its maintenance flows and
settings come from `maintenance`).

One command is in flight at a time; a background task reads the link so a lost connection is noticed at
once and stale replies are dropped before each command. A job counts as started or done only when the printer's
own status says so.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import re
import time
from collections import deque
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, BinaryIO, Self, TypeVar
from urllib.parse import parse_qsl, urlsplit

import msgspec

from fabwire.config import XYZSettings
from fabwire.devices import XYZ
from fabwire.errors import (
    DeviceBusy,
    DeviceError,
    InputError,
    LinkClosed,
    LinkError,
    LinkTimeout,
    PrintCancelled,
    RemoteProtocolError,
    excerpt,
)
from fabwire.opening import DeviceLink, DeviceTarget, Opening
from fabwire.transport import Transport, open_transport
from fabwire.transport.peers import name_peer, wrong_peer
from fabwire.xyz import protocol as p
from fabwire.xyz import userinput
from fabwire.xyz.codes import PRINT_STOP
from fabwire.xyz.maintenance import Maintenance
from fabwire.xyz.maintenance import StatusCallback as StatusCallback  # also the sync client's
from fabwire.xyz.models import PrinterModel
from fabwire.xyz.protocol import ActionStat, ErrorReply, Link, NoReply, Reply, ReplyReader
from fabwire.xyz.status import (
    CANCELLING,
    FILE_CHECK,
    FILE_REJECTED,
    IDLE,
    PAUSED,
    PRINT_DONE,
    PRINTING,
    ErrorWord,
    Status,
)

if TYPE_CHECKING:
    from fabwire.xyz.sync import SyncXYZPrinter

log = logging.getLogger("fabwire.xyz")
T = TypeVar("T")
UploadProgress = Callable[[int, int], None]

REPLY_ERRORS = {
    0: "the printer refused the command",
    1: "the printer refused the command",
    3: "the printer is busy",
    4: "the printer is busy finishing a job",
    7: "the printer is busy finishing a job",
}
TRANSIENT_RETRIES = 20
NOT_A_PRINTER = "an XYZv3 printer"
FILE_CHECK_LIMIT = 120.0  # printer seconds of "checking file" (9520) before a print is stuck; real checks take seconds
CHECKING_NOTE_EVERY = 15.0  # seconds between "still checking the file" notes
FINISHED_PERCENT = 99
"""Progress from which a print that goes idle counts as finished: the firmware may show idle for a moment between
printing and 9509 (reference §3.2), and rounds its percentage."""
UPLOAD_READ_BUFFER = 1 << 20
"""Bytes read from a file being uploaded at a time (it travels in blocks of a few KiB: one read per block would
be a system call each)."""
HANGS_UP = frozenset({"dvF110B000"})
"""Models that close the TCP connection after every reply."""
_FIRMWARE_HEADER = re.compile(rb"([A-Za-z0-9]{10})\+([0-9][0-9A-Za-z.]*)")


def link_for(transport: Transport) -> Link:
    """TCP is Wi-Fi framing, everything else serial; `sim://xyz?link=wifi` says so itself."""
    url = transport.url
    if url.startswith("tcp://"):
        return Link.WIFI
    if url.startswith("sim://"):
        options = dict(parse_qsl(urlsplit(url).query))
        return Link.WIFI if options.get("link") == "wifi" else Link.SERIAL
    return Link.SERIAL


def link_for_address(address: str) -> Link | None:
    """`sim://xyz?link=wifi` names its framing; other addresses leave it to the transport."""
    if address.startswith("sim://"):
        return Link.WIFI if dict(parse_qsl(urlsplit(address).query)).get("link") == "wifi" else Link.SERIAL
    return None


def time_scale_for(address: str) -> float:
    """Printer seconds per wall second: N for an in-process `sim://xyz?speed=N`, else 1 (the wire does not tell)."""
    speed = dict(parse_qsl(urlsplit(address).query)).get("speed", "1") if address.startswith("sim://") else "1"
    return float(speed) if re.fullmatch(r"\d+(\.\d*)?", speed) and float(speed) > 0 else 1.0


def _release(waiter: asyncio.Future[None] | None) -> None:
    if waiter is not None and not waiter.done():
        waiter.set_result(None)


class UploadResult(msgspec.Struct, frozen=True):
    name: str
    size: int
    blocks: int
    seconds: float


class XYZPrinter(Maintenance):
    """Async client for one printer on an open transport: status, printing and job control here, the maintenance
    flows and settings from `Maintenance`."""

    poll_interval = 0.25
    upload_window = 8
    """Blocks in flight on Wi-Fi (TCP buffers them; miniMover sends every block without waiting).
    Serial links wait for each block's ack, as every serial client does."""

    def __init__(self, transport: Transport, *, link: Link | None = None, timeout: float = 5.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.transport = transport
        self.link = link or link_for(transport)
        self.timeout = timeout
        self.clock = clock
        self.reader = ReplyReader(self.link)
        self.time_scale = time_scale_for(transport.url)  # printer seconds per wall second
        self.last_status: Status = Status()
        self.stats: deque[ActionStat] = deque(maxlen=200)
        self._waiter: asyncio.Future[None] | None = None
        """What a request waits on while the reader task reads its reply (see `_wait_for_pump`)."""
        self._lock = asyncio.Lock()
        self._lost: LinkError | None = None
        self._pump_task = asyncio.get_running_loop().create_task(self._pump(), name="xyz-reader")
        self.address: str | None = None
        """Set by `connect`: lets a Wi-Fi client reconnect when the printer closes the connection."""
        self.reopen: Callable[[], Awaitable[Transport]] | None = None
        """Set by `open`: opens a new link to the same address, wrapped like the first (trace, faults)."""
        self.settings = XYZSettings()
        self.per_command = False
        """Open a new connection for every command (the 1.1 Plus hangs up after each reply)."""
        self.reconnects = 0  # links opened again: a command sent just before one may never have arrived
        self._heard = False
        """Some reply made sense: the peer speaks XYZv3 (until then, stray text means a wrong device)."""

    @classmethod
    def open(cls, target: DeviceTarget = None, **options: Any) -> Opening[XYZPrinter]:
        """`async with XYZPrinter.open("192.168.1.50") as printer` (or `await` it): the one way to open a printer.

        `target` and the common options are described in `fabwire.opening`; the printer's settings are
        `fabwire.config.XYZSettings` (link, reply_timeout, model). A Wi-Fi printer that hangs up after every reply
        (the 1.1 Plus) is reconnected to the same address, through the same trace.
        """
        return Opening(XYZ, target, options, cls._on_link)

    @classmethod
    def open_sync(cls, target: DeviceTarget = None, **options: Any) -> SyncXYZPrinter:
        """The same, blocking, for plain scripts: `with XYZPrinter.open_sync("office") as printer: printer.status()`."""
        from fabwire.xyz.sync import SyncXYZPrinter

        return SyncXYZPrinter(target, **options)

    @classmethod
    async def _on_link(cls, transport: Transport, opened: DeviceLink) -> XYZPrinter:
        settings = opened.settings
        assert isinstance(settings, XYZSettings)
        address = opened.address
        link = Link(settings.link) if settings.link != "auto" else link_for_address(address) if address else None
        client = cls(transport, link=link, timeout=settings.reply_timeout or max(settings.timeout, 2.0))
        client.address, client.settings = address, settings
        client.time_scale = time_scale_for(address or transport.url)
        client.reopen = opened.reopen if address else None
        return client

    @classmethod
    async def connect(cls, address: str, *, link: Link | None = None, timeout: float = 5.0) -> XYZPrinter:
        """Kept for older scripts: `await XYZPrinter.open(address, timeout=…, reply_timeout=…)`."""
        return await cls.open(address, link=link.value if link else None, timeout=timeout, reply_timeout=timeout)

    async def _reconnect(self) -> None:
        """Wi-Fi printers such as the 1.1 Plus close the connection after every reply: open a new one."""
        if self._lost is None or self.address is None or self.link is not Link.WIFI:
            return
        log.info("the printer closed the connection (%s): opening a new one", self._lost)
        await self.transport.close()
        self.transport = await (self.reopen() if self.reopen is not None else
                                open_transport(self.address, XYZ, connect_timeout=self.timeout))
        self._lost = None
        self.reconnects += 1
        self.reader = ReplyReader(self.link)
        self._start_pump()

    async def close(self) -> None:
        self._pump_task.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await self._pump_task
        await self.transport.close()

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                        tb: TracebackType | None) -> None:
        await self.close()

    # ---------------------------------------------------------------------------------------- plumbing

    async def _pump(self) -> None:
        try:
            while True:
                data = await self.transport.read()
                self.reader.receive(data, self.clock())
                self._wake()
        except LinkError as exc:
            self._lost = exc
        self._wake()

    def _wake(self) -> None:
        """From the reader task: the request waiting (if any) looks at what came."""
        _release(self._waiter)

    def _check_link(self, doing: str) -> None:
        if self._lost is not None:
            raise LinkClosed(f"the link to the printer was lost while {doing}: {self._lost}")

    async def _write(self, data: bytes, doing: str) -> None:
        self._check_link(doing)
        try:
            await self.transport.write(data)
        except LinkError as exc:
            raise LinkClosed(f"the link to the printer was lost while {doing}: {exc}") from exc

    def _match(self, event: p.ReaderEvent | None, command: p.Command, doing: str) -> Reply | None:
        if isinstance(event, ActionStat):
            self.stats.append(event)
        elif isinstance(event, Reply) and event.command is command:
            return event
        elif isinstance(event, ErrorReply) and event.command is command:
            meaning = REPLY_ERRORS.get(event.code) or ErrorWord.decode(event.code).meaning
            raise DeviceError(f"E{event.code}", meaning, action=f"while {doing}")
        elif isinstance(event, NoReply) and event.command is command:
            raise LinkTimeout(f"the printer on {self.transport.peer or self.transport.url} did not answer "
                              f"{command.body!r} within {self.timeout:g} s")
        return None

    def _wait_time(self) -> float:
        deadline = self.reader.deadline()
        return 1.0 if deadline is None else max(0.0, deadline - self.clock()) + 0.001

    async def _event(self, command: p.Command, doing: str, *, direct: bool = False) -> Reply:
        """The reply to `command`; `direct` reads the link here instead of waiting on the reader task
        (one task hop less per upload block)."""
        while True:
            event = self.reader.next_event(self.clock())
            reply = self._match(event, command, doing)
            if reply is not None:
                return reply
            if event is not None:
                continue
            if not self._heard:
                self._check_peer()
            if direct:
                await self._read_once(doing)
            else:
                await self._wait_for_pump(doing)

    def _check_peer(self) -> None:
        """Before the printer was ever heard: words from another kind of machine or server end the wait as soon as
        the first bytes the peer sent name it."""
        said = self.reader.first.data
        if said and (wrong := wrong_peer(said, NOT_A_PRINTER, XYZ.name, self.transport.peer or self.transport.url)):
            raise wrong

    async def _name_peer(self) -> LinkError | RemoteProtocolError | None:
        """Why a peer never heard as a printer did not answer: the error naming what it is (from its first bytes,
        or from its answer to a probe when it said nothing), or None when nothing names it."""
        where = self.transport.peer or self.transport.url
        if not self.reader.first:  # free the peer's connection slot for the probes (a bridge may have only one)
            await self._stop_pump()
            await self.transport.close()
            self._lost = self._lost or LinkClosed(f"the link to {where} was closed to ask what answers there")
        if (named := await name_peer(self.reader.first.data, self.transport.url, NOT_A_PRINTER, XYZ.name, where)):
            return named
        sample = self.reader.noise_sample
        if sample is None:  # the start of a reply cut short, or nothing that is a line: the link's own error
            return None
        return RemoteProtocolError(f"{where} is not {NOT_A_PRINTER}: it answered {excerpt(sample, 60)}")

    async def _wait_for_pump(self, doing: str) -> None:
        """Until the reader task has read something, or the reply's deadline (a NoReply) has come: one future and
        one timer, the least a wait with a limit takes (a poll makes one of these each second per printer)."""
        self._check_link(doing)
        loop = asyncio.get_running_loop()
        waiter = self._waiter = loop.create_future()
        timer = loop.call_later(self._wait_time(), _release, waiter)
        try:
            await waiter
        finally:
            timer.cancel()
            self._waiter = None

    async def _read_once(self, doing: str) -> None:
        try:
            async with asyncio.timeout(self._wait_time()):
                data = await self.transport.read()
        except TimeoutError:
            return
        except LinkError as exc:
            self._lost = exc
            raise LinkClosed(f"the link to the printer was lost while {doing}: {exc}") from exc
        self.reader.receive(data, self.clock())

    async def _stop_pump(self) -> None:
        self._pump_task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._pump_task

    def _start_pump(self) -> None:
        if self._lost is None:
            self._pump_task = asyncio.get_running_loop().create_task(self._pump(), name="xyz-reader")

    async def request(self, command: p.Command, *, timeout: float | None = None) -> Reply:
        """Send one command and return its reply (drops stale input first)."""
        async with self._lock:
            return await self._request_once_more(command, timeout or self.timeout)

    async def _request_once_more(self, command: p.Command, timeout: float) -> Reply:
        """A Wi-Fi printer may hang up between commands; on a new connection the command is sent again."""
        if self.per_command and self.address is not None and self._lost is None:
            self._lost = LinkClosed("a new connection for every command")
        if self._lost is not None:
            await self._reconnect()
        try:
            return await self._request(command, timeout)
        except LinkClosed as exc:
            if self.address is None or self.link is not Link.WIFI:
                raise
            self._lost = self._lost or exc
            self.per_command = True  # it hangs up: from now on, one connection per command like XYZware
            await self._reconnect()
            return await self._request(command, timeout)

    async def _request(self, command: p.Command, timeout: float) -> Reply:
        doing = f"sending {command.body!r}"
        self._check_link(doing)
        self.reader.discard()
        data = self.reader.send(command, self.clock(), timeout)
        try:
            await self._write(data, doing)
            reply = await self._event(command, doing, direct=self._pump_task.done())
        except (LinkClosed, LinkTimeout) as exc:
            if not self._heard and (named := await self._name_peer()) is not None:
                raise named from exc
            raise
        except DeviceError:
            self._heard = True
            raise
        finally:
            self.reader.abandon()
        self._heard = True
        return reply

    # ------------------------------------------------------------------------------------------ status

    async def status(self, letters: str = "a") -> Status:
        """Query the printer; a partial query merges into the last full status.

        `E4$`/`E7$` (firmware busy while a print winds down) are transient: ask again for a few seconds.
        """
        for attempt in range(TRANSIENT_RETRIES + 1):
            try:
                reply = await self.request(p.Query(letters))
                break
            except DeviceError as exc:
                if exc.code not in ("E4", "E7") or attempt == TRANSIENT_RETRIES:
                    raise
                await asyncio.sleep(self.poll_interval)
        base = Status() if "a" in letters else self.last_status
        status = base.update(reply.lines)
        if "a" in letters and status.state is None:
            raise RemoteProtocolError(f"the status reply has no state (j:) among its {len(reply.lines)} lines; "
                                      "this is not a da Vinci answering XYZv3")
        if status.state != self.last_status.state:
            log.info("printer state: %s (%s)", status.state_name, status.state_code)
        self.last_status = status
        if self.last_status.model_number in HANGS_UP and self.link is Link.WIFI:
            self.per_command = True
        return self.last_status

    async def monitor(self, interval: float = 1.0, count: int | None = None) -> AsyncIterator[Status]:
        n = 0
        while count is None or n < count:
            yield await self.status()
            n += 1
            if count is None or n < count:
                await asyncio.sleep(interval)

    async def model(self) -> PrinterModel:
        status = self.last_status if self.last_status.model_number else await self.status()
        model = status.model
        if model is None:
            raise DeviceError("model", f"the printer reports an unknown model {status.model_number!r}")
        return model

    async def require_idle(self, doing: str, command: p.Command | None = None) -> Status:
        """A busy printer or one reporting an error cannot start something new: say which, in words (a state that
        passes is DeviceBusy, exit 4, as every machine's; an error the printer reports is DeviceError, exit 7)."""
        status = await self.status()
        if command is not None:
            await self._supports(command)
        for word in status.error_words:
            raise DeviceError(f"0x{word.raw:08X}", word.meaning, action=f"cannot {doing}")
        if status.state_code == PRINT_DONE:
            raise DeviceBusy("the last print is finished but not yet acknowledged: take it off the bed and "
                             f"acknowledge it (fabwire xyz acknowledge) to {doing}")
        if status.state_code != IDLE:
            raise DeviceBusy(f"the printer is busy ({status.state_name}): cannot {doing}")
        return status

    # ------------------------------------------------------------------------------------------ printing

    def prepare(self, source: Path | bytes, model: PrinterModel, *, override: bool = False) -> bytes:
        """The bytes to upload: a .3w (binary or base64 text) as is if it suits `model`, G-code converted for
        `model`; any other kind of file is an InputError saying what it is. (`print_file` streams from disk.)"""
        from fabwire.xyz import printjob  # G-code scanning (numpy): loaded when a file is printed, not for a status

        with printjob.ready_file(source, model, override=override) as ready:
            return ready.read_bytes()

    async def upload(self, data: bytes | Path, name: str, *, progress: UploadProgress | None = None,
                     firmware: bool = False, crc: bool = True, save_to_sd: bool = False) -> UploadResult:
        """Send a file (bytes, or a file read block by block) in blocks, each acknowledged; a link lost on the way
        is a LinkError, never success. `name` is checked as user input (InputError); `save_to_sd` adds XYZware's
        `,SaveToSD` flag."""
        with contextlib.ExitStack() as stack:
            if isinstance(data, Path):
                try:
                    handle = stack.enter_context(data.open("rb", buffering=UPLOAD_READ_BUFFER))
                except OSError as exc:
                    raise InputError(f"cannot read {data}: {exc.strerror}") from exc
                source: bytes | BinaryIO = handle
                size = os.fstat(handle.fileno()).st_size
            else:
                source, size = data, len(data)
            return await self._upload(source, size, name, progress, firmware, crc, save_to_sd)

    async def _upload(self, data: bytes | BinaryIO, size: int, name: str, progress: UploadProgress | None,
                      firmware: bool, crc: bool, save_to_sd: bool) -> UploadResult:
        if not size:
            raise InputError("nothing to upload: the file is empty")
        name = userinput.upload_name(name)
        block = self.last_status.block_size if self.last_status.packet else (await self.status()).block_size
        command: p.Upload | p.FirmwareUpload = (
            p.FirmwareUpload(name, size) if firmware else p.Upload(name, size, save_to_sd))
        started = self.clock()
        sent = 0
        blocks = 0
        window = self.upload_window if self.link is Link.WIFI else 1
        async with self._lock:
            if self.per_command and self.address is not None:
                self._lost = LinkClosed("a new connection for the upload")
                await self._reconnect()
            else:
                await self._request_once_more(p.Query("o"), self.timeout)  # the link is alive right now
            await self._stop_pump()
            try:
                await self._request(command, self.timeout)
                acks = p.AckCounter()
                in_flight: deque[int] = deque()
                batch: list[bytes] = []  # blocks that fill the window, written at once (one send, not one each)
                for chunk in p.iter_blocks(data, block, crc=crc):
                    batch.append(chunk)
                    in_flight.append(len(chunk) - 12)
                    blocks += 1
                    if len(in_flight) < window:
                        continue
                    await self._write(b"".join(batch), "uploading")
                    batch.clear()
                    while len(in_flight) >= window:
                        for _ in range(await self._acks(acks, len(in_flight))):
                            sent += in_flight.popleft()
                        if progress is not None:
                            progress(sent, size)
                if batch:
                    await self._write(b"".join(batch), "uploading")
                while in_flight:
                    for _ in range(await self._acks(acks, len(in_flight))):
                        sent += in_flight.popleft()
                    if progress is not None:
                        progress(sent, size)
                await self._request(p.UploadDidFinish(), self.timeout)
            except (LinkError, LinkTimeout) as exc:
                raise LinkError(f"upload of {name} failed after {sent} of {size} bytes: {exc}; "
                                "the printer did not receive the whole file") from exc
            finally:
                self._start_pump()
        return UploadResult(name, size, blocks, self.clock() - started)

    async def _acks(self, counter: p.AckCounter, most: int) -> int:
        """Wait for at least one block ack; return how many came (never more than `most`)."""
        try:
            async with asyncio.timeout(self.timeout):
                while True:
                    count, error = counter.feed(await self.transport.read())
                    if error is not None:
                        meaning = REPLY_ERRORS.get(error) or ErrorWord.decode(error).meaning
                        raise DeviceError(f"E{error}", meaning, action="the printer refused an upload block")
                    if count:
                        if count > most:
                            raise RemoteProtocolError(f"the printer acknowledged {count} blocks, {most} were sent")
                        return count
        except TimeoutError:
            raise LinkTimeout(f"the printer did not acknowledge an upload block within {self.timeout:g} s") from None
        except LinkError as exc:
            self._lost = exc
            raise LinkClosed(f"the link to the printer was lost while uploading: {exc}") from exc

    async def print_file(self, source: Path | bytes, *, model: PrinterModel | None = None,
                         progress: UploadProgress | None = None, on_status: StatusCallback | None = None,
                         wait: bool = True, name: str | None = None, save_to_sd: bool = False,
                         start_limit: float = 30.0, on_note: Callable[[str], None] | None = None,
                         force: bool = False) -> Status:
        """Convert if needed, upload, start and (unless wait=False) follow the job to its end.

        `name` is the upload name (default: a safe one derived from the file name). The job counts as started
        only when the printer says so (checking the file, printing, or a file error); a printer that stays idle
        for `start_limit` s is a DeviceError, never success."""
        from fabwire.xyz import printjob

        printjob.check_source(source)  # before disturbing the printer
        checked = printjob.check_in_background(source)  # the file's own checks while the printer is asked its state
        name = userinput.upload_name(name) if name is not None else userinput.derived_upload_name(
            source.name if isinstance(source, Path) else None)
        status = await self.require_idle("print")
        printer_model = status.model
        target = model or printer_model
        if target is None:
            raise DeviceError("model", f"the printer reports an unknown model {status.model_number!r}; pass a model")
        with contextlib.suppress(Exception):  # waited for without holding up the link; its outcome is read below
            await asyncio.wrap_future(checked)
        with printjob.ready_file(source, target, override=model is not None, force=force, checked=checked) as ready:
            await self.upload(ready, name, progress=progress, save_to_sd=save_to_sd)
        status = await self._await_job_start(start_limit)
        if on_status:
            on_status(status)
        if not wait:
            return status
        return await self.follow_job(on_status, on_note=on_note)

    async def _await_job_start(self, limit: float = 30.0) -> Status:
        """The first status that shows the job under way; a printer still idle after `limit` s never took it."""
        end = self.clock() + limit
        while True:
            status = await self.status()
            if FILE_REJECTED in [w.code for w in status.error_words]:
                raise DeviceError("0x020D", "the printer rejected the file (unsupported file version)")
            if status.state_code is not None and status.state_code != IDLE:
                return status
            if self.clock() > end:
                raise DeviceError(str(status.state_code), f"the printer took the file but did not start the job "
                                  f"within {limit:g} s (it is {status.state_name})",
                                  action="nothing is printing; check the printer's screen and send the file again")
            await asyncio.sleep(self.poll_interval)

    async def follow_job(self, on_status: StatusCallback | None = None, *, limit: float | None = None,
                         on_note: Callable[[str], None] | None = None) -> Status:
        """Poll until the job ends (9509 done or idle); a printer error is DeviceError, a file check (9520) over
        FILE_CHECK_LIMIT printer seconds LinkTimeout, `on_note` told every CHECKING_NOTE_EVERY s meanwhile.

        A print that ends in idle after 9602 (cancelling) or 9512 (stopped), or before its progress came near the
        end (`FINISHED_PERCENT`; the firmware may show idle briefly between 9505 and 9509, reference §3.2), was
        cancelled: DeviceError, since it did not finish."""
        end = None if limit is None else self.clock() + limit
        checking_since: float | None = None
        noted = 0  # notes given so far
        stopped = False  # 9602 or 9512 seen
        percent: int | None = None  # the last progress shown while printing
        while True:
            status = await self.status()
            words = status.error_words
            if words:  # raised before it is shown: a failed job's state (often 9509) must not read "finished"
                word = words[0]
                raise DeviceError(f"0x{word.raw:08X}", word.meaning, action="the job stopped")
            if on_status:
                on_status(status)
            if status.state_code == FILE_CHECK:
                checking_since = self.clock() if checking_since is None else checking_since
                checking = (self.clock() - checking_since) * self.time_scale
                if checking > FILE_CHECK_LIMIT:
                    raise LinkTimeout(f"the printer has been checking the file for over {FILE_CHECK_LIMIT:g} s "
                                      "(it usually takes seconds); stop it with `fabwire xyz cancel` or on its panel")
                if on_note is not None and checking >= (noted + 1) * CHECKING_NOTE_EVERY:
                    noted = int(checking // CHECKING_NOTE_EVERY)
                    on_note(f"the printer is still checking the file ({checking:.0f} s; limit {FILE_CHECK_LIMIT:g} s)")
            else:
                checking_since = None
                noted = 0
            if status.state_code in (CANCELLING, PRINT_STOP):
                stopped = True
            elif status.state_code == PRINTING and status.progress is not None:
                percent = status.progress.percent
            if status.state_code == IDLE and (stopped or (percent is not None and percent < FINISHED_PERCENT)):
                raise PrintCancelled(percent)
            if status.state_code in (PRINT_DONE, IDLE):
                return status
            if end is not None and self.clock() > end:
                raise LinkTimeout("the job did not finish in time")
            await asyncio.sleep(self.poll_interval)

    async def pause(self) -> None:
        await self._job_control("pause", (PRINTING,))

    async def resume(self) -> None:
        await self._job_control("resume", (PAUSED,))

    async def cancel(self, *, confirm: Callable[[], None] | None = None) -> None:
        """Stop the print for good. `confirm`, when given, runs once the printer shows a print to cancel and may
        raise to go no further (the CLI's "Cancel the running print?" is asked only when there is one)."""
        await self._job_control("cancel", (PRINTING, PAUSED, 9520), confirm)

    async def acknowledge(self) -> None:
        """Tell the printer the finished print was taken off the bed (leaves 'print finished')."""
        await self._job_control("complete", (PRINT_DONE,))

    async def _job_control(self, op: str, states: tuple[int, ...], confirm: Callable[[], None] | None = None) -> None:
        """Send a job command if the printer's state allows it; otherwise an InputError in words (the host's own
        check: the firmware would only answer with a bare error code)."""
        status = await self.status()
        if status.state_code not in states:
            state = status.state_name
            if op == "pause" and status.state_code == PAUSED:
                raise InputError("the print is already paused (fabwire xyz resume continues it)")
            if op == "resume" and status.state_code == PRINTING:
                raise InputError("the print is already running")
            if op == "cancel":
                raise InputError(f"nothing to cancel: no print is running (the printer shows '{state}')")
            wanted = {"resume": "paused", "complete": "showing a finished print"}.get(op, "printing")
            raise InputError(f"nothing to {op}: the printer is not {wanted} (it is {state})")
        if confirm is not None:
            confirm()
        command = p.PrintControl(op)
        if command.expects(self.link) is not p.Expect.NOTHING:
            await self.request(command)  # the printer's ok
        else:  # a Wi-Fi printer answers nothing: its state leaving the one it was in is the evidence
            await self._send_confirmed(command, "j", lambda st: st.state_code != status.state_code)

    async def upload_firmware(self, image: bytes, *, confirm: bool, progress: UploadProgress | None = None,
                              name: str = "temp.bin") -> UploadResult:
        """Flash firmware (the image's 16-byte `<model>+<version>` header is checked, then not sent)."""
        if not confirm:
            raise InputError("firmware upload can brick the printer: confirm it explicitly")
        if len(image) <= 16:
            raise InputError("the firmware image is too short")
        found = _FIRMWARE_HEADER.fullmatch(image[:16].rstrip(b"\x00 "))
        if found is None:
            raise InputError("not a da Vinci firmware image (it does not start with a <model>+<version> header)")
        model_text, version = found[1].decode("ascii"), found[2].decode("ascii")
        model = await self.model()
        if model_text != model.model_number or not version:
            raise InputError(f"the firmware image is for {model_text or 'an unknown model'!r}, "
                             f"not this {model.name} ({model.model_number})")
        await self.require_idle("update the firmware")
        return await self.upload(image[16:], name, progress=progress, firmware=True)
