"""Where output goes: results on stdout (JSON with --json), people's text and progress on stderr.

The rich consoles are made on first use, so a command that prints JSON or one plain line never imports rich.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TextIO

if TYPE_CHECKING:
    from rich.console import Console


class StdoutClosed(BaseException):
    """The reader of stdout went away (`fabwire trace show | head`): the command ends quietly with exit code 0.

    A BaseException, as KeyboardInterrupt is, so that it unwinds the command (links and partial files closed on
    the way) rather than being reported as an error, and never taken for a device link's broken pipe."""


class _GuardedStream:
    """A stream whose broken pipe is StdoutClosed; everything else is the stream's own."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream

    def write(self, data: Any) -> int:
        try:
            return int(self._stream.write(data))
        except BrokenPipeError:
            raise StdoutClosed from None

    def writelines(self, lines: Any) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            raise StdoutClosed from None

    @property
    def buffer(self) -> Any:
        return _GuardedStream(self._stream.buffer)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def guard_stdout() -> None:
    """Make a closed stdout StdoutClosed (see `stdout_closed` for the end); for the entry point only."""
    if sys.stdout is not None and not isinstance(sys.stdout, _GuardedStream):
        sys.stdout = _GuardedStream(sys.stdout)


def stdout_closed() -> int:
    """End after StdoutClosed: what is still buffered goes nowhere (so that the interpreter's last flush is quiet,
    as Python's note on SIGPIPE advises), and the exit code is 0."""
    import os

    with open(os.devnull, "wb") as devnull:
        os.dup2(devnull.fileno(), sys.__stdout__.fileno() if sys.__stdout__ is not None else 1)
    return 0


def _default(value: object) -> object:
    if isinstance(value, bytes):
        return value.decode("latin-1")
    if hasattr(value, "__dict__"):
        return vars(value)
    return str(value)


MAX_WIDTH = 110
"""The widest help and tables are laid out, on a terminal or not (the help's `max_content_width`)."""


def columns(stream: Any = None) -> int | None:
    """The width output is laid out to: $COLUMNS when set (as click and rich read it), else the width of the
    terminal `stream` (default stdout) is; None when it is no terminal."""
    given = os.environ.get("COLUMNS", "")
    if given.isdigit() and int(given) > 0:
        return int(given)
    target = stream or sys.__stdout__
    try:
        return os.get_terminal_size(target.fileno()).columns if target is not None else None
    except (ValueError, OSError):  # not a terminal, or closed
        return None


def help_width() -> int:
    """Columns of `--help` text: click's rule (the terminal's width less 2, between 50 and `MAX_WIDTH`), with
    `MAX_WIDTH` rather than click's 80 when the help goes to a pipe or a file, as the tables do."""
    return max(min(columns() or MAX_WIDTH, MAX_WIDTH) - 2, 50)


def _console(stderr: bool) -> Console:
    from fabwire.importing import collection_paused

    with collection_paused():
        from rich.console import Console

    stream = sys.__stderr__ if stderr else sys.__stdout__
    try:
        terminal = stream is not None and stream.isatty()
    except ValueError:  # closed
        terminal = False
    # Off a terminal (a pipe, a log), lines are never broken (a path stays whole) and tables get $COLUMNS or
    # `MAX_WIDTH` columns, not rich's 80; on one, rich follows the terminal's width.
    # Markup and emoji codes off: device names, SSIDs and file names are printed as they are, never read as rich markup.
    return Console(stderr=stderr, highlight=False, markup=False, emoji=False,
                   width=None if terminal else columns(stream) or MAX_WIDTH, soft_wrap=not stderr or not terminal)


def console(stderr: bool = False) -> Console:
    """A rich console for fabwire's output (see `Output.out` / `Output.err`, which keep one each)."""
    return _console(stderr)


RICH_TERMINAL_VARIABLES = ("FORCE_TERMINAL", "FORCE_COLOR", "TTY_COMPATIBLE")
"""Environment variables by which rich treats a stream that is not a terminal as one (rich's
`Console.is_terminal`): where one is set, rich decides."""


class PlainLines:
    """Lines of text on a stream that is not a terminal, without importing rich: the part of rich's Console that a
    view printing one line per change uses (`is_terminal`, `print`). Text is written as it is: no markup, no
    wrapping, one line per `print`."""

    is_terminal = False

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream

    def print(self, *objects: object, markup: bool | None = None) -> None:
        self.stream.write(" ".join(map(str, objects)) + "\n")
        self.stream.flush()


def _terminal_like(stream: TextIO) -> bool:
    """Whether rich could draw on `stream`: a terminal, or one of RICH_TERMINAL_VARIABLES set."""
    if any(name in os.environ for name in RICH_TERMINAL_VARIABLES):
        return True
    try:
        return stream.isatty()
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


class Output:
    def __init__(self, json_mode: bool = False) -> None:
        self.json_mode = json_mode
        self._err: Console | None = None
        self._out: Console | None = None

    @property
    def err(self) -> Console:
        """The rich console on stderr (progress bars, notes)."""
        if self._err is None:
            self._err = _console(stderr=True)
        return self._err

    @property
    def out(self) -> Console:
        """The rich console on stdout (human results)."""
        if self._out is None:
            self._out = _console(stderr=False)
        return self._out

    def lines_err(self) -> Console | PlainLines:
        """Where a view prints its lines on stderr: the rich console when rich could draw there (a terminal), else
        plain lines, so a command whose stderr is a file or a pipe never imports rich for them."""
        if self._err is None and not _terminal_like(sys.stderr):
            return PlainLines(sys.stderr)
        return self.err

    def _line(self, stream: Any, text: str) -> None:
        stream.write(text + "\n")
        stream.flush()

    def _json_line(self, data: Any) -> None:
        """One JSON document on a line of stdout, always valid UTF-8.

        Names from the file system or a device may hold lone surrogates (undecodable bytes kept by
        surrogateescape); those become `\\udcXX` JSON escapes instead of reaching stdout as raw bytes.
        """
        text = json.dumps(data, default=_default, ensure_ascii=False)
        text = text.encode("utf-8", "backslashreplace").decode("utf-8")
        self._line(sys.stdout, text)

    def result(self, data: Any, human: Callable[[], None] | str | None = None) -> None:
        """Print a command's result: `data` as one JSON document, or `human` for people."""
        if self.json_mode:
            self._json_line(data)
        elif callable(human):
            human()
        elif human is not None:
            self._line(sys.stdout, human)  # plain text: names and replies may contain [brackets]
        else:
            self.out.print(data)

    def event(self, data: dict[str, Any], human: str) -> None:
        """One item of a stream (monitor, progress): a JSON line per event, or a line of text."""
        if self.json_mode:
            self._json_line(data)
        else:
            self._line(sys.stdout, human)

    def note(self, text: str) -> None:
        """Text for people only, never on stdout."""
        if self._err is None:
            self._line(sys.stderr, text)
        else:
            self._err.print(text, markup=False)  # keeps a live progress bar below the note
