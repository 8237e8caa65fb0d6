"""The agent: one session per device, their latest states, a live event stream, actions and jobs.

Every event is a JSON-ready dict `{"ts": ISO-8601 UTC, "device": id, "type": T, ...}` where T is
  "state"   — `"state"`: the device's latest state (see `Agent.state`), sent when anything in it changed;
  "online"  — `"info"`: the DeviceInfo as a dict, after a (re)connect;
  "offline" — `"reason"`: why the link is down, `"exit_code"`: the CLI's exit code for that failure,
              `"retry_in_s"`: when the next attempt is;
  "event"   — `"event"`: something the device reported (an MMU progress step, an error it raised …);
  "job"     — `"job"`: a job record (see `fabwire.agent.jobs`), `"stroke"` too while a Line-us draws;
  "error"   — `"message"`, `"exit_code"`: an action or job failed (the CLI's exit-code class).
"""

from __future__ import annotations

import asyncio
import dataclasses
import os
import re
import socket
from collections.abc import AsyncIterable, AsyncIterator, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from fabwire import __version__
from fabwire.errors import FabwireError, InputError, excerpt

if TYPE_CHECKING:
    from fabwire.agent.session import JobClaim, Session
    from fabwire.transport.sameness import Machine

Kind = Literal["xyz", "lineus", "mmu"]
EventType = Literal["state", "event", "online", "offline", "job", "error"]
KINDS: tuple[Kind, ...] = ("xyz", "lineus", "mmu")
SUBSCRIBER_QUEUE = 2000
"""Events a slow subscriber may lag behind by before the oldest are dropped (it sees a `"dropped"` count)."""


class UnknownDevice(InputError):
    """No device with that id is monitored by this agent."""


def private_dir(path: Path) -> Path:
    """Create `path` (and its parents) if missing; the directory made here is 0700, its owner's alone (XDG Base
    Directory spec: state data is the user's). An existing directory keeps its mode: it is the owner's choice."""
    if not path.is_dir():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.mkdir(mode=0o700, exist_ok=True)
        os.chmod(path, 0o700)  # mkdir's mode passes through the umask
    return path


def now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


@dataclass(frozen=True, slots=True)
class DeviceInfo:
    """What a device is; `id` is stable across restarts and unique across agents (see `device_id`)."""

    id: str
    name: str
    kind: str
    """"xyz" | "lineus" | "mmu"."""
    model: str | None
    serial: str | None
    firmware: str | None
    address: str

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True, slots=True)
class DeviceSpec:
    """A device to monitor: how the config (or an API call) names it and where it is."""

    name: str
    kind: Kind
    address: str
    options: Mapping[str, Any] = field(default_factory=dict)
    """The kind's settings (`fabwire.config`: timeout, speed, auto_retries …), as in devices.toml."""
    fixed_id: str | None = None
    """The id to use whatever the machine reports (the demo's simulators sit on a new port each run)."""


_LOCAL = re.compile(r"^(sim:|serial:|pty:|/|(tcp://)?(127\.[0-9.]+|localhost|\[?::1\]?)(:|/|$))", re.IGNORECASE)


def _slug(text: str) -> str:
    """Lower-case letters, digits and single inner '-' only."""
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "device"


MAX_DEVICE_ID = 100
"""The longest device id. An id names the device's folders (`library/ID/`), so it must stay under a file name's
limit (NAME_MAX, 255 bytes on Linux filesystems) and it is a level of MQTT topics and Home Assistant unique ids;
a longer one is cut and ends with a hash of the whole, so two long addresses keep two ids."""


DEVICE_IDS: tuple[tuple[str, str, str], ...] = (
    ("a machine that reports a serial number", "KIND-SERIAL", "the machine's serial (XYZ `query=i`, Line-us "
                                                             "hello `SERIAL:`, MMU none)"),
    ("a machine on a network address, no serial", "KIND-ADDRESS", "the `--device`/devices.toml address"),
    ("a machine on a loopback, serial-port or in-process address, no serial", "KIND-HOST-ADDRESS",
     "the address, qualified with this computer's host name"),
    ("a machine whose id would be a demo's (a serial `demo`)", "KIND-demo-HASH",
     "the id above and a hash of the address, so a real machine never takes a demo's id"),
    ("a simulator of `serve --demo`", "KIND-demo", "fixed, the same on every run (the README's and scripts' ids)"),
)
"""Every form a device id takes: (whose, form, where its parts come from). The demo's are theirs alone."""


