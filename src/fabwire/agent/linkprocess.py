"""The agent's links in a child process (`fabwire.agent.linkworker`): its polls take none of the interpreter the
agent's API answers with. The child starts with the first link opened in it and ends when the agent ends (it exits
when the socket between them closes, however the agent ended). When the child dies, every call waiting on it
fails with a LinkError saying so: the machines go offline with that reason, and their reconnection starts a new
child."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import signal
import socket
import subprocess
import sys
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fabwire.agent.core import DeviceSpec
from fabwire.agent.drivers.base import Identity
from fabwire.agent.links import LinkOwner
from fabwire.agent.linkside import Polled, make_driver
from fabwire.agent.linkthread import SWITCH_INTERVAL_S
from fabwire.agent.linkwire import Unframer, frame, unpack_error
from fabwire.errors import LinkError

if TYPE_CHECKING:
    from fabwire.agent.session import RequestsFirst

log = logging.getLogger("fabwire.agent")
REAP_WAIT_S = 2.0
"""How long a child whose socket closed may take to exit before it is killed."""
ENDED = "the links' process ended"
HOLD_S = 0.02
"""How long polls' results may wait for the agent's requests in flight to be answered before they are handled."""
POLLS_PER_TURN = 8
"""Polls' results handled in one turn of the agent's loop: a request that arrives meanwhile waits for no more."""


class LinkProcess:
    """The child process hosting an agent's device links, and the calls waiting on it. On the agent's loop."""

    def __init__(self, requests: RequestsFirst | None = None) -> None:
        self.home = asyncio.get_running_loop()
        # The agent's own threads (the history's writer, a check of an upload) hand the interpreter back every
        # 0.5 ms rather than 5: a request waits for them at most that long at each step of its handling.
        sys.setswitchinterval(min(sys.getswitchinterval(), SWITCH_INTERVAL_S))
        self._requests = requests
        """The agent's requests in flight: polls' results wait for them (HOLD_S at most)."""
        self._polls: deque[tuple[Any, ...]] = deque()
        self._polls_since = 0.0
        self._draining = False
        self._held = False
        self.on_empty: Any = lambda: None
        """Called when its last link is released (and the child told to end)."""
        self._links: dict[int, ProcessLink] = {}
        self._next_link = 0
        self._next_call = 0
        self._calls: dict[int, asyncio.Future[Any]] = {}
        self._child: subprocess.Popen[bytes] | None = None
        self._transport: Any = None
        """The socket to the child: an asyncio.Transport's interface (uvloop's are not its subclasses)."""
        self._starting: asyncio.Future[None] | None = None
        self._reason = ENDED
        """Why there is no child (after one died): the message of the LinkError calls get."""

    @property
    def pid(self) -> int | None:
        """The child's process id while it runs."""
        return self._child.pid if self._child is not None and self._transport is not None else None

    def open(self, spec: DeviceSpec, owner: LinkOwner) -> ProcessLink:
        """A link to the machine of `spec` in the child, reporting to `owner`."""
        self._next_link += 1
        link = ProcessLink(self, self._next_link, spec, owner)
        self._links[link.number] = link
        if self._transport is not None:
            self._send(("open", link.number, link.spec))
        return link

    def release(self, link: ProcessLink) -> None:
        if self._links.pop(link.number, None) is None:
            return
        if self._transport is not None:
            self._send(("drop", link.number))
        if not self._links:
            self.close()
            self.on_empty()

    def close(self) -> None:
        """End the child: it exits when its socket closes."""
        transport, self._transport = self._transport, None
        if transport is not None:
            transport.close()
        self._reason = ENDED

    # -------------------------------------------------------------------------------------- calls

    async def call(self, link: int, operation: str, *args: Any, start: bool = True) -> Any:
        """`operation` of link number `link` in the child, its result or its exception; `start`: start a child if
        none runs (else LinkError when there is none)."""
        if self._transport is None:
            if not start:
                raise LinkError(self._reason)
            await self._start()
        self._next_call += 1
        number = self._next_call
        future: asyncio.Future[Any] = self.home.create_future()
        self._calls[number] = future
        self._send(("call", number, link, operation, args))
        try:
            return await future
        except asyncio.CancelledError:
            if self._calls.pop(number, None) is not None and self._transport is not None:
                self._send(("cancel", number))
            raise

    def _send(self, message: Any) -> None:
        if self._transport is not None:
            self._transport.write(frame(message))

    # -------------------------------------------------------------------------------------- the child

    async def _start(self) -> None:
        if self._starting is None:
            self._starting = self.home.create_future()
            try:
                await self._spawn()
            except BaseException as exc:
                failed = LinkError(f"the links' process could not start: {exc or type(exc).__name__}")
                self._starting.set_exception(failed)
                self._starting.exception()  # retrieved: those waiting get it from there
                if isinstance(exc, Exception):
                    raise failed from exc
                raise  # cancelled (the session stops): that, not a link's failure
            else:
                self._starting.set_result(None)
            finally:
                self._starting = None
        else:
            await asyncio.shield(self._starting)

    async def _spawn(self) -> None:
        ours, child = _spawn_child()
        try:
            transport, _ = await self.home.connect_accepted_socket(lambda: _FromChild(self, child), ours)
        except BaseException:
            child.kill()
            raise
        self._child = child
        self._transport = transport
        log.info("links' process %d started", child.pid)
        for link in self._links.values():
            link.forget_last()
            self._send(("open", link.number, link.spec))

    def _child_lost(self, child: subprocess.Popen[bytes], transport: asyncio.BaseTransport) -> None:
        """The socket to `child` closed: what waited on it fails once it has exited (bounded), with why."""
        on_purpose = self._transport is not transport
        if not on_purpose:
            self._transport = None
        calls, self._calls = self._calls, {}
        self.home.create_task(self._reap(child, calls, on_purpose=on_purpose))

    async def _reap(self, child: subprocess.Popen[bytes], calls: dict[int, asyncio.Future[Any]], *,
                    on_purpose: bool) -> None:
        code = child.poll()
        for _ in range(int(REAP_WAIT_S / 0.01)):
            if code is not None:
                break
            await asyncio.sleep(0.01)
            code = child.poll()
        if code is None:
            child.kill()
            code = await asyncio.to_thread(child.wait)
        if self._child is child:
            self._child = None
        reason = ENDED
        if not on_purpose:
            reason = self._reason = f"{ENDED} ({_how(code)}); it starts again with the next connection"
            log.warning("%s", reason)
        for future in calls.values():
            if not future.done():
                future.set_exception(LinkError(reason))

    def _on_message(self, message: tuple[Any, ...]) -> None:
        kind = message[0]
        if kind == "polls":
            if not self._polls:
                self._polls_since = self.home.time()
            self._polls.extend(message[1])
            if not self._draining:
                self._draining = True
                self.home.call_soon(self._drain)
        elif kind == "ok" or kind == "err":
            future = self._calls.pop(message[1], None)
            if future is not None and not future.done():
                if kind == "ok":
                    future.set_result(message[2])
                else:
                    future.set_exception(unpack_error(message[2]))
        elif kind == "event":
            link = self._links.get(message[1])
            if link is not None:
                self._run(link.owner.device_event, message[2])
        elif kind == "job":
            link = self._links.get(message[1])
            if link is not None:
                self._run(getattr(link.owner, f"job_{message[2]}"), *message[3])
        elif kind == "log":
            logging.getLogger(message[1]).log(message[2], "%s", message[3])

    def _drain(self) -> None:
        """Hand polls' results to their sessions, POLLS_PER_TURN a turn of the loop; while requests are in flight,
        after them, as long as the oldest result waiting has waited less than HOLD_S."""
        requests = self._requests
        if requests is not None and requests.busy and self.home.time() - self._polls_since < HOLD_S:
            self._held = True
            requests.when_idle(self._resume)
            self.home.call_later(HOLD_S, self._resume)
            return
        polls = self._polls
        links = self._links
        for _ in range(min(POLLS_PER_TURN, len(polls))):
            link_number, status, summary, at, lag, interval = polls.popleft()
            link = links.get(link_number)
            if link is not None:
                self._run(link.polled, status, summary, at, lag, interval)
        if polls:
            self.home.call_soon(self._drain)
        else:
            self._draining = False

    def _resume(self) -> None:
        if self._held:
            self._held = False
            self._drain()

    def _run(self, callback: Any, *args: Any) -> None:
        """As if scheduled on its own: a callback that fails is reported and the rest still run."""
        try:
            callback(*args)
        except Exception as exc:
            self.home.call_exception_handler({"message": f"exception in callback {callback!r}", "exception": exc})


