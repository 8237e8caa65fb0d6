"""How a running print looks: one live panel on a terminal, plain lines in order elsewhere, timestamped JSON lines
with --json."""

from __future__ import annotations

import asyncio
import contextlib
import datetime
import os
import sys
from collections.abc import Awaitable, Callable
from types import TracebackType
from typing import TYPE_CHECKING, Any

from fabwire import units
from fabwire.console import Output
from fabwire.errors import InputError
from fabwire.xyz.status import PAUSED, PRINTING, Status

if TYPE_CHECKING:  # rich is imported when a view is drawn, not when the CLI starts
    from rich.console import Console
    from rich.live import Live
    from rich.panel import Panel


def now_iso() -> str:
    """The current UTC time as ISO-8601 with milliseconds, e.g. 2026-01-02T03:04:05.678+00:00."""
    return datetime.datetime.now(datetime.UTC).isoformat(timespec="milliseconds")


def job_line(status: Status) -> str:
    """One line for a log: state in words, temperatures, progress while a job runs."""
    target = status.extruder_target
    parts = [status.state_name, f"extruder {units.heating(status.extruder, target or None)}"]
    if status.bed is not None:
        parts.append(f"bed {units.temperature(status.bed)}")
    if status.progress and status.state_code in (PRINTING, PAUSED):
        parts.append(f"{status.progress.percent} % ({units.minutes(status.progress.remaining_min)} left)")
    return ", ".join(parts)


def _bed_target(status: Status) -> int | None:
    value = (status.targets or {}).get("bed")
    return int(value) if isinstance(value, str) and value.isdigit() else None


KEYS_HINT = "space: pause/resume · c: cancel"


def job_panel(status: Status, title: str, upload: tuple[int, int] | None = None, footer: str | None = None) -> Panel:
    """The live view of a job: state, a progress bar, temperatures with targets, elapsed and time left."""
    from rich.console import Group
    from rich.panel import Panel
    from rich.progress_bar import ProgressBar
    from rich.table import Table

    table = Table.grid(padding=(0, 2))
    table.add_column(style="bold")
    table.add_column()
    if upload is not None:
        done, total = upload
        table.add_row("Upload", Group(ProgressBar(total=max(total, 1), completed=done, width=40),
                                      f"{done} of {total} bytes"))
    table.add_row("State", status.state_name if status.state is not None else units.ABSENT)
    progress = status.progress
    percent = progress.percent if progress else None
    if percent is not None:
        table.add_row("Progress", Group(ProgressBar(total=100, completed=percent, width=40), f"{percent} %"))
    table.add_row("Extruder", units.heating(status.extruder, status.extruder_target))
    if status.bed is not None or _bed_target(status) is not None:
        table.add_row("Bed", units.heating(status.bed, _bed_target(status)))
    table.add_row("Elapsed", units.minutes(progress.elapsed_min if progress else None))
    table.add_row("Time left", units.minutes(progress.remaining_min if progress else None))
    for word in status.error_words:
        table.add_row("Error", str(word))
    return Panel(table, title=title, expand=False, subtitle=footer)


class JobView:
    """Shows statuses as they come: a live panel when `console` is a terminal (and not --json), else one plain line
    per change, or one JSON line per status with its time."""

    def __init__(self, output: Output, console: Console, title: str) -> None:
        self.output = output
        self.console = console
        self.title = title
        self.live_mode = console.is_terminal and not output.json_mode
        self._live: Live | None = None
        self._last_line = ""
        self._status = Status()
        self._upload: tuple[int, int] | None = None
        self.footer: str | None = None
        """A line under the panel (the keys that control the job)."""

    def __enter__(self) -> JobView:
        if self.live_mode:
            from rich.live import Live

            self._live = Live(job_panel(self._status, self.title, footer=self.footer), console=self.console,
                              auto_refresh=False, transient=False)
            self._live.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._live is not None:
            self._live.stop()

    def upload(self, done: int, total: int) -> None:
        if self._live is not None:
            self._upload = (done, total)
            self.redraw()
        elif done >= total and not self.output.json_mode:
            self.console.print(f"uploaded {total} bytes")

    def show(self, status: Status, extra: dict[str, Any] | None = None) -> None:
        self._status = status
        if self.output.json_mode:
            self.output.event({"time": now_iso(), **(extra or {}), **status.to_dict()}, "")
            return
        if self._live is not None:
            self.redraw()
            return
        line = job_line(status)
        if line != self._last_line:
            self._last_line = line
            self.console.print(line)

    @property
    def status(self) -> Status:
        """The last status shown."""
        return self._status

    def redraw(self) -> None:
        if self._live is not None:
            upload = self._upload if self._upload and self._upload[0] < self._upload[1] else None
            self._live.update(job_panel(self._status, self.title, upload, self.footer), refresh=True)

    def note(self, text: str) -> None:
        """A message between updates (link lost, reconnecting)."""
        if self._live is not None:
            self._live.console.print(text)
        else:
            self.output.note(text)


