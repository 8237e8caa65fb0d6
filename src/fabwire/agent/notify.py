"""Notifications: the agent's event stream turned into messages in words, sent through Apprise to any URL it
knows (e-mail, Telegram, ntfy, Pushover, Gotify, Discord, JSON webhooks …; see Apprise's list of services).

What is announced is the table `RULES`; `NoticeWatch` decides from the events alone (it is pure, so each rule is
tested without a machine), and `Notifier` adds the picture and sends. A print's picture is the largest thumbnail
its slicer embedded (`fabwire.thumbnails`); a drawing's is the drawing itself (`fabwire.lineus.render`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import deque
from collections.abc import Coroutine, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from fabwire.errors import InputError

if TYPE_CHECKING:
    from fabwire.agent.core import Agent, Subscription

log = logging.getLogger("fabwire.notify")

OFFLINE_AFTER_S = 60.0
"""How long a machine that was online must stay unreachable before it is announced (a Wi-Fi hiccup is not news)."""
QUEUE = 100
"""Messages waiting to be sent; past that the oldest is dropped (a dead notification service must not grow
the agent's memory)."""
MMU_ERROR_AFTER_S = 3.0
"""How long an MMU error must stand before it is announced: one the host retries by itself is gone by then."""
PICTURE_DPI = 40.0
"""Resolution of a drawing's picture: a phone notification's size."""


@dataclass(frozen=True, slots=True)
class Rule:
    name: str
    notify_type: str
    """Apprise's NotifyType value: "success", "failure", "warning" or "info" (the services' icon or colour)."""
    when: str
    source: str
    """The established host's event this matches, which owners already automate on."""


RULES: tuple[Rule, ...] = (
    Rule("finished", "success", "a print or drawing ended complete (the da Vinci shows its print-done screen)",
         "Moonraker [notifier] event `complete`; OctoPrint event PrintDone"),
    Rule("failed", "failure", "a print or drawing ended on an error (the job failed, or the printer went from "
         "printing to an error state)", "Moonraker [notifier] event `error`; OctoPrint event PrintFailed"),
    Rule("cancelled", "warning", "a print or drawing was cancelled (from fabwire, or on the printer: it went from "
         "printing to idle without finishing)", "Moonraker [notifier] event `cancelled`; OctoPrint event "
         "PrintCancelled"),
    Rule("mmu-error", "warning", "an MMU stopped on an error and waits for Retry/Continue or Stop",
         "Prusa-Firmware-MMU error screens (the printer waits for a button, MMU protocol 'E' reply); "
         "Moonraker [notifier] event `paused`"),
    Rule("offline", "warning", "a machine that was online has not answered for the offline delay",
         "OctoPrint event Disconnected; Moonraker's Klippy disconnected notification"),
)
RULE = {r.name: r for r in RULES}
JOB_ENDINGS = {"done": "finished", "failed": "failed", "cancelled": "cancelled"}
"""A job record's final state → the rule it announces (see `fabwire.agent.jobs`)."""
PRINTING = frozenset({"printing", "paused"})
STATE_ENDINGS = {"done": "finished", "error": "failed", "idle": "cancelled"}
"""A print not started by the agent (from the printer's panel or another host): where the summary state goes
from printing → the rule it announces."""


@dataclass(frozen=True, slots=True)
class Notice:
    """One message: `rule` names the row of `RULES`; `job` is the job record when there is one."""

    rule: str
    device: str
    title: str
    body: str
    job: dict[str, Any] | None = None

    @property
    def notify_type(self) -> str:
        return RULE[self.rule].notify_type


def _duration(seconds: float) -> str:
    minutes = round(seconds / 60)
    if minutes < 1:
        return f"{seconds:.0f} s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min" if hours else f"{minutes} min"


def _what(kind: str) -> str:
    return "drawing" if kind == "lineus" else "print"


@dataclass
class _Device:
    name: str
    kind: str = ""
    online: bool = False
    summary_state: str | None = None
    armed: bool = False
    """Printing without an agent job: its end is told from the state."""
    job_ended: bool = False
    """An agent job just ended and was announced: its print's last states are not a second ending."""
    offline_since: float | None = None
    offline_reason: str = ""
    offline_told: bool = False
    mmu_error: Notice | None = None
    """An MMU error not yet announced, and since when it stands."""
    mmu_error_since: float = 0.0


@dataclass
class NoticeWatch:
    """Turns agent events (see `fabwire.agent.core`) into notices; `due(now)` gives the offline ones whose delay
    has passed. `now` is `time.monotonic()` seconds."""

    offline_after_s: float = OFFLINE_AFTER_S
    devices: dict[str, _Device] = field(default_factory=dict)
    _told_jobs: deque[str] = field(default_factory=lambda: deque(maxlen=1000))

    def _device(self, event: dict[str, Any]) -> _Device:
        device = self.devices.get(event["device"])
        if device is None:
            device = self.devices[event["device"]] = _Device(event["device"])
        return device

    def feed(self, event: dict[str, Any], now: float) -> list[Notice]:
        device = self._device(event)
        kind = event.get("type")
        if kind == "online":
            device.online = True
            device.offline_since = None
            device.offline_told = False
            return []
        if kind == "offline":
            if device.online and device.offline_since is None:
                device.offline_since = now
            device.online = False
            device.offline_reason = str(event.get("reason") or "no answer")
            return []
        if kind == "job":
            return self._job(device, event["job"])
        if kind == "state":
            return self._state(device, event["state"], now)
        return []

    def _job(self, device: _Device, job: dict[str, Any]) -> list[Notice]:
        rule = JOB_ENDINGS.get(job.get("state", ""))
        if rule is None or job["id"] in self._told_jobs:
            return []
        self._told_jobs.append(job["id"])
        device.armed = False
        device.job_ended = True
        what = _what(device.kind)
        name = job.get("filename") or {"text": "the text", "print": "the print", "draw": "the drawing"}.get(
            job.get("type", ""), f"the {job.get('type', 'job')} job")
        message = (job.get("message") or "").strip()
        if rule == "finished":
            body = f"{name} finished" + (f": {message}." if message else ".")
        elif rule == "failed":
            body = f"{name} failed: {message or 'no reason given'}."
        else:
            body = f"{name} was cancelled" + (f" at {job['progress_percent']:.0f} %." if
                                              job.get("progress_percent") else ".")
        return [Notice(rule, device.name, f"{device.name}: {what} {rule}", body, job)]

    def _state(self, device: _Device, state: dict[str, Any], now: float) -> list[Notice]:
        device.name = state.get("name") or device.name
        device.kind = state.get("kind") or device.kind
        summary = state.get("summary") or {}
        previous, current = device.summary_state, summary.get("state")
        if current == previous or current == "offline":  # a link drop is not an ending: the print may go on
            return []
        device.summary_state = current
        out: list[Notice] = []
        device.mmu_error = None
        if device.kind == "mmu" and current == "error":
            buttons = " or ".join(b.capitalize() for b in summary.get("actions") or ()) or "a button"
            error = summary.get("state_text") or summary.get("error") or "an error"
            device.mmu_error = Notice("mmu-error", device.name, f"{device.name}: MMU error waiting",
                                      f"{error}. The MMU waits for {buttons} (on the dashboard or the printer).")
            device.mmu_error_since = now
        if current not in PRINTING:
            device.job_ended = False
        if state.get("job") is not None:
            device.armed = False
        elif current in PRINTING and not device.job_ended:
            device.armed = True
        elif device.armed and previous in PRINTING and current in STATE_ENDINGS:
            device.armed = False
            rule = STATE_ENDINGS[current]
            words = {"finished": "The print finished.",
                     "failed": f"The print stopped on an error: {summary.get('error') or summary.get('state_text')}.",
                     "cancelled": "The print stopped before it finished (cancelled on the printer)."}[rule]
            out.append(Notice(rule, device.name, f"{device.name}: print {rule}", words))
        return out

    def due(self, now: float) -> list[Notice]:
        out = []
        for device in self.devices.values():
            if device.mmu_error is not None and now - device.mmu_error_since >= MMU_ERROR_AFTER_S:
                out.append(device.mmu_error)
                device.mmu_error = None
            since = device.offline_since
            if since is not None and not device.offline_told and now - since >= self.offline_after_s:
                device.offline_told = True
                out.append(Notice("offline", device.name, f"{device.name} is offline",
                                  f"{device.name} has not answered for {_duration(now - since)}: "
                                  f"{device.offline_reason}."))
        return out


def _apprise() -> Any:
    try:
        import apprise
    except ImportError:
        raise InputError("notifications need Apprise: pip install 'fabwire[serve]'") from None
    return apprise


def check_urls(urls: Sequence[str]) -> Any:
    """An `apprise.Apprise` sending to every URL; InputError naming the first one Apprise cannot use (its
    password or token is left out of the message)."""
    apprise = _apprise()
    sender = apprise.Apprise()
    for url in urls:
        service = apprise.Apprise.instantiate(url.strip())
        if service is None:
            scheme = url.partition("://")[0] if "://" in url else ""
            shown = f"a {scheme}:// URL" if scheme else repr(url[:40])
            raise InputError(f"--notify: Apprise cannot send to {shown}: an unknown service or a URL missing its "
                             "parts (see Apprise's list of services, e.g. ntfy://topic, mailto://user:pass@host, "
                             "json://host:port/path)")
        sender.add(service)
    return sender


class Notifier:
    """Sends `RULES`' notices for an agent's events to every `--notify` URL; `run` until cancelled."""

    def __init__(self, urls: Sequence[str], *, offline_after_s: float = OFFLINE_AFTER_S) -> None:
        self.sender = check_urls(urls)
        self.watch = NoticeWatch(offline_after_s)
        self.sent = 0
        self.failed = 0
        self._queue: deque[tuple[Notice, bytes | None]] = deque(maxlen=QUEUE)
        self._wake = asyncio.Event()

    def run(self, agent: Agent) -> Coroutine[Any, Any, None]:
        """Subscribe now (nothing published from here on is missed) and return the loop to run as a task."""
        return self._run(agent, agent.subscribe())

    async def _run(self, agent: Agent, subscription: Subscription) -> None:
        sending = asyncio.create_task(self._send_loop())
        tick = min(1.0, max(self.watch.offline_after_s / 4, 0.05))
        try:
            while True:
                try:
                    event = await asyncio.wait_for(anext(subscription), tick)
                except TimeoutError:
                    event = None
                now = time.monotonic()
                notices = (self.watch.feed(event, now) if event is not None else []) + self.watch.due(now)
                for notice in notices:
                    picture = await asyncio.to_thread(self._picture, agent, notice)
                    self._queue.append((notice, picture))
                    self._wake.set()
        finally:
            subscription.close()
            sending.cancel()
            with contextlib.suppress(BaseException):
                await sending

    def _picture(self, agent: Agent, notice: Notice) -> bytes | None:
        """The print's embedded thumbnail or the drawing, as PNG; None when there is none (never raises)."""
        try:
            if notice.job is not None and notice.job.get("type") == "print":
                from fabwire.thumbnails import best_png

                path = agent.jobs.path_of(notice.job)
                return best_png(path) if path is not None and path.suffix != ".3w" else None
            if notice.job is not None and notice.rule != "offline":
                drawing = agent.session(notice.job["device"]).drawing
                strokes = drawing["ink"] or drawing["preview"]
                return _drawing_png(strokes) if strokes else None
        except Exception:  # a picture is a nicety: the words go out without it
            log.exception("no picture for the %s notice", notice.rule)
        return None

    async def _send_loop(self) -> None:
        while True:
            while not self._queue:
                self._wake.clear()
                await self._wake.wait()
            notice, picture = self._queue.popleft()
            ok = await asyncio.to_thread(self.send, notice, picture)
            self.sent += ok
            self.failed += not ok

    def send(self, notice: Notice, picture: bytes | None) -> bool:
        """Deliver one notice to every URL (blocking); False when any service refused it."""
        apprise = _apprise()
        attach = None
        if picture is not None:
            from apprise.attachment.memory import AttachMemory

            memory = AttachMemory(content=picture, name=f"{notice.rule}.png",  # type: ignore[no-untyped-call]
                                  mimetype="image/png")
            attach = apprise.AppriseAttachment(memory)
        ok = bool(self.sender.notify(body=notice.body, title=notice.title, notify_type=notice.notify_type,
                                     attach=attach))
        if not ok:
            log.warning("a notification (%s) was not delivered to every --notify URL", notice.title)
        return ok


def _drawing_png(strokes: list[list[tuple[float, float]]]) -> bytes:
    import tempfile
    from pathlib import Path

    from fabwire.lineus.render import dpi_scale, write_drawing

    with tempfile.TemporaryDirectory(prefix="fabwire-notice-") as folder:
        path = write_drawing(Path(folder) / "drawing.png", strokes, scale=dpi_scale(PICTURE_DPI))
        return path.read_bytes()

