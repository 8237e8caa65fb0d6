"""One view of a machine for every door (fabwire's own API, the OctoPrint- and Moonraker-compatible routes).

A door translates a `MachineView` into its own vocabulary and nothing more: which phase a machine is in, its
temperatures, its job with the library's figures for the file, and, when it cannot take a job now, why.

Phases: "standby" (ready for a job), "printing" (a print or a drawing runs), "pausing", "paused", "resuming",
"cancelling", "done" (a da Vinci's finished print waits to be taken off and acknowledged), "busy" (homing,
loading filament …), "error", "offline".
"""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any

from fabwire.agent.core import Subscription
from fabwire.agent.drivers.base import offline_reason
from fabwire.agent.history import epoch
from fabwire.devices import KINDS
from fabwire.errors import DeviceBusy, InputError

if TYPE_CHECKING:
    from fabwire.agent.core import Agent
    from fabwire.agent.session import Session

REQUEST_SHOWN_S = 30.0
"""How long a pause/resume/cancel asked for is shown as "pausing"/"resuming"/"cancelling" while the machine
has not yet reported the change."""

PHASE_OF_SUMMARY: dict[str, str] = {
    "idle": "standby", "printing": "printing", "drawing": "printing", "paused": "paused", "done": "done",
    "busy": "busy", "error": "error", "offline": "offline",
}
"""The agent summary's `state` (see `fabwire.agent.drivers.base`) → the phase."""

STATE_CODE_PHASE: dict[int, str] = {9602: "cancelling", 9601: "paused"}
"""da Vinci state codes that say more than the summary (reference §3: 9602 "cancelling print")."""


class _JobEnds(Subscription):
    """Notes each job's end as it is published (synchronously: a request right after a cancel sees it)."""

    def __init__(self, agent: Agent, machines: Machines) -> None:
        super().__init__(agent, None)
        self._machines = machines

    def offer(self, event: dict[str, Any]) -> None:
        if event["type"] == "job" and event["job"].get("state") in JOB_ENDS:
            self._machines.job_ended(event["device"], event["job"])


JOB_ENDS = frozenset({"done", "failed", "cancelled", "interrupted"})


BUSY_PHASES = frozenset({"printing", "pausing", "paused", "resuming", "cancelling"})
"""The phases of a machine at work on a print or a drawing (one started here or on its own panel)."""


class MachineNotReady(DeviceBusy):
    """The machine cannot start a job now; the message says why and what to do."""


class TakesNoJobs(DeviceBusy):
    """The machine has no jobs at all (an MMU), or cannot do what was asked (set a temperature …)."""


@dataclass(frozen=True, slots=True)
class MachineView:
    id: str
    name: str
    kind: str
    model: str | None
    online: bool
    phase: str
    message: str
    """The machine's state in words (its own wording), or why it is offline."""
    error: str | None
    extruder_c: float | None
    extruder_target_c: float | None
    bed_c: float | None
    bed_target_c: float | None
    job: dict[str, Any] | None
    """The agent's running job record (see `fabwire.agent.jobs`), else None."""
    progress_percent: float | None
    elapsed_s: float | None
    time_left_s: float | None
    takes_jobs: bool
    last_job: dict[str, Any] | None = None
    """The agent's record of the machine's last job as it ended (state "done", "failed", "cancelled" or
    "interrupted"), kept while nothing has started since: what a print host shows of the job just finished; None
    before its first job here, and while a job runs."""

    @property
    def shown_job(self) -> dict[str, Any] | None:
        """The job a print host names: the running one, else the last one (see `last_job`)."""
        return self.job if self.job is not None else self.last_job

    def figures(self, now: float | None = None) -> JobFigures | None:
        """The shown job's figures (`job_figures`); for a print the machine runs without a job here (started on
        its panel), its own progress and elapsed time; None with neither."""
        job = self.shown_job
        if job is None and self.printing:
            now = time.time() if now is None else now
            job = {"state": "running", "progress_percent": self.progress_percent,
                   "started": None if self.elapsed_s is None else
                   datetime.fromtimestamp(now - self.elapsed_s, UTC).isoformat()}
        return job_figures(job, now) if job is not None else None

    @property
    def printing(self) -> bool:
        return self.phase in BUSY_PHASES

    def require_files(self) -> None:
        """TakesNoJobs (HTTP 409) unless the machine takes files: the doors and the library refuse an MMU alike."""
        if not self.takes_jobs:
            raise TakesNoJobs(f"{self.name} is {KINDS[self.kind].a_title}: it takes no files")

    def refusal(self) -> str | None:
        """Why a job cannot start now (words for the owner, with what to do), or None when it can."""
        name = self.name
        if not self.takes_jobs:
            return f"{name} is {KINDS[self.kind].a_title} and takes no jobs"
        if self.phase == "offline":
            return f"{name} is offline ({offline_reason(self.message)})"
        # a Line-us draws: the phases' OctoPrint words (printing, paused …) are said as a drawing's
        phase, work = (self.phase.replace("printing", "drawing"), "drawing") if self.kind == "lineus" else (
            self.phase, "print")
        if self.job is not None:
            shown = self.job.get("filename") or self.job.get("type")
            return (f"{name} is busy with job {self.job['id']} ({shown}, {phase}): wait for it to finish "
                    "or cancel it")
        if self.printing:
            return f"{name} is {phase}: wait for the {work} to finish or cancel it"
        if self.phase == "done" and self.kind == "xyz":  # only a printer waits for its work to be taken away
            return (f"{name} has finished a print that is still on the bed: take it off and acknowledge it "
                    "(the printer's OK button, or Acknowledge on the dashboard), then send again")
        if self.phase == "error":
            return f"{name} reports an error: {self.error or self.message}"
        if self.phase == "busy":
            return f"{name} is busy ({self.message}): try again when it is idle"
        return None


