"""The agent's links' process: `python -m fabwire.agent.linkworker FD`, started by `fabwire.agent.linkprocess`.

It hosts the drivers of the machines the agent gives it and works them on its own event loop, talking with the
agent over the socket FD in `fabwire.agent.linkwire` frames. Agent → here: ("open", link, DeviceSpec), ("call",
call, link, operation, args), ("cancel", call), ("drop", link). Here → agent: ("ok", call, result), ("err", call,
packed exception), ("polls", [(link, status, summary, at, lag, interval), …]) every DELIVER_EVERY_S at most,
("event", link, payload), ("job", link, report, args), ("log", logger, level, message). It ends when that socket
closes: when the agent ends, however it ends.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket
import sys
from functools import partial
from typing import Any

from fabwire.agent.linkside import LinkSide
from fabwire.agent.linkthread import DELIVER_EVERY_S
from fabwire.agent.linkwire import UNCHANGED, Unframer, frame, pack_error
from fabwire.agent.offload import check_within

NICENESS = 4
"""How much lower the links' process's scheduling priority is than the agent's (nice(2) steps)."""


class Worker(asyncio.Protocol):
    """The drivers and the calls running on them, for the agent at the other end of the socket."""

    def __init__(self, ended: asyncio.Future[None]) -> None:
        self._ended = ended
        self._loop = asyncio.get_running_loop()
        self._transport: Any = None
        """An asyncio.Transport's interface (uvloop's are not its subclasses)."""
        self._unframer = Unframer(self._on_message)
        self._sides: dict[int, LinkSide] = {}
        self._last: dict[int, tuple[Any, Any]] = {}
        """Per link, the status and summary its last scheduled poll sent."""
        self._calls: dict[int, asyncio.Task[None]] = {}
        self._polls: list[tuple[Any, ...]] = []
        self._flush_due = False

    # -------------------------------------------------------------------------------------- the socket

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = transport

    def data_received(self, data: bytes) -> None:
        self._unframer.feed(data)

    def connection_lost(self, exc: Exception | None) -> None:
        if not self._ended.done():
            self._ended.set_result(None)

    def send(self, message: Any) -> None:
        """Polls waiting in the batch go first: the agent hears of everything in the order it happened."""
        if self._polls:
            self._flush()
        if self._transport is not None and not self._transport.is_closing():
            self._transport.write(frame(message))

    def _flush(self) -> None:
        self._flush_due = False
        if self._polls:
            batch, self._polls = self._polls, []
            if self._transport is not None and not self._transport.is_closing():
                self._transport.write(frame(("polls", batch)))

    # -------------------------------------------------------------------------------------- the agent's messages

    def _on_message(self, message: tuple[Any, ...]) -> None:
        kind = message[0]
        if kind == "call":
            _, call, link, operation, args = message
            self._calls[call] = self._loop.create_task(self._call(call, link, operation, args))
        elif kind == "cancel":
            task = self._calls.pop(message[1], None)
            if task is not None:
                task.cancel()
        elif kind == "open":
            _, link, spec = message
            self._sides[link] = LinkSide(spec, lambda payload: self.send(("event", link, payload)),
                                         lambda *polled: self._polled(link, *polled), _no_wait)
        elif kind == "drop":
            self._sides.pop(message[1], None)
            self._last.pop(message[1], None)

    async def _call(self, call: int, link: int, operation: str, args: tuple[Any, ...]) -> None:
        try:
            side = self._sides[link]
            if operation == "run_job":
                path, job_type, params = args
                result: Any = await side.driver.run_job(path, job_type, _Handle(self, link), params)
            elif operation in ("poll_forever", "poll_now", "act_then_poll"):
                result = await getattr(side, operation)(*args)
            elif operation == "check_upload":
                result = await check_within(side.driver.check_upload, *args, name=args[0])
            elif operation == "describe_upload":
                name, path, check = args
                result = await check_within(partial(side.driver.describe_upload, check=check), name, path, name=name)
            elif operation in ("connect", "close", "act", "stop_job"):
                result = await getattr(side.driver, operation)(*args)
            else:
                raise ValueError(f"no link operation {operation!r}")
        except asyncio.CancelledError:
            return  # the agent stopped waiting for it
        except Exception as exc:
            self.send(("err", call, pack_error(exc)))
        else:
            try:
                self.send(("ok", call, result))
            except Exception as exc:  # a result that cannot travel: the agent hears why rather than waiting
                self.send(("err", call, pack_error(exc)))
        finally:
            self._calls.pop(call, None)

    def _polled(self, link: int, status: dict[str, Any] | None, summary: dict[str, Any], at: float, lag: float,
                interval: float) -> None:
        last_status, last_summary = self._last.get(link, (None, None))
        self._last[link] = (status, summary)
        self._polls.append((link, UNCHANGED if status is last_status and status is not None else status,
                            UNCHANGED if summary is last_summary else summary, at, lag, interval))
        if not self._flush_due:
            self._flush_due = True
            self._loop.call_later(DELIVER_EVERY_S, self._flush)

    async def wind_down(self) -> None:
        """Cancel what still runs and close every link."""
        for task in list(self._calls.values()):
            task.cancel()
        for side in list(self._sides.values()):
            with contextlib.suppress(Exception):
                await asyncio.wait_for(side.driver.close(), 2.0)


