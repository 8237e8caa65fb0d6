"""The host's reply reader, sans-IO: what the printer answers to each command, told apart from late replies, action
progress lines and noise. Serial and Wi-Fi links answer differently (Wi-Fi omits `$` after most replies and every
config/action ack), so the reader is told the link kind and never waits for a terminator that will not come. Time
is always an argument."""

from __future__ import annotations

import re

import msgspec

from fabwire.errors import LocalProtocolError
from fabwire.xyz.commands import (
    RAW_REPLIES,
    Command,
    Expect,
    Flow,
    Home,
    Jog,
    Link,
    Query,
    Signature,
    TagInfo,
    Uid,
    encode,
)


class Reply(msgspec.Struct, frozen=True):
    """A complete reply to `command`: its lines with `$`, `ok` and stray noise removed."""

    command: Command
    lines: tuple[str, ...] = ()
    acked: bool = False


class ErrorReply(msgspec.Struct, frozen=True):
    """`E<n>$` in reply to `command`."""

    command: Command
    code: int


class NoReply(msgspec.Struct, frozen=True):
    """The reply did not finish before the deadline; `lines` holds what did arrive."""

    command: Command
    lines: tuple[str, ...] = ()


class ActionStat(msgspec.Struct, frozen=True):
    """`<name>:{"stat":"<word>",…}`: progress of an action flow, solicited or not (serial only)."""

    name: str
    stat: str
    values: tuple[int, ...] = ()
    extra: dict[str, str] = msgspec.field(default_factory=dict)


ReaderEvent = Reply | ErrorReply | NoReply | ActionStat

_ERROR = re.compile(r"^E(\d{1,10})\$?$")
_STAT = re.compile(r"^([A-Za-z][A-Za-z0-9_]+):(\{.*\})$")
MAX_STATUS_LINES = 256
"""Lines kept of one status reply: a full `query=a` is about 30, one per letter."""
_NUMBER = re.compile(r"-?\d{1,12}")  # fullmatch: a reading, never a 5000-digit int()
_STATUS_RUN = re.compile(r"(?:[^\n]:[^\n]*\n)*")
"""Lines whose second character is `:` (`x:value`), one after the other."""
_STATUS_LINE = re.compile(r"([^\n]:[^\n]*?)[\r ]*\n")
"""One of them without its line end and trailing spaces (as `str.rstrip("\r ")`)."""


def parse_stat_line(line: str) -> ActionStat | None:
    """`load:{"stat":"heat","extemp":"24"}` or `calibratejr:{"stat":"ok",438,…}`; None if not such a line."""
    m = _STAT.match(line)
    if not m:
        return None
    inner = m[2][1:-1]
    stat = ""
    values: list[int] = []
    extra: dict[str, str] = {}
    for part in inner.split(","):
        key, sep, value = part.partition(":")
        if sep:
            key, value = key.strip().strip('"'), value.strip().strip('"')
            if key == "stat":
                stat = value
            else:
                extra[key] = value
        elif _NUMBER.fullmatch(part.strip()):
            values.append(int(part.strip()))
        elif part.strip():
            return None
    if not stat and not values:
        return None
    return ActionStat(m[1], stat, tuple(values), extra)


class _Pending(msgspec.Struct):
    command: Command
    expect: Expect
    deadline: float
    lines: list[str] = msgspec.field(default_factory=list)
    acked: bool = False
    seen: set[str] = msgspec.field(default_factory=set)
    last_rx: float | None = None
    wanted: frozenset[str] = frozenset()
    """The letters of a partial query on Wi-Fi, whose reply ends once they all came (it has no `$`)."""


