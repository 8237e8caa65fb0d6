"""Log lines that never stall the event loop: records go through a bounded queue to a writer thread.

A simulator or agent whose stderr is a pipe nobody reads (a service manager, a test harness, `cmd 2>&1 | head`)
would otherwise freeze at the first full pipe buffer, with every client locked out. Here only the writer thread
blocks; when the queue is full, new lines are dropped and counted, and the count is reported once there is room.
"""

from __future__ import annotations

import atexit
import logging
import logging.handlers
import queue
import sys
import threading
import time
from typing import TextIO

QUEUE_LINES = 1000
"""Lines held while the stream is blocked; beyond this they are dropped (and counted)."""


class DroppingQueueHandler(logging.handlers.QueueHandler):
    """A QueueHandler that drops a record instead of blocking or raising when the queue is full."""

    def __init__(self, records: queue.Queue[logging.LogRecord]) -> None:
        super().__init__(records)
        self.dropped = 0

    def enqueue(self, record: logging.LogRecord) -> None:
        try:
            if self.dropped:
                self.queue.put_nowait(logging.makeLogRecord({
                    "name": "fabwire", "levelno": logging.WARNING, "levelname": "WARNING",
                    "msg": "%d log line(s) dropped while stderr was not being read", "args": (self.dropped,)}))
                self.dropped = 0
            self.queue.put_nowait(record)
        except queue.Full:
            self.dropped += 1


class _StreamWriter(logging.StreamHandler):  # type: ignore[type-arg]
    """Writes lines to the stream until it is gone (the reader closed the pipe, the fd was closed), then drops
    them quietly: a traceback about a dead stderr would only go to that same dead stderr, or into a host's."""

    gone = False

    def emit(self, record: logging.LogRecord) -> None:
        if not self.gone:
            super().emit(record)

    def handleError(self, record: logging.LogRecord) -> None:  # noqa: N802 - logging's name
        if isinstance(sys.exc_info()[1], OSError | ValueError):  # ValueError: write to a closed file
            self.gone = True
            return
        super().handleError(record)


def non_blocking_handler(stream: TextIO, formatter: logging.Formatter) -> logging.Handler:
    """A handler writing `formatter`'s lines to `stream` from a daemon thread; at exit, what is queued gets a
    moment to be written (a pipe nobody reads cannot hold the process)."""
    records: queue.Queue[logging.LogRecord] = queue.Queue(QUEUE_LINES)
    writer = _StreamWriter(stream)
    writer.setFormatter(formatter)

    def write_forever() -> None:
        while True:
            writer.handle(records.get())
            records.task_done()

    threading.Thread(target=write_forever, name="fabwire-log", daemon=True).start()
    atexit.register(_drain, records)
    return DroppingQueueHandler(records)


def _drain(records: queue.Queue[logging.LogRecord], wait: float = 1.0) -> None:
    ends = time.monotonic() + wait
    while records.unfinished_tasks and time.monotonic() < ends:
        time.sleep(0.01)


def log_in_background(also: tuple[str, ...] = ()) -> None:
    """For long-running servers (simulators, the agent): move the CLI's stderr log handler onto a writer thread.

    The loggers named in `also` (a library's, such as uvicorn's) write through the same thread, in place of
    whatever handlers they had.
    """
    root = logging.getLogger("fabwire")
    for handler in list(root.handlers):
        if getattr(handler, "fabwire_cli", False) and isinstance(handler, logging.StreamHandler):
            background = non_blocking_handler(handler.stream, handler.formatter or logging.Formatter())
            background.fabwire_cli = True  # type: ignore[attr-defined]
            root.removeHandler(handler)
            root.addHandler(background)
            for name in also:
                other = logging.getLogger(name)
                other.handlers = [background]
                other.propagate = False
