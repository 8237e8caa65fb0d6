"""Stopping long work that nobody waits for any more, between its steps: whoever runs the work (the agent's
`fabwire.agent.offload.in_thread`) gives it a flag; the work calls `check_cancelled()` at points where stopping
leaves nothing half done (between the elements of a drawing, between a file's stages). Outside such work (a CLI
command) the check does nothing.
"""

from __future__ import annotations

import contextvars
import threading

FLAG: contextvars.ContextVar[threading.Event | None] = contextvars.ContextVar("fabwire_work_cancelled",
                                                                              default=None)
"""The running work's flag, set once nobody waits for it; None outside such work."""


class WorkCancelled(Exception):
    """The work was stopped between two of its steps: whoever waited for it is gone."""


def check_cancelled() -> None:
    """WorkCancelled when the work running in this thread was cancelled; nothing elsewhere (a CLI command)."""
    flag = FLAG.get()
    if flag is not None and flag.is_set():
        raise WorkCancelled("stopped: nobody waits for this work any more")
