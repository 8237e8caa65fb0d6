"""Child processes that end when their parent does, whatever ends the parent (SIGKILL, a crash, a power-off of
the terminal): the simulators `fabwire serve --demo` and `fabwire demo` start, and those the tests start.

The lifeline is the child's stdin, a pipe whose write end only the parent holds and never writes to. When the
parent process ends for any reason the kernel closes that end; the child reads end-of-file and stops as it does
on SIGTERM (so a simulator still writes what it records), and leaves at once if it has not stopped within
`GRACE` seconds. Linux's `prctl(PR_SET_PDEATHSIG)` is not used: it fires when the parent *thread* that started
the child ends (the agent starts its simulators from a worker thread), it misses a parent that died before the
child set it, and it exists on Linux only. A pipe has none of these holes and works wherever pipes do.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import threading
from collections.abc import Callable, Mapping, Sequence
from typing import Any

ENV = "FABWIRE_LIFELINE"
"""Set to `stdin` in a child whose stdin is its lifeline; absent otherwise (a simulator run by hand keeps its
terminal's stdin and ignores it)."""
GRACE = 15.0
"""Seconds a child whose parent is gone has to stop by itself before it exits without cleaning up."""


def spawn(command: Sequence[str], *, env: Mapping[str, str] | None = None, **popen: Any) -> subprocess.Popen[Any]:
    """`subprocess.Popen(command, **popen)` with stdin as the child's lifeline (see the module). The parent keeps
    `process.stdin` open for as long as the child should live; closing it asks the child to stop.

    Raises OSError as Popen does; `stdin` may not be given."""
    if "stdin" in popen:
        raise TypeError("spawn() takes the child's stdin for its lifeline")
    child_env = dict(os.environ if env is None else env)
    child_env[ENV] = "stdin"
    return subprocess.Popen(command, stdin=subprocess.PIPE, env=child_env, **popen)


def watch(on_parent_gone: Callable[[], object], *, grace: float = GRACE) -> bool:
    """In a child started by `spawn`: call `on_parent_gone()` (from a watcher thread) when the parent is gone,
    then end the process if it is still running `grace` seconds later. Returns False, watching nothing, in a
    process not started by `spawn`. The variable is taken out of the environment so grandchildren do not
    mistake their own stdin for a lifeline."""
    if os.environ.pop(ENV, None) != "stdin":
        return False
    thread = threading.Thread(target=_wait_for_eof, args=(on_parent_gone, grace), name="fabwire-lifeline",
                              daemon=True)
    thread.start()
    return True


def _wait_for_eof(on_parent_gone: Callable[[], object], grace: float) -> None:
    try:
        while os.read(0, 4096):  # fd 0 itself: sys.stdin may have been replaced
            pass  # the parent never writes; anything that arrives is not a reason to stop
    except OSError:
        pass  # an unreadable lifeline is as good as a cut one
    with contextlib.suppress(Exception):
        on_parent_gone()
    threading.Event().wait(grace)
    os._exit(1)  # still here: whatever was meant to stop the process is stuck, and nobody is left to stop it