class Machines:
    """The machines of an agent as views, and the pause/resume/cancel requests still on their way."""

    def __init__(self, agent: Agent) -> None:
        self.agent = agent
        self._requested: dict[str, tuple[str, float]] = {}
        self._ended: dict[str, tuple[str, object]] = {}
        self._last_jobs: dict[str, dict[str, Any]] = {}
        """device → its last job's record as it ended (kept until the next job starts: Klipper's print_stats and
        OctoPrint's job keep the finished job)."""

    def start(self) -> None:
        """Follow the agent's job ends (see `job_ended`); the agent ends it with its other subscriptions."""
        _JobEnds(self.agent, self)

    def job_ended(self, device_id: str, job: dict[str, Any]) -> None:
        """A job just ended (its record): until the machine is polled again, its last reported state is older than
        that end (a cancelled print's "printing"), so the job's outcome tells the phase."""
        outcome = str(job["state"])
        with contextlib.suppress(InputError):
            self._ended[device_id] = (outcome, self.agent.session(device_id).state.get("status"))
        self._last_jobs[device_id] = dict(job)

    def view(self, device: str) -> MachineView:
        """UnknownDevice (an InputError) when no machine has that name or id."""
        return self._view(self.agent.session(device))

    def all(self) -> list[MachineView]:
        return [self._view(s) for s in self.agent.sessions()]

    def default(self, kinds: tuple[str, ...] = ("xyz", "lineus")) -> MachineView | None:
        """The first machine of the first kind in `kinds` that the agent monitors (the configuration's order)."""
        sessions = self.agent.sessions()
        for kind in kinds:
            for session in sessions:
                if session.spec.kind == kind:
                    return self._view(session)
        return None

    def requested(self, device_id: str, what: str) -> None:
        """Note that "pausing", "resuming" or "cancelling" was asked for (shown until the machine reports it)."""
        self._requested[device_id] = (what, time.monotonic())

    def require_ready(self, device: str) -> MachineView:
        view = self.view(device)
        reason = view.refusal()
        if reason is not None:
            raise MachineNotReady(reason)
        return view

    def _view(self, session: Session) -> MachineView:
        state = session.state
        summary = state.get("summary") or {}
        status = state.get("status") or {}
        online = bool(state.get("online"))
        phase = PHASE_OF_SUMMARY.get(str(summary.get("state")), "busy") if online else "offline"
        code = status.get("state") if session.spec.kind == "xyz" else None
        if isinstance(code, int) and code in STATE_CODE_PHASE:
            phase = STATE_CODE_PHASE[code]
        job = state.get("job")
        if job is not None and online and phase == "standby":  # its file on the way to the machine: at work already
            phase = "printing"
        ended = self._ended.get(session.info.id)
        if ended is not None and job is None and online:
            outcome, status_then = ended
            if state.get("status") is status_then:  # not polled since: the outcome is the news
                phase = "done" if outcome == "done" else "standby"
            else:
                del self._ended[session.info.id]
        asked = self._requested.get(session.info.id)
        if asked is not None:
            what, when = asked
            settled = {"pausing": ("paused",), "resuming": ("printing",),
                       "cancelling": ("standby", "done", "error")}[what]
            if time.monotonic() - when > REQUEST_SHOWN_S or phase in settled or phase == "offline":
                del self._requested[session.info.id]
            elif phase in ("printing", "paused"):
                phase = what
        return MachineView(
            id=session.info.id, name=session.spec.name, kind=session.spec.kind, model=session.info.model,
            online=online, phase=phase, message=str(summary.get("state_text") or phase), error=summary.get("error"),
            extruder_c=summary.get("extruder_temp_c"), extruder_target_c=summary.get("extruder_target_c"),
            bed_c=summary.get("bed_temp_c"), bed_target_c=summary.get("bed_target_c"), job=job,
            progress_percent=(job or {}).get("progress_percent") if job else summary.get("progress_percent"),
            elapsed_s=summary.get("elapsed_s"),
            time_left_s=(job or {}).get("time_left_s") or summary.get("time_left_s"),
            takes_jobs=bool(session.driver.job_types),
            last_job=None if job is not None or phase in BUSY_PHASES else self._last_jobs.get(session.info.id))


