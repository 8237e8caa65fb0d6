"""One drawing at a time per Line-us on this host, across CLI processes and the agent.

The Line-us takes commands from every connection it has and runs them interleaved, so two programs drawing on one
robot ruin the sheet and both "succeed". Whoever draws holds an exclusive `flock` on a file named after the robot's
address in one folder for the whole host (`lock_dir`: every user and the agent's service see it; the OS drops the
lock when the process ends, however it ends), and writes beside it who they are and how far the drawing has got
(`Drawer`): a second drawing is refused with those words, and the agent shows another program's drawing as the
arm's state.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import fcntl
import getpass
import glob
import hashlib
import json
import os
import re
import sys
import tempfile
import time
import warnings
from collections.abc import AsyncIterator
from dataclasses import asdict, dataclass
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Self

from fabwire.errors import DeviceBusy, FabwireError, LinkError
from fabwire.transport import Transport

if TYPE_CHECKING:
    from fabwire.lineus.client import LineUs


SHARED_LOCK_DIRS = (Path("/run/lock"), Path(tempfile.gettempdir()))
"""Where a lock every process of the host sees can live: /run/lock (FHS 3.0 §3.15.5, "lock files"; a systemd
service's PrivateTmp hides /tmp from it, not /run/lock), else the temporary directory (macOS)."""
LOCK_FOLDER = "fabwire-lineus"


def lock_dir() -> Path:
    """`/run/lock/fabwire-lineus`, a folder every user may add to (sticky, as /tmp is), so the owner's shell and the
    agent's service (another account) see each other's drawings; the user's runtime directory where no shared
    folder can be written."""
    for base in SHARED_LOCK_DIRS:
        if base.is_dir() and os.access(base, os.W_OK | os.X_OK):
            return base / LOCK_FOLDER
    from platformdirs import user_runtime_path

    with warnings.catch_warnings():  # platformdirs warns when it falls back to /tmp/runtime-<uid>
        warnings.simplefilter("ignore")
        return user_runtime_path("fabwire") / "lineus"


def _shared_folder() -> Path:
    """`lock_dir`, made if missing with the sticky bit and room for every user (umask left aside)."""
    folder = lock_dir()
    try:
        folder.mkdir(parents=True)
    except FileExistsError:
        return folder
    with contextlib.suppress(OSError):
        folder.chmod(0o1777)
    return folder


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


def _stem(robot: str) -> str:
    return re.sub(r"[^A-Za-z0-9.-]+", "_", robot)[:60] + "-" + hashlib.sha256(robot.encode()).hexdigest()[:12]


def _files(robot: str, pid: int) -> tuple[Path, Path]:
    """The robot's lock file, and the words of drawer `pid` (one file per process: in a sticky folder a file is
    replaced or removed only by its own user, so a drawer never needs another's)."""
    folder = lock_dir()
    return folder / f"{_stem(robot)}.lock", folder / f"{_stem(robot)}.{pid}.json"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def _held(robot: str) -> bool:
    """Whether some process holds `robot`'s lock: taking it for a moment fails then."""
    try:
        fd = os.open(_files(robot, 0)[0], os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW)
    except OSError:
        return False  # no lock file: nobody has drawn there since the host started
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)  # (releases the moment's lock with it)
    return False


def current_drawer(robot: str) -> Drawer | None:
    """Who is drawing on `robot` now, or None (nobody holds its lock; words left by a process that has gone, whose
    number may belong to another program by now, are not believed)."""
    if not _held(robot):
        return None
    found: list[Drawer] = []
    with contextlib.suppress(OSError):
        for info in lock_dir().glob(f"{glob.escape(_stem(robot))}.*.json"):
            try:
                drawer = Drawer(**json.loads(info.read_text(encoding="utf-8")))
            except (OSError, ValueError, TypeError):
                continue
            if isinstance(drawer.pid, int) and _alive(drawer.pid):
                found.append(drawer)
    return max(found, key=lambda d: d.started, default=None)


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
        self._lock_path, self._info_path = _files(robot, os.getpid())

    def acquire(self) -> None:
        _shared_folder()
        # read-only is enough for flock, so a lock file another user made serves every user (it is 0644)
        try:
            fd = os.open(self._lock_path, os.O_RDONLY | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, 0o644)
        except OSError as exc:
            raise LinkError(f"cannot open the drawing lock {self._lock_path}: {exc.strerror or exc}") from None
        with contextlib.suppress(OSError):
            os.fchmod(fd, 0o644)  # whatever the umask: the owner's (it fails quietly on another user's file)
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
        tmp = self._info_path.with_name(f"{self._info_path.name}.tmp")
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        # a file of its own, never followed through a link someone else put there
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
        with os.fdopen(fd, "w", encoding="utf-8") as out:
            out.write(json.dumps(asdict(self.drawer)))
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