def _spawn_child() -> tuple[socket.socket, subprocess.Popen[bytes]]:
    """A new child, and the agent's end of the socket to it (the child has the other end)."""
    import fabwire

    ours, theirs = socket.socketpair()
    try:
        env = dict(os.environ)
        source = str(Path(fabwire.__file__).resolve().parents[1])  # the child imports the same fabwire
        env["PYTHONPATH"] = os.pathsep.join(p for p in (source, env.get("PYTHONPATH")) if p)
        level = str(logging.getLogger("fabwire").getEffectiveLevel())  # -v, -vv: the wire's bytes too
        child = subprocess.Popen([sys.executable, "-m", "fabwire.agent.linkworker", str(theirs.fileno()), level],
                                 pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL, env=env)
    except BaseException:
        ours.close()
        raise
    finally:
        theirs.close()
    return ours, child


def _how(code: int) -> str:
    if code < 0:
        with contextlib.suppress(ValueError):
            return f"killed by {signal.Signals(-code).name}"
        return f"killed by signal {-code}"
    return f"exit code {code}"


class _FromChild(asyncio.Protocol):
    def __init__(self, process: LinkProcess, child: subprocess.Popen[bytes]) -> None:
        self._process = process
        self._child = child
        self._transport: asyncio.BaseTransport | None = None
        self._unframer = Unframer(process._on_message)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = transport

    def data_received(self, data: bytes) -> None:
        self._unframer.feed(data)

    def connection_lost(self, exc: Exception | None) -> None:
        assert self._transport is not None
        self._process._child_lost(self._child, self._transport)


