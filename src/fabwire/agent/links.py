"""Where an agent's device links run, and the one interface its sessions use for them.

A few machines' links share a thread with the agent (`fabwire.agent.linkthread`): no process to start, no bytes
to copy. From LINK_PROCESS_FROM machines on, they run in a child process (`fabwire.agent.linkprocess`): the polls
of a large bench then take none of the interpreter the agent's API answers with, so a request's latency does not
grow with the number of machines. `$FABWIRE_LINKS` = `thread` or `process` puts every link in one of them
(`auto`, the default, chooses as above); a `sim://` machine lives in the agent's own process and stays on the
thread whatever is chosen.
"""

from __future__ import annotations

import os
import weakref
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from fabwire.agent.core import DeviceSpec
from fabwire.agent.drivers.base import Driver, Identity
from fabwire.agent.linkside import Polled

if TYPE_CHECKING:
    from fabwire.agent.core import Agent
    from fabwire.agent.linkprocess import LinkProcess
    from fabwire.agent.linkthread import LinkThread

LINK_PROCESS_FROM = 20
"""Machines from which an agent's links run in a process of their own. A typical owner's 1-3 machines pay no
second interpreter (some 45 MB resident, about a second to start); a bench's polls, sharing the agent's, would make
its API's p99 latency grow with their number (2.3x from 250 to 1,000 printers on a loaded machine)."""
LINKS_ENV = "FABWIRE_LINKS"
LINK_MODES = ("auto", "thread", "process")


class LinkOwner(Protocol):
    """What a link reports to, on the agent's loop (a session)."""

    def polled(self, status: dict[str, Any] | None, summary: dict[str, Any], at: float, lag: float,
               interval: float) -> None:
        """A scheduled poll's result: status, summary, wall-clock time (s), lag behind its slot (s), interval (s)."""

    def device_event(self, payload: dict[str, Any]) -> None:
        """Something the machine reported on its own (an `"event"` payload)."""

    def job_progress(self, percent: float, time_left_s: float | None, message: str | None) -> None: ...

    def job_stroke(self, points: list[tuple[float, float]]) -> None: ...

    def job_preview(self, strokes: list[list[tuple[float, float]]]) -> None: ...

    def job_note(self, text: str) -> None: ...


class DeviceLink(Protocol):
    """One machine's link, wherever it runs. Every method raises what the driver raised, as the same class with the
    same message; cancelling a call cancels the work."""

    driver: Driver
    """A driver of the machine's kind, for what needs no link (its actions, job types, checks of an upload)."""

    async def connect(self) -> Identity: ...

    async def close(self) -> None: ...

    async def poll_forever(self) -> None:
        """Poll on the grid's schedule, each result to `LinkOwner.polled`, until cancelled or the link fails."""

    async def poll_now(self) -> Polled | None:
        """A poll out of turn, or None when it fails."""

    async def act(self, action: str, params: dict[str, Any]) -> dict[str, Any]: ...

    async def act_then_poll(self, action: str, params: dict[str, Any]) -> tuple[dict[str, Any], Polled | None]: ...

    async def run_job(self, path: Path | None, job_type: str, params: dict[str, Any]) -> str:
        """The driver's `run_job`, its reports to `LinkOwner.job_progress` and the like."""

    async def stop_job(self) -> None: ...

    async def check_upload(self, name: str, path: Path) -> None:
        """The driver's `check_upload` of the stored upload at `path`, in a thread beside the link's driver (its
        checks read what the machine last said: a printer's model); cancelling the wait stops it between stages."""

    async def describe_upload(self, name: str, path: Path, *, check: bool) -> dict[str, Any]:
        """The driver's `describe_upload`, as `check_upload` runs it."""

    def release(self) -> None:
        """This link is no longer used (after its `close`)."""


class _Hosts:
    """An agent's links' thread and process, each started with the first link it hosts."""

    def __init__(self) -> None:
        self.thread: LinkThread | None = None
        self.process: LinkProcess | None = None


_HOSTS: weakref.WeakKeyDictionary[Agent, _Hosts] = weakref.WeakKeyDictionary()


def links_mode() -> str:
    """`$FABWIRE_LINKS` (auto, thread or process); auto when unset or unknown."""
    mode = os.environ.get(LINKS_ENV, "auto").strip().lower()
    return mode if mode in LINK_MODES else "auto"


def in_process(spec: DeviceSpec) -> bool:
    """Whether the machine exists only inside the agent's process (an in-process simulator)."""
    return spec.address.startswith("sim://")


def wants_process(agent: Agent, spec: DeviceSpec, order: int) -> bool:
    """Whether the link of the `order`-th machine added (from 0) runs in the links' process."""
    if in_process(spec):
        return False
    mode = agent.links if agent.links != "auto" else links_mode()
    if mode != "auto":
        return mode == "process"
    return max(agent.expected_devices, order + 1) >= LINK_PROCESS_FROM


def open_link(agent: Agent, spec: DeviceSpec, owner: LinkOwner, order: int) -> DeviceLink:
    """A link to the machine of `spec` for `owner`, in the agent's links' process or on its links' thread."""
    hosts = _HOSTS.get(agent)
    if hosts is None:
        hosts = _HOSTS[agent] = _Hosts()
    if wants_process(agent, spec, order):
        from fabwire.agent.linkprocess import LinkProcess

        if hosts.process is None:
            process = hosts.process = LinkProcess(agent.requests)
            process.on_empty = lambda: _forget(agent, process)
        return hosts.process.open(spec, owner)
    from fabwire.agent.linkthread import LinkThread

    if hosts.thread is None:
        thread = hosts.thread = LinkThread()
        thread.on_empty = lambda: _forget(agent, thread)
    return hosts.thread.open(spec, owner, agent.requests.step_aside)


def _forget(agent: Agent, host: object) -> None:
    hosts = _HOSTS.get(agent)
    if hosts is not None:
        if hosts.thread is host:
            hosts.thread = None
        if hosts.process is host:
            hosts.process = None