def _no_wait() -> None:
    """The links' process shares no interpreter with the agent's requests: it never steps aside for them."""


class _Handle:
    """The JobHandle of a job run here: each report is a ("job", link, report, args) message."""

    def __init__(self, worker: Worker, link: int) -> None:
        self._worker = worker
        self._link = link

    def progress(self, percent: float, *, time_left_s: float | None = None, message: str | None = None) -> None:
        self._worker.send(("job", self._link, "progress", (percent, time_left_s, message)))

    def stroke(self, points: list[tuple[float, float]]) -> None:
        self._worker.send(("job", self._link, "stroke", (points,)))

    def preview(self, strokes: list[list[tuple[float, float]]]) -> None:
        self._worker.send(("job", self._link, "preview", (strokes,)))

    def note(self, text: str) -> None:
        self._worker.send(("job", self._link, "note", (text,)))


class _ToAgent(logging.Handler):
    """The drivers' log records, sent to the agent's log (this process's stderr may be read by nobody)."""

    def __init__(self, worker: Worker) -> None:
        super().__init__()
        self._worker = worker

    def emit(self, record: logging.LogRecord) -> None:
        with contextlib.suppress(Exception):
            self._worker.send(("log", record.name, record.levelno, record.getMessage()))


def yield_to_agent() -> None:
    """Let the agent's process go first whenever both want a core: a request it answers preempts polls, which have
    half an interval of slack (nice NICENESS; where that cannot be set, the polls just share the cores evenly)."""
    with contextlib.suppress(OSError, AttributeError):
        os.nice(NICENESS)


async def serve(sock: socket.socket, level: int = logging.INFO) -> None:
    """Work for the agent at the other end of `sock` until it closes; fabwire's log records from `level` (the
    agent's own level for them) go to the agent's log."""
    loop = asyncio.get_running_loop()
    ended: asyncio.Future[None] = loop.create_future()
    worker = Worker(ended)
    await loop.connect_accepted_socket(lambda: worker, sock)
    logging.getLogger().addHandler(_ToAgent(worker))
    logging.getLogger("fabwire").setLevel(level)
    await ended
    await worker.wind_down()


def main(argv: list[str]) -> int:
    """argv: [program, socket's file descriptor, log level (a number, INFO when absent)]."""
    sock = socket.socket(fileno=int(argv[1]))
    level = int(argv[2]) if len(argv) > 2 else logging.INFO
    yield_to_agent()
    try:
        import uvloop
    except ImportError:
        asyncio.run(serve(sock, level))
    else:
        uvloop.run(serve(sock, level))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