def demo_id(kind: str) -> str:
    """The id of the `serve --demo` simulator of `kind` (`xyz-demo`, …): the same every run, never a machine's."""
    return f"{kind}-demo"


DEMO_IDS = frozenset(demo_id(kind) for kind in KINDS)


def is_demo_id(device: str) -> bool:
    """Whether `device` is the id of a `serve --demo` simulator (`device_id` never gives a machine one)."""
    return device in DEMO_IDS


def device_id(kind: str, serial: str | None, address: str, host: str | None = None) -> str:
    """`{kind}-{serial}` when the machine reports a serial number, else `{kind}-{address}` made URL-safe (a-z, 0-9
    and '-'), at most MAX_DEVICE_ID characters.

    A loopback, serial-port or in-process address means something only on this computer, so it is
    qualified with the host name: two agents' `127.0.0.1:9100` are two different machines."""
    if serial and serial.strip():
        found = _bounded(f"{kind}-{_slug(serial)}")
    elif _LOCAL.match(address):
        found = _bounded(f"{kind}-{_slug(host or socket.gethostname())}-{_slug(address)}")
    else:
        found = _bounded(f"{kind}-{_slug(address)}")
    if is_demo_id(found):  # a machine never takes the demo's id, its MQTT topics or its Home Assistant device
        import hashlib

        found = f"{found}-{hashlib.sha256(address.encode()).hexdigest()[:6]}"
    return found


def _bounded(slug: str) -> str:
    if len(slug) <= MAX_DEVICE_ID:
        return slug
    import hashlib

    return f"{slug[:MAX_DEVICE_ID - 9].rstrip('-')}-{hashlib.sha256(slug.encode()).hexdigest()[:8]}"


def make_event(device: str, type_: EventType, **payload: Any) -> dict[str, Any]:
    return {"ts": now_iso(), "device": device, "type": type_, **payload}


class Subscription(AsyncIterator[dict[str, Any]]):
    """Live events as an async iterator; registered when created, so nothing published after that is missed."""

    def __init__(self, agent: Agent, device_id: str | None) -> None:
        self.device_id = device_id
        self.dropped = 0
        self._queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self._agent = agent
        agent._subscribers.add(self)

    def offer(self, event: dict[str, Any]) -> None:
        if self.device_id is not None and event["device"] != self.device_id:
            return
        if self._queue.qsize() >= SUBSCRIBER_QUEUE:
            self._queue.get_nowait()
            self.dropped += 1
        self._queue.put_nowait(event)

    def __aiter__(self) -> Subscription:
        return self

    async def __anext__(self) -> dict[str, Any]:
        if self not in self._agent._subscribers and self._queue.empty():
            raise StopAsyncIteration
        return await self._queue.get()

    async def aclose(self) -> None:
        self._agent._subscribers.discard(self)

    def close(self) -> None:
        self._agent._subscribers.discard(self)