class ProcessLink:
    """A `fabwire.agent.links.DeviceLink` whose driver lives in a `LinkProcess`'s child."""

    def __init__(self, process: LinkProcess, number: int, spec: DeviceSpec, owner: LinkOwner) -> None:
        self.process = process
        self.number = number
        self.spec = DeviceSpec(spec.name, spec.kind, spec.address, dict(spec.options), spec.fixed_id)
        self.owner = owner
        self.driver = make_driver(spec, owner.device_event)
        self._status: dict[str, Any] | None = None
        self._summary: dict[str, Any] | None = None

    def polled(self, status: Any, summary: Any, at: float, lag: float, interval: float) -> None:
        """A scheduled poll from the child: a status or summary it marked unchanged is the very one before."""
        if isinstance(status, str):
            status = self._status
        else:
            self._status = status
        if isinstance(summary, str):
            summary = self._summary
        else:
            self._summary = summary
        self.owner.polled(status, summary, at, lag, interval)

    def forget_last(self) -> None:
        self._status = self._summary = None

    async def connect(self) -> Identity:
        result: Identity = await self.process.call(self.number, "connect")
        return result

    async def close(self) -> None:
        with contextlib.suppress(LinkError):  # no child: nothing is open
            await self.process.call(self.number, "close", start=False)

    async def poll_forever(self) -> None:
        await self.process.call(self.number, "poll_forever", start=False)

    async def poll_now(self) -> Polled | None:
        result: Polled | None = await self.process.call(self.number, "poll_now", start=False)
        return result

    async def act(self, action: str, params: dict[str, Any]) -> dict[str, Any]:
        result: dict[str, Any] = await self.process.call(self.number, "act", action, params, start=False)
        return result

    async def act_then_poll(self, action: str, params: dict[str, Any]) -> tuple[dict[str, Any], Polled | None]:
        result: tuple[dict[str, Any], Polled | None] = await self.process.call(
            self.number, "act_then_poll", action, params, start=False)
        return result

    async def run_job(self, path: Path | None, job_type: str, params: dict[str, Any]) -> str:
        result: str = await self.process.call(self.number, "run_job", path, job_type, params, start=False)
        return result

    async def stop_job(self) -> None:
        await self.process.call(self.number, "stop_job", start=False)

    async def check_upload(self, name: str, path: Path) -> None:
        await self.process.call(self.number, "check_upload", name, path)

    async def describe_upload(self, name: str, path: Path, *, check: bool) -> dict[str, Any]:
        result: dict[str, Any] = await self.process.call(self.number, "describe_upload", name, path, check)
        return result

    def release(self) -> None:
        self.process.release(self)
