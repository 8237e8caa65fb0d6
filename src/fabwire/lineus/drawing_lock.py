"""One drawing at a time per Line-us on this host, across CLI processes and the agent.

The Line-us takes commands from every connection it has and runs them interleaved, so two programs drawing on one
robot ruin the sheet and both "succeed". Whoever draws holds an exclusive `flock` on a file named after the robot's
address in the user's runtime directory (the OS drops it when the process ends, however it ends), and writes
beside it who they are and how far the drawing has got (`Drawer`): a second drawing is refused with those words,
and the agent shows another program's drawing as the arm's state.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import fcntl
import getpass
import hashlib
import json
import os
import re
import sys
import time
import warnings
from collections.abc import AsyncIterator
from dataclasses import asdict, dataclass
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Self

from fabwire.errors import DeviceBusy, FabwireError
from fabwire.transport import Transport

if TYPE_CHECKING:
    from fabwire.lineus.client import LineUs


def lock_dir() -> Path:
    """`$XDG_RUNTIME_DIR/fabwire/lineus` (platformdirs' user runtime directory; a per-user folder under /tmp where
    the session has none)."""
    from platformdirs import user_runtime_path

    with warnings.catch_warnings():  # platformdirs warns when it falls back to /tmp/runtime-<uid>
        warnings.simplefilter("ignore")
        return user_runtime_path("fabwire") / "lineus"


def robot_address(transport: Transport) -> str:
    """The robot's socket address (`192.168.1.20:1337`) under any wrapping transport, so `line-us.local`,
    `localhost` and the IP address name one robot; the transport's own words where there is no socket."""
    inner: Any = transport
    while getattr(inner, "_inner", None) is not None:
        inner = inner._inner
    writer = getattr(inner, "_writer", None)
    peer = writer.get_extra_info("peername") if isinstance(writer, asyncio.StreamWriter) else None
    if isinstance(peer, tuple) and len(peer) >= 2:
        host = str(peer[0]).removeprefix("::ffff:")
        return f"[{host}]:{peer[1]}" if ":" in host else f"{host}:{peer[1]}"
    return transport.peer or transport.url


@dataclass
class Drawer:
    """Who draws on a robot: process id, command line, user, what is drawn, since when (Unix time), how far."""

    pid: int
    command: str
    user: str
    what: str
    started: float
    progress_percent: float = 0.0
    progress: str = ""

    def words(self) -> str:
        """`'drawing.svg' by `fabwire lineus draw drawing.svg` (process 4242, user ann, since 10:02:07), stroke 3
        of 40`."""
        since = time.strftime("%H:%M:%S", time.localtime(self.started))
        done = f", {self.progress}" if self.progress else ""
        return f"{self.what} by `{self.command}` (process {self.pid}, user {self.user}, since {since}){done}"


def _files(robot: str) -> tuple[Path, Path]:
    name = re.sub(r"[^A-Za-z0-9.-]+", "_", robot)[:60] + "-" + hashlib.sha256(robot.encode()).hexdigest()[:12]
    folder = lock_dir()
    return folder / f"{name}.lock", folder / f"{name}.json"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def current_drawer(robot: str) -> Drawer | None:
    """Who is drawing on `robot` now, or None (no holder, or one whose process has gone)."""
    _, info = _files(robot)
    try:
        data = json.loads(info.read_text(encoding="utf-8"))
        drawer = Drawer(**data)
    except (OSError, ValueError, TypeError):
        return None
    return drawer if isinstance(drawer.pid, int) and _alive(drawer.pid) else None


def _command_line() -> str:
    args = [Path(sys.argv[0]).name, *sys.argv[1:]] if sys.argv and sys.argv[0] else ["python"]
    if args[0] in ("__main__.py", "-m", "-c"):
        args[0] = "fabwire"
    text = " ".join(args)
    return text if len(text) <= 160 else text[:159] + "…"


class DrawingLock:
    """`with DrawingLock(robot, "'cat.svg'"):` draws alone on `robot` (an address from `robot_address`), or raises
    DeviceBusy naming who draws there. `update(percent, words)` tells other programs how far the drawing got."""

    def __init__(self, robot: str, what: str, *, command: str | None = None) -> None:
        self.robot = robot
        self.drawer = Drawer(os.getpid(), command or _command_line(), getpass.getuser(), what, time.time())
        self._fd: int | None = None
        self._lock_path, self._info_path = _files(robot)

    def acquire(self) -> None:
        self._lock_path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        fd = os.open(self._lock_path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise
            holder = current_drawer(self.robot)
            who = holder.words() if holder is not None else "another program (it has not said what yet)"
            raise DeviceBusy(f"the Line-us at {self.robot} is drawing already: {who}; wait for it to finish or "
                             "stop it (Ctrl-C, or cancel the job in the agent) first") from None
        self._fd = fd
        self._write()

    def update(self, percent: float, progress: str) -> None:
        self.drawer.progress_percent, self.drawer.progress = round(percent, 1), progress
        self._write()

    def _write(self) -> None:
        tmp = self._info_path.with_name(f"{self._info_path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(asdict(self.drawer)), encoding="utf-8")
        tmp.replace(self._info_path)

    def release(self) -> None:
        fd, self._fd = self._fd, None
        if fd is None:
            return
        with contextlib.suppress(OSError):
            self._info_path.unlink()
        os.close(fd)  # closing the descriptor drops the flock

    def __enter__(self) -> Self:
        self.acquire()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.release()


@contextlib.asynccontextmanager
async def drawing_alone(arm: LineUs, what: str, *, command: str | None = None) -> AsyncIterator[DrawingLock]:
    """`async with drawing_alone(arm, "'cat.svg'") as lock:` draw holding the robot's `DrawingLock`; an interrupt
    (Ctrl-C, a cancelled task) lifts the pen before it goes on, so the connection does not close on a pen left
    down on the paper."""
    with DrawingLock(robot_address(arm.transport), what, command=command) as lock:
        try:
            yield lock
        except (asyncio.CancelledError, KeyboardInterrupt):
            with contextlib.suppress(FabwireError, OSError):
                await asyncio.shield(arm.lift_after_stop())
            raise
