"""One view of a machine for every door (fabwire's own API, the OctoPrint- and Moonraker-compatible routes).

A door translates a `MachineView` into its own vocabulary and nothing more: which phase a machine is in, its
temperatures, its job with the library's figures for the file, and, when it cannot take a job now, why.

Phases: "standby" (ready for a job), "printing" (a print or a drawing runs), "pausing", "paused", "resuming",
"cancelling", "done" (a da Vinci's finished print waits to be taken off and acknowledged), "busy" (homing,
loading filament …), "error", "offline".
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from fabwire.agent.core import Subscription
from fabwire.agent.drivers.base import offline_reason
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
            self._machines.job_ended(event["device"], event["job"]["state"])


JOB_ENDS = frozenset({"done", "failed", "cancelled", "interrupted"})


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
    last_outcome: str | None = None
    """How the machine's last job ended ("done", "failed", "cancelled", "interrupted") while nothing has started
    since; None before its first job here, and while a job runs."""

    @property
    def printing(self) -> bool:
        return self.phase in ("printing", "pausing", "paused", "resuming", "cancelling")

    def require_files(self) -> None:
        """TakesNoJobs (HTTP 409) unless the machine takes files: the doors and the library refuse an MMU alike."""
        if not self.takes_jobs:
            raise TakesNoJobs(f"{self.name} is a {KINDS[self.kind].title}: it takes no files")

    def refusal(self) -> str | None:
        """Why a job cannot start now (words for the owner, with what to do), or None when it can."""
        name = self.name
        if not self.takes_jobs:
            return f"{name} is a {KINDS[self.kind].title} and takes no jobs"
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
        self._outcomes: dict[str, str] = {}
        """device → how its last job ended (kept until the next job: Klipper's print_stats keeps "cancelled")."""
        """device → (how its last job ended, the status the machine had last reported then)."""

    def start(self) -> None:
        """Follow the agent's job ends (see `job_ended`); the agent ends it with its other subscriptions."""
        _JobEnds(self.agent, self)

    def job_ended(self, device_id: str, outcome: str) -> None:
        """A job just ended: until the machine is polled again, its last reported state is older than that end
        (a cancelled print's "printing"), so the job's outcome tells the phase."""
        with contextlib.suppress(InputError):
            self._ended[device_id] = (outcome, self.agent.session(device_id).state.get("status"))
        self._outcomes[device_id] = outcome

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
            last_outcome=None if job is not None else self._outcomes.get(session.info.id))