class ReplyReader:
    """Matches printer output to the command in flight, one at a time, for one link kind.

    Lines that belong to nothing (late `$`, the extra `ok` after an upload, an `ok` inside a status reply)
    are dropped and counted in `noise`; action progress lines become ActionStat events whenever they come.
    """

    settle = 0.4
    """Wi-Fi partial queries: once some lines came, this much silence ends the reply."""

    def __init__(self, link: Link) -> None:
        self.link = link
        self._buffer = bytearray()
        self._events: list[ReaderEvent] = []
        self._pending: _Pending | None = None
        self._swallow_dollar = 0
        self.noise = 0
        self.noise_sample: str | None = None
        """The first line that fitted nothing: evidence when the peer is not an XYZv3 printer at all."""
        from fabwire.transport.peers import FirstBytes  # here: the file commands read the protocol, never a peer

        self.first = FirstBytes()
        """The first bytes the peer sent, whatever became of them: what names a peer that is no printer."""

    @property
    def busy(self) -> bool:
        return self._pending is not None

    def send(self, command: Command, now: float, timeout: float = 5.0) -> bytes:
        """Arm the reader for `command` and return its bytes to write."""
        if self._pending is not None:
            raise LocalProtocolError(f"a reply to {self._pending.command.body!r} is still outstanding")
        expect = command.expects(self.link)
        if expect is Expect.NOTHING:
            self._events.append(Reply(command))
        else:
            self._pending = self._pending_for(command, expect, now + timeout)
        return encode(command, self.link)

    def arm(self, command: Command, now: float, timeout: float = 5.0) -> None:
        """Expect a reply for bytes already sent by other means (upload blocks)."""
        self._pending = self._pending_for(command, command.expects(self.link), now + timeout)

    def _pending_for(self, command: Command, expect: Expect, deadline: float) -> _Pending:
        wanted = command.wanted if self.link is Link.WIFI and isinstance(command, Query) else frozenset()
        return _Pending(command, expect, deadline, wanted=wanted)

    def abandon(self) -> None:
        """Stop waiting for the reply in flight (its command failed or was given up)."""
        self._pending = None

    def discard(self) -> None:
        """Forget buffered input (the stale replies a client drains before each command)."""
        self._buffer.clear()
        if self._events:
            self._events = [e for e in self._events if isinstance(e, ActionStat)]

    def receive(self, data: bytes, now: float) -> None:
        self.first.feed(data)  # up to its bound
        self._buffer += data
        p = self._pending
        if p is not None:
            p.last_rx = now
        if p is None or type(p.command) not in RAW_REPLIES:
            # No reply read by byte count can start while these lines are read (a command is armed only
            # between receives): every complete line at once, one decode for all of them.
            end = self._buffer.rfind(b"\n") + 1
            if end:
                text = self._buffer[:end].decode("latin-1")
                del self._buffer[:end]
                self._lines(text)
            self._bound()
            return
        while True:
            raw_line = self._raw_reply()
            if raw_line is not None:
                if raw_line:
                    self._note(raw_line)
                    continue
                break
            end = self._buffer.find(b"\n")
            if end < 0:
                break
            raw = bytes(self._buffer[:end])
            del self._buffer[: end + 1]
            self._note(raw.decode("latin-1").rstrip("\r "))
        self._bound()

    def _lines(self, text: str) -> None:
        """Complete lines (`text` ends with `\n`), each as `_note` takes it; a run of status lines, the bulk of a
        status reply, is read in one pass (they go straight to the reply: see `_line`)."""
        at, size = 0, len(text)
        while at < size:
            p = self._pending
            if p is not None and p.expect is Expect.STATUS and not p.wanted:
                run = _STATUS_RUN.match(text, at)
                if run is not None and run.end() > at:
                    lines = _STATUS_LINE.findall(text, at, run.end())
                    room = max(0, MAX_STATUS_LINES - len(p.lines))
                    p.lines += lines[:room]
                    for line in lines[room:]:
                        self._note(line)  # past the bound: noise
                    at = run.end()
                    continue
            end = text.index("\n", at)
            self._note(text[at:end].rstrip("\r "))
            at = end + 1

    def _bound(self) -> None:
        if len(self._buffer) > 65536:  # a line this long is not XYZv3; keep the reader bounded
            self._buffer.clear()
            self.noise += 1

    def _note(self, line: str) -> None:
        before = self.noise
        self._line(line)
        if self.noise > before and self.noise_sample is None:
            self.noise_sample = line[:60]

    def _raw_reply(self) -> str | None:
        """A `signature`/`uid` reply is read by byte count (its raw bytes may hold `\n`): the line, "" while
        it is still arriving, or None when the buffer does not start with one."""
        p = self._pending
        spec = RAW_REPLIES.get(type(p.command)) if p is not None else None
        if spec is None:
            return None
        head = f'{spec[0]}:"'.encode()
        buf = self._buffer
        if not (buf.startswith(head) or (len(buf) < len(head) and head.startswith(bytes(buf)) and buf)):
            return None
        size = len(head) + spec[1] + 1
        if len(buf) < size + 1:
            return ""
        if buf[size - 1 : size + 1] != b'"\n':
            return None  # not the framing we know: fall back to reading a line
        line = bytes(buf[:size]).decode("latin-1")
        del buf[: size + 1]
        return line

    def next_event(self, now: float) -> ReaderEvent | None:
        self._check_time(now)
        return self._events.pop(0) if self._events else None

    def deadline(self) -> float | None:
        p = self._pending
        if p is None:
            return None
        if self.link is Link.WIFI and p.expect is Expect.STATUS and p.lines and p.last_rx is not None:
            return min(p.deadline, p.last_rx + self.settle)
        return p.deadline

    def _check_time(self, now: float) -> None:
        p = self._pending
        if p is None:
            return
        quiet = self.link is Link.WIFI and p.expect is Expect.STATUS and bool(p.lines)
        if quiet and p.last_rx is not None and now >= p.last_rx + self.settle:
            self._finish()
        elif now >= p.deadline:
            if quiet or (p.expect is Expect.ACK and p.acked):
                self._finish()
            else:
                self._pending = None
                self._events.append(NoReply(p.command, tuple(p.lines)))

    def _finish(self) -> None:
        p = self._pending
        assert p is not None
        self._pending = None
        self._events.append(Reply(p.command, tuple(p.lines), p.acked))

    def _line(self, line: str) -> None:
        if not line:
            return
        p = self._pending
        if p is not None and p.expect is Expect.STATUS and line[1:2] == ":":
            # `x:value`, the bulk of a status reply, is neither an error (`E<n>`), a `$`, an `ok` nor an action
            # progress line (whose name has two characters or more): straight to the reply.
            self._status_line(p, line)
            return
        if (m := _ERROR.match(line)) and (line.endswith("$") or p is not None):
            if p is not None:
                self._pending = None
                self._events.append(ErrorReply(p.command, int(m[1])))
            else:
                self.noise += 1
            return
        stat = parse_stat_line(line)
        if stat is not None and not (p is not None and p.expect in (Expect.DATA, Expect.LINE, Expect.ACTION)
                                     and _stat_matches(p.command, stat)):
            self._events.append(stat)
            if self.link is Link.SERIAL:
                self._swallow_dollar += 1
            return
        if line == "$":
            if p is not None and self._swallow_dollar == 0 and self._dollar_ends(p):
                self._finish()
            elif self._swallow_dollar:
                self._swallow_dollar -= 1
            else:
                self.noise += 1
            return
        if p is None:
            self.noise += 1
            return
        if line == "ok" or line.startswith("ok "):
            if p.expect in (Expect.UPLOAD, Expect.FINISH):
                p.acked = True
                self._finish()
            elif p.expect is Expect.ACK:
                p.acked = True
            else:
                self.noise += 1
            return
        if p.expect is Expect.STATUS:
            self._status_line(p, line)
        elif p.expect is Expect.NUMBER:
            if _NUMBER.fullmatch(line) and not p.lines:
                p.lines.append(line)
            else:
                self.noise += 1
        elif p.expect in (Expect.DATA, Expect.ACTION, Expect.LINE):
            if not p.lines:
                p.lines.append(line)
                if p.expect is Expect.LINE:
                    self._finish()
            else:
                self.noise += 1
        else:
            self.noise += 1

    def _status_line(self, p: _Pending, line: str) -> None:
        if len(p.lines) >= MAX_STATUS_LINES:
            self.noise += 1  # a reply that never ends: keep the reader bounded, let the wait time out
        elif line[1:2] == ":":
            p.lines.append(line)
            if p.wanted:
                p.seen.add(line[0])
                if p.wanted <= p.seen:
                    self._finish()
        else:
            self.noise += 1

    def _dollar_ends(self, p: _Pending) -> bool:
        if p.expect is Expect.STATUS:
            # A stale `$` can precede a full status reply; a real `a` reply always has lines.
            return bool(p.lines) or not (isinstance(p.command, Query) and not p.command.wanted)
        if p.expect is Expect.ACK:
            return p.acked
        if p.expect in (Expect.NUMBER, Expect.DATA, Expect.ACTION):
            return bool(p.lines)
        return False


def _stat_matches(command: Command, stat: ActionStat) -> bool:
    if isinstance(command, Flow):
        return stat.name == command.flow
    if isinstance(command, Home):
        return stat.name == "home"
    if isinstance(command, Jog):
        return stat.name == "jog"
    return isinstance(command, TagInfo | Signature | Uid)


class AckCounter:
    """Counts upload-block acks (`ok`, `ok `) in a byte stream, so several blocks may be in flight.

    `E<n>$` is an error; a stray `$` or blank line is ignored; anything else is counted as noise.
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self.noise = 0

    def feed(self, data: bytes) -> tuple[int, int | None]:
        """Return (acks in `data`, the first error code or None)."""
        self._buffer += data
        acks = 0
        while (end := self._buffer.find(b"\n")) >= 0:
            line = bytes(self._buffer[:end]).rstrip(b"\r ")
            del self._buffer[: end + 1]
            if line == b"ok" or line.startswith(b"ok "):
                acks += 1
            elif m := _ERROR.match(line.decode("latin-1")):
                return acks, int(m[1])
            elif line not in (b"", b"$"):
                self.noise += 1
        if len(self._buffer) > 4096:
            self._buffer.clear()
            self.noise += 1
        return acks, None