class Agent:
    """Sessions to every device, their states, a live event stream, actions and jobs; history when given a store.

        agent = Agent(state_dir=Path("state"))
        async with agent:
            await agent.add_device(DeviceSpec("office", "xyz", "192.168.1.50"))
            async for event in agent.subscribe("xyz-3dp01p…"):
                ...

    Errors: `UnknownDevice` (an InputError) for an id it does not monitor; actions raise the FabwireError
    subclasses the clients raise (DeviceError, LinkError, LinkTimeout, InputError for bad parameters).
    """

    def __init__(self, *, state_dir: Path | None = None, retention_s: float = 24 * 3600.0,
                 max_upload_bytes: int = 64 * 1024 * 1024, backoff: tuple[float, float] = (0.5, 30.0),
                 first_attempt_s: float = 10.0, links: Literal["auto", "thread", "process"] = "auto") -> None:
        from fabwire.agent.history import History
        from fabwire.agent.jobs import JobStore
        from fabwire.agent.library import Library
        from fabwire.agent.session import RequestsFirst, Tally

        self.state_dir = state_dir
        self.backoff = backoff
        self.first_attempt_s = first_attempt_s
        self.links = links
        """Where the device links run (see `fabwire.agent.links`): "auto" chooses by the number of machines."""
        self.expected_devices = 0
        """How many machines are about to be added (the config's): "auto" links choose by it from the first."""
        self.history = History(state_dir / "history.sqlite3" if state_dir else None, retention_s=retention_s)
        self.jobs = JobStore(self.history, state_dir / "uploads" if state_dir else None, max_upload_bytes)
        self.library = Library(self, state_dir / "library" if state_dir else None)
        """Uploads kept per machine, their previews and the print queues (see `fabwire.agent.library`)."""
        self._sessions: dict[str, Session] = {}
        self.requests = RequestsFirst()
        """The API marks the requests it is answering; the polls step aside for them."""
        self._tally = Tally()
        """Health's counts over every machine monitored, kept as they change (see `PollStats`)."""
        self._subscribers: set[Subscription] = set()
        self._started = False
        self._added = 0
        self._reached: dict[str, frozenset[Machine]] = {}
        """Each monitored (or starting) device's name and the names of the machine it reaches (`machine_keys`),
        taken before its session starts, so simultaneous adds of one machine cannot both pass."""

    async def __aenter__(self) -> Agent:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    async def start(self) -> None:
        await self.history.open()
        await self.jobs.recover()
        await self.library.start()
        self._started = True

    async def stop(self) -> None:
        sessions = list(self._sessions.values())
        self._sessions.clear()
        self._reached.clear()
        for session in sessions:
            session.stats.leave()
        await asyncio.gather(*(s.stop() for s in sessions), return_exceptions=True)
        await self.library.stop()
        for sub in list(self._subscribers):
            sub.close()
        await self.history.close()
        self._started = False

    # ------------------------------------------------------------------------------------------ the contract

    def devices(self) -> list[DeviceInfo]:
        """In the order they were added (the config's order), however long each took to answer."""
        return [s.info for s in self.sessions()]

    def state(self, device_id: str) -> dict[str, Any]:
        """The latest state: `{"ts", "online", "device", "kind", "name", "summary": {…}, "status": {…}, "job"}`.

        `status` is exactly what the device's `--json status` prints (None before the first poll); `summary` is
        the same view for every kind, SI units in the key names (see `fabwire.agent.drivers.base.Summary`)."""
        return self.session(device_id).state

    def subscribe(self, device_id: str | None = None) -> Subscription:
        """Live events of one device (or all); iterate, and `aclose()` when done."""
        return Subscription(self, self.session(device_id).info.id if device_id is not None else None)

    def resolve(self, device: str) -> str:
        """The id of the device named or identified by `device`; as given when no current device matches
        (a job list may ask about a device no longer monitored)."""
        try:
            return self.session(device).info.id
        except UnknownDevice:
            return device

    async def act(self, device_id: str, action: str, params: Mapping[str, Any]) -> dict[str, Any]:
        """Run an action (see `actions_for`); returns its result dict. Long ones (a tool change) run in the
        background and return `{"started": action}`; their end arrives as events."""
        return await self.session(device_id).act(action, dict(params))

    async def add_device(self, spec: DeviceSpec) -> DeviceInfo:
        """Start monitoring; waits for the first connection attempt (bounded) so the id can use the serial."""
        from fabwire.agent.session import Session
        from fabwire.config import validate_settings
        from fabwire.devices import KINDS as DEVICE_KINDS
        from fabwire.transport.sameness import machines_of, same_machine
        from fabwire.transport.urls import parse_url

        if spec.kind not in KINDS:
            raise InputError(f"device kind must be one of {', '.join(KINDS)}, not {spec.kind!r}")
        validate_settings(DEVICE_KINDS[spec.kind], dict(spec.options))  # a wrong option fails here, not later
        order = self._added  # the order devices were given in, whichever start finishes first
        self._added += 1
        reached, = await asyncio.to_thread(machines_of, [parse_url(spec.address, DEVICE_KINDS[spec.kind])])
        if spec.name in self._reached:
            raise InputError(f"a device named {spec.name!r} is already monitored")
        other = same_machine(reached, list(self._reached.items()))
        if other is not None:
            raise InputError(f"{excerpt(spec.address, 60)} reaches the machine already monitored as {other!r}: "
                             "one machine is monitored once")
        self._reached[spec.name] = reached
        try:
            session = Session(self, spec, order=order)
            await session.start()
        except BaseException:
            del self._reached[spec.name]
            raise
        self._sessions[session.info.id] = session
        session.stats.join(self._tally)
        await self.history.remember_device(session.info)
        return session.info

    async def remove_device(self, device_id: str) -> None:
        session = self.session(device_id)
        del self._sessions[session.info.id]
        self._reached.pop(session.spec.name, None)
        session.stats.leave()
        await session.stop()

    # ------------------------------------------------------------------------------------------ jobs

    def claim_job(self, device_id: str, filename: str) -> JobClaim:
        """Claim a machine for an upload named `filename`, before reading a byte of it (see `JobClaim`):
        atomic, so of simultaneous uploads to one machine exactly one gets it and the others DeviceBusy (409).
        UnknownDevice (404), InputError (400) for a file the kind does not take, LinkError (503) offline."""
        return self.session(device_id).claim_job(filename)

    async def upload_job(self, device_id: str, filename: str, chunks: AsyncIterable[bytes]) -> dict[str, Any]:
        """Claim the machine, stream the upload to disk under the size limit, check it and start it; returns
        the job record. Errors as `claim_job`, `JobClaim.write` and `JobClaim.start`."""
        async with self.claim_job(device_id, filename) as claim:
            async for chunk in chunks:
                await claim.write(chunk)
            return await claim.start()

    async def start_job(self, device_id: str, filename: str, data: bytes) -> dict[str, Any]:
        """Store an upload under a generated name and start it on the device (print a G-code/.3w, draw an SVG)."""
        return await self.session(device_id).start_job(filename, data)

    async def cancel_job(self, job_id: str, *, confirm: bool) -> dict[str, Any]:
        job = await self.jobs.get(job_id)
        return await self.session(job["device"]).cancel_job(job_id, confirm=confirm)

    def health(self) -> dict[str, Any]:
        """Counts and poll punctuality (a poll is late when it starts over half an interval after its slot), read
        from the agent's tally: the same work for one machine or a thousand."""
        tally = self._tally
        lags = tally.lags
        return {"version": __version__, "devices": len(self._sessions), "online": tally.online,
                "polls": tally.polls, "late_polls": tally.late,
                "poll_lag_p99_s": lags[int(0.99 * (len(lags) - 1))] if lags else None,
                "poll_lag_max_s": lags[-1] if lags else None, "subscribers": len(self._subscribers)}

    # ------------------------------------------------------------------------------------------ plumbing

    def publish(self, event: dict[str, Any]) -> None:
        for sub in list(self._subscribers):
            sub.offer(event)
        self.history.record_event(event)

    def claim_id(self, wanted: str, fallback: str) -> str:
        """`wanted` unless another session already has it (two simulators may report one serial)."""
        taken = set(self._sessions)
        return wanted if wanted not in taken else fallback

    def session(self, device_id: str) -> Session:
        """The session of a device addressed by its id or its configured name; UnknownDevice if there is none."""
        if device_id in self._sessions:
            return self._sessions[device_id]
        for session in self._sessions.values():
            if session.spec.name == device_id:
                return session
        known = ", ".join(f"{s.spec.name} ({id_})" if s.spec.name and s.spec.name != id_ else id_
                          for id_, s in self._sessions.items())
        raise UnknownDevice(f"no device {excerpt(device_id, 60)} here (known: {known or 'none'})")

    def sessions(self) -> list[Session]:
        return sorted(self._sessions.values(), key=lambda s: s.order)

    @staticmethod
    def error_event(device: str, exc: BaseException) -> dict[str, Any]:
        return make_event(device, "error", message=str(exc) or type(exc).__name__, exit_code=exit_code_of(exc))


def exit_code_of(exc: BaseException) -> int:
    """The CLI's exit-code class for an exception (FabwireError's own, 9 timeouts, 8 links, 1 otherwise)."""
    if isinstance(exc, FabwireError):
        return exc.exit_code
    if isinstance(exc, TimeoutError):
        return 9
    if isinstance(exc, ConnectionError | OSError):
        return 8
    return 1