PRINTER_ELAPSED_STEP_S = 60.0
"""The resolution of a printer's elapsed time: a da Vinci reports whole minutes (XYZv3 status `d:<pct>,<elapsed
minutes>,<minutes left>`), so the true time is up to a step past what it said when it first said it."""


@dataclass(frozen=True, slots=True)
class JobFigures:
    """A job's figures as every door shows them, from its record (`fabwire.agent.jobs`) alone.

    Durations are seconds on the agent's clock from the job's start, kept within what the printer's own elapsed
    time allows; a finished job's figures stay as they were at its end."""

    state: str
    """The job record's state: "queued", "running", "done", "failed", "cancelled", "interrupted"."""
    filename: str
    started: float | None
    """Epoch seconds (agent clock), None before it runs."""
    finished: float | None
    total_s: float
    """Seconds from the start to now (or to the end), pauses included."""
    print_s: float
    """`total_s` without the time paused."""
    printing_s: float
    """Seconds since the job started or last resumed (0 while paused or ended)."""
    fraction: float
    """Progress 0.0 … 1.0 (1.0 once done)."""
    filament_used_mm: float
    """The file's filament in mm times `fraction` (0.0 when the file does not say)."""
    filament_total_mm: float | None
    layers: int | None
    current_layer: int | None
    """The layer `fraction` is in (1-based, 0 before the first), None when the file gives no layer count."""
    size: int
    """The file's bytes (0 when the job has no file)."""
    position: int
    """`fraction` of `size`: the byte the job has come to."""
    estimated_s: float | None
    """The slicer's estimated print time, None when the file does not say."""


def job_figures(job: dict[str, Any], now: float | None = None) -> JobFigures:
    """The figures of a job record at `now` (epoch seconds; the current time when None)."""
    now = time.time() if now is None else now
    state = str(job.get("state") or "queued")
    started, finished = (epoch(t) if t else None for t in (job.get("started"), job.get("finished")))
    if finished is not None:
        until = finished
    elif state in ("queued", "running"):
        until = now
    else:  # ended without an end on record (the agent stopped): the last time the job was seen
        seen = [float(t) for t in ((job.get("printer_elapsed") or [None, None])[1], job.get("resumed_at"),
                                   job.get("paused_since")) if t is not None]
        until = max(seen, default=started or now)
    total = max(0.0, until - started) if started is not None else 0.0
    reported = job.get("printer_elapsed")
    if started is not None and reported:
        said, since = float(reported[0]), float(reported[1])
        total = min(max(total, said), said + PRINTER_ELAPSED_STEP_S + max(0.0, until - since))
    paused = float(job.get("paused_s") or 0.0)
    paused_since = job.get("paused_since")
    if paused_since is not None:
        paused += max(0.0, until - float(paused_since))
    print_s = max(0.0, total - paused)
    running = state == "running" and paused_since is None
    resumed = job.get("resumed_at")
    printing = (min(print_s, max(0.0, until - float(resumed))) if resumed is not None else print_s) if running else 0.0
    fraction = 1.0 if state == "done" else round(min(1.0, max(0.0, float(job.get("progress_percent") or 0.0)
                                                               / 100.0)), 4)
    meta = job.get("file_meta") or {}
    filament = meta.get("filament_mm")
    layers = meta.get("layers")
    layers = int(layers) if isinstance(layers, int | float) and layers > 0 else None
    current = None if layers is None else min(layers, math.floor(fraction * layers) + 1) if fraction > 0 else 0
    size = int(job.get("size_bytes") or 0)
    estimate = meta.get("print_time_s")
    return JobFigures(
        state=state, filename=str(job.get("filename") or ""), started=started, finished=finished,
        total_s=round(total, 3), print_s=round(print_s, 3), printing_s=round(printing, 3), fraction=fraction,
        filament_used_mm=round(float(filament) * fraction, 2) if filament else 0.0,
        filament_total_mm=float(filament) if filament else None, layers=layers, current_layer=current, size=size,
        position=int(size * fraction), estimated_s=float(estimate) if estimate is not None else None)