CANCEL_WINDOW_S = 5.0
"""How long after a first `c` a second one cancels the print."""


class JobKeys:
    """Keys on a terminal while a print is followed, as miniMover offers them: space pauses or resumes, `c` twice
    cancels. Active only when standard input is a terminal and the view is live; the terminal's mode is restored
    on exit. `pause`, `resume` and `cancel` are the printer's job commands."""

    def __init__(self, view: JobView, pause: Callable[[], Awaitable[None]], resume: Callable[[], Awaitable[None]],
                 cancel: Callable[[], Awaitable[None]]) -> None:
        self.view = view
        self.actions = {"pause": pause, "resume": resume, "cancel": cancel}
        self._saved: list[Any] | None = None
        self._fd = -1
        self._cancel_asked = -1.0
        self.cancel_sent = False
        """Whether the user cancelled the print with the keys (its end is then the one asked for)."""
        self._tasks: set[asyncio.Task[None]] = set()
        self._toggling: asyncio.Lock | None = None
        """Space presses run one after the other, each deciding from the printer's state after the one before."""

    def __enter__(self) -> JobKeys:
        try:
            import termios
            import tty
        except ImportError:  # no POSIX terminal: no keys
            return self
        fd = sys.stdin.fileno() if sys.stdin is not None else -1
        if not self.view.live_mode or fd < 0 or not os.isatty(fd):
            return self
        self._fd = fd
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)
        asyncio.get_running_loop().add_reader(fd, self._key)
        self.view.footer = KEYS_HINT
        self.view.redraw()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._saved is None:
            return
        import termios

        with contextlib.suppress(Exception):
            asyncio.get_running_loop().remove_reader(self._fd)
        termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)
        self._saved = None

    def _key(self) -> None:
        key = os.read(self._fd, 1)
        now = asyncio.get_running_loop().time()
        if key == b" ":
            self._run("pause/resume")
        elif key in (b"c", b"C"):
            if now - self._cancel_asked <= CANCEL_WINDOW_S:
                self._cancel_asked = -1.0
                self.cancel_sent = True
                self._run("cancel")
                return
            self._cancel_asked = now
            self.view.footer = "press c again to cancel the print"
            self.view.redraw()
            return
        if self.view.footer != KEYS_HINT:
            self.view.footer = KEYS_HINT
            self.view.redraw()

    async def _toggle(self) -> None:
        """Resume a paused print, else pause a running one: the printer's own state decides (the view's may be a
        poll behind), and `resume` refuses (InputError) before it sends anything unless the print is paused."""
        if self._toggling is None:
            self._toggling = asyncio.Lock()
        async with self._toggling:
            try:
                await self.actions["resume"]()
                done = "resume"
            except InputError:
                await self.actions["pause"]()
                done = "pause"
        self.view.footer = f"{done} sent · {KEYS_HINT}"
        self.view.redraw()

    def _run(self, action: str) -> None:
        self.view.footer = f"{action} sent · {KEYS_HINT}"
        self.view.redraw()

        async def act() -> None:
            try:
                if action == "pause/resume":
                    await self._toggle()
                else:
                    await self.actions[action]()
            except Exception as exc:  # the print goes on: say why the key did nothing
                self.view.note(f"{action}: {exc}")

        task = asyncio.get_running_loop().create_task(act())
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
