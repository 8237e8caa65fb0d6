"""Blocking work the agent hands to a thread (checking an upload, planning a drawing) that stops when nobody
waits for it any more: the uploader went away (`while_connected`), the job was cancelled, the agent is stopping.

`in_thread(func, ...)` runs `func` in a daemon thread of its own, so a stopping agent never waits for it (a
thread of asyncio's default executor would hold the interpreter's exit until it ends). When the awaiting task is
cancelled, or `cancel` is set, the work's flag is set; the work reads it with `check_cancelled()` between its
stages and raises WorkCancelled there. A stage already under way runs to its end (Python cannot interrupt a
thread), which the intake's own bounds keep short.
"""

from __future__ import annotations

import asyncio
import contextlib
import contextvars
import os
import threading
import weakref
from collections.abc import Callable, Coroutine
from typing import TYPE_CHECKING, Any, TypeVar

from fabwire.cancelling import FLAG as _FLAG
from fabwire.cancelling import WorkCancelled, check_cancelled
from fabwire.errors import InputError

if TYPE_CHECKING:
    from starlette.requests import Request

T = TypeVar("T")

__all__ = ["CHECK_LIMIT_S", "WorkCancelled", "check_cancelled", "check_within", "in_thread", "while_connected"]

CHECK_LIMIT_S = 120.0
"""Longest an upload's check (reading and planning the file) may take; past it the upload is refused and the
check stops at its next step."""

WORKERS = min(32, (os.cpu_count() or 1) + 4)
"""Works running at once per event loop, as many as asyncio's default executor has threads; a cancelled work keeps
its place until its thread has ended, so the threads are bounded even when their callers leave."""
_SLOTS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, asyncio.Semaphore] = weakref.WeakKeyDictionary()

async def in_thread(func: Callable[..., T], /, *args: Any, cancel: threading.Event | None = None) -> T:
    """`func(*args)` in a daemon thread, its result or exception returned here; `cancel` (made when not given)
    is the flag `check_cancelled` reads, set when this call is cancelled."""
    loop = asyncio.get_running_loop()
    slots = _SLOTS.setdefault(loop, asyncio.Semaphore(WORKERS))
    await slots.acquire()
    done: asyncio.Future[T] = loop.create_future()
    flag = cancel if cancel is not None else threading.Event()
    context = contextvars.copy_context()
    context.run(_FLAG.set, flag)

    def settle(result: T | None, error: BaseException | None) -> None:
        if done.done():
            return
        if error is not None:
            done.set_exception(error)
        else:
            done.set_result(result)  # type: ignore[arg-type]

    def work() -> None:
        try:
            result = context.run(func, *args)
        except BaseException as exc:  # handed to the awaiting task, which raises it
            outcome: tuple[T | None, BaseException | None] = (None, exc)
        else:
            outcome = (result, None)
        with contextlib.suppress(RuntimeError):  # the loop is closed: nobody is left to tell
            loop.call_soon_threadsafe(settle, *outcome)
            loop.call_soon_threadsafe(slots.release)

    try:
        threading.Thread(target=work, name=f"fabwire {getattr(func, '__name__', 'work')}", daemon=True).start()
    except BaseException:
        slots.release()
        raise
    try:
        return await done
    except asyncio.CancelledError:
        flag.set()
        raise


async def check_within(func: Callable[..., T], /, *args: Any, name: str) -> T:
    """`in_thread(func, *args)` within CHECK_LIMIT_S; past it InputError naming the upload `name` (the work is
    told to stop, as when its caller leaves)."""
    limit = asyncio.timeout(CHECK_LIMIT_S)
    try:
        async with limit:
            return await in_thread(func, *args)
    except TimeoutError:
        if limit.expired():
            raise InputError(f"{name}: checking it took longer than {CHECK_LIMIT_S:g} s; refusing it") from None
        raise


async def while_connected(request: Request, work: Coroutine[Any, Any, T], body_read: asyncio.Event | None = None
                          ) -> T:
    """`work`'s result, unless the client disconnects once its body is read (`body_read`; None: read already),
    while the upload is checked: then `work` is cancelled (its claim released, its file deleted, its checking
    thread told to stop) and ClientDisconnect ends the request, which the boundary logs."""
    from starlette.requests import ClientDisconnect

    async def gone() -> None:
        if body_read is not None:
            await body_read.wait()
        while (await request.receive())["type"] != "http.disconnect":
            pass

    task = asyncio.ensure_future(work)
    watch = asyncio.ensure_future(gone())
    try:
        await asyncio.wait({task, watch}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        watch.cancel()
        if not task.done():
            task.cancel()
    if task.done() and not task.cancelled():
        return task.result()
    with contextlib.suppress(BaseException):
        await task  # the claim is released before the request ends
    raise ClientDisconnect()
