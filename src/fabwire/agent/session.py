"""One device under the agent: connect, poll on a fixed schedule, reconnect with backoff, run actions and jobs.

Every change becomes an event on the agent (see `fabwire.agent.core` for their shapes) and a history row.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import threading
import time
from collections import deque
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sortedcontainers import SortedList

from fabwire.agent.core import DeviceInfo, DeviceSpec, device_id, exit_code_of, is_demo_id, make_event, now_iso
from fabwire.agent.drivers.base import Identity, checked_params, offline_summary
from fabwire.agent.jobs import note_course
from fabwire.agent.library import require_plain_name
from fabwire.agent.links import open_link
from fabwire.agent.linkside import LINK_FAILURES
from fabwire.errors import DeviceBusy, FabwireError, InputError, LinkError, excerpt

if TYPE_CHECKING:
    from fabwire.agent.core import Agent

log = logging.getLogger("fabwire.agent")
JOB_ACTIONS = ("cancel", "pause", "resume")
"""Actions on the work in progress: refused as "nothing to cancel" (…) when the machine offers them not."""
JOB_EVENT_EVERY_S = 0.5
STEP_ASIDE_S = 0.02
"""How long the links' thread waits for the agent's requests in flight before it goes on with its polls; it then
works at least as long before it steps aside again, so a flood of requests slows the polls to half speed at most."""
STOP_WAIT_S = 30.0
STOP_AGAIN_S = 1.0
"""While a cancelled job still runs, the machine is asked to stop again this often (seconds)."""
"""How long a cancelled job may take to stop on the machine before the agent cuts it off."""


class RequestsFirst:
    """The agent's requests before its polls. Both loops share one interpreter lock: while a request is answered on
    the agent's loop (`serving`), a polling links' thread would take the lock from it at every turn of its handling,
    and under load each hand-over costs a wait for the scheduler. So at its next poll the links' thread steps aside
    (`step_aside`, waiting without the lock) until the requests in flight are answered, STEP_ASIDE_S at most: a
    request is answered alike whether a thousand machines are polled or ten. One per agent."""

    def __init__(self) -> None:
        self._idle = threading.Event()
        self._idle.set()
        self._in_flight = 0
        self._resume_at = 0.0
        """When the links' thread may step aside again (its own clock, read on that thread only)."""
        self._when_idle: list[Callable[[], None]] = []

    @property
    def busy(self) -> bool:
        """On the agent's loop: whether requests are being answered."""
        return self._in_flight > 0

    def when_idle(self, callback: Callable[[], None]) -> None:
        """On the agent's loop: `callback()` soon after no request is in flight any more (at once when none is)."""
        if self._in_flight <= 0:
            callback()
        else:
            self._when_idle.append(callback)

    def begin(self) -> None:
        """On the agent's loop: a request is being answered."""
        self._in_flight += 1
        self._idle.clear()

    def end(self) -> None:
        """On the agent's loop: that request is answered."""
        self._in_flight -= 1
        if self._in_flight <= 0:
            self._in_flight = 0
            self._idle.set()
            if self._when_idle:
                waiting, self._when_idle = self._when_idle, []
                loop = asyncio.get_running_loop()
                for callback in waiting:
                    loop.call_soon(callback)

    def step_aside(self) -> None:
        """On the links' thread, between polls: while requests are in flight, wait for them (at most STEP_ASIDE_S,
        and not again within STEP_ASIDE_S of the last wait's end)."""
        if self._idle.is_set():
            return
        if time.monotonic() < self._resume_at:
            return
        self._idle.wait(STEP_ASIDE_S)
        self._resume_at = time.monotonic() + STEP_ASIDE_S


class Tally:
    """What the agent's health reports of every machine monitored, kept up to date as each poll and each change of
    link happens: a request reads it without visiting a session, so its cost does not grow with the fleet."""

    def __init__(self) -> None:
        self.lags: SortedList = SortedList()
        """The recent poll lags of every machine, in order: health reads their p99 without sorting them."""
        self.polls = 0
        self.late = 0
        self.online = 0


class PollStats:
    """A machine's link and how punctual its polls are: a poll is late when it starts more than half an interval
    after its slot. Counted in the agent's `Tally` too once joined."""

    def __init__(self) -> None:
        self.polls = 0
        self.late = 0
        self.online = False
        self.lags: deque[float] = deque(maxlen=600)
        """The last ten minutes' lags at 1 Hz."""
        self._tally: Tally | None = None

    def record(self, lag: float, interval: float) -> None:
        late = lag > interval / 2
        self.polls += 1
        self.late += late
        lags = self.lags
        tally = self._tally
        if tally is not None:
            tally.polls += 1
            tally.late += late
            if len(lags) == lags.maxlen:
                tally.lags.remove(lags[0])
            tally.lags.add(lag)
        lags.append(lag)

    def set_online(self, online: bool) -> None:
        if online != self.online:
            self.online = online
            if self._tally is not None:
                self._tally.online += 1 if online else -1

    def join(self, tally: Tally) -> None:
        """Count this machine in `tally` (the agent's, for every machine) from now on."""
        self._count(tally, 1)
        tally.lags.update(self.lags)
        self._tally = tally

    def leave(self) -> None:
        """Take this machine out of the tally it joined."""
        tally, self._tally = self._tally, None
        if tally is not None:
            self._count(tally, -1)
            for lag in self.lags:
                tally.lags.remove(lag)

    def _count(self, tally: Tally, sign: int) -> None:
        tally.polls += sign * self.polls
        tally.late += sign * self.late
        tally.online += sign * self.online


class Session:
    def __init__(self, agent: Agent, spec: DeviceSpec, *, order: int = 0) -> None:
        self.agent = agent
        self.order = order
        self.spec = spec
        self.link = open_link(agent, spec, self, order)
        """The machine's link, on the agent's links' thread or in its links' process (`fabwire.agent.links`);
        states, events and history are handled here, on the agent's loop."""
        self.driver = self.link.driver
        self.info = DeviceInfo("", spec.name, spec.kind, None, None, None, spec.address)
        self.stats = PollStats()
        self.state: dict[str, Any] = {}
        self.drawing: dict[str, list[list[tuple[float, float]]]] = {"preview": [], "ink": []}
        """The Line-us job's planned strokes and those drawn so far (a page opened mid-job shows both)."""
        self._identity: Identity | None = None
        self._first_attempt = asyncio.Event()
        self._id_ready = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._job: dict[str, Any] | None = None
        self._job_task: asyncio.Task[None] | None = None
        self._claim: JobClaim | None = None
        self._background: set[asyncio.Task[None]] = set()
        self._last_job_event = 0.0
        self._reason = "not connected yet"
        self._reason_code = 8
        """The CLI's exit code for `_reason` (8 link, 9 timeout, 6 not this kind of machine …)."""
        self._stopping = False
        self._cancelling = False

    @property
    def online(self) -> bool:
        """Whether the link is up (the agent's tally counts it)."""
        return self.stats.online

    @online.setter
    def online(self, online: bool) -> None:
        self.stats.set_online(online)

    # ------------------------------------------------------------------------------------------ lifecycle

    async def start(self) -> None:
        known = self.spec.fixed_id or await self.agent.history.known_id(self.spec.kind, self.spec.address)
        if known is not None and not self.spec.fixed_id and is_demo_id(known):
            known = None  # a demo's simulator once sat on this address: a machine never takes a demo's id
        self._task = asyncio.create_task(self._run(), name=f"session-{self.spec.name}")
        if known is None:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(self.agent.first_attempt_s):
                    await self._first_attempt.wait()
        serial = self._identity.serial if self._identity else None
        fallback = device_id(self.spec.kind, None, self.spec.address)
        chosen = known or self.agent.claim_id(device_id(self.spec.kind, serial, self.spec.address), fallback)
        self._set_info(chosen)
        self._set_state(online=self.online, summary=offline_summary(self._reason) if not self.online else None)
        self._id_ready.set()

    async def stop(self) -> None:
        self._stopping = True
        tasks = [t for t in (self._task, self._job_task, *self._background) if t is not None]
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(BaseException):
                await task
        try:
            await self.link.close()
        finally:
            self.link.release()

    def _set_info(self, id_: str | None = None) -> None:
        ident = self._identity
        self.info = DeviceInfo(id_ or self.info.id, self.spec.name, self.spec.kind, ident.model if ident else None,
                               ident.serial if ident else None, ident.firmware if ident else None,
                               self.spec.address)

    # ------------------------------------------------------------------------------------------ the loop

    async def _run(self) -> None:
        low, high = self.agent.backoff
        delay = low
        while True:
            try:
                self._identity = await self.link.connect()
            except LINK_FAILURES as exc:
                self._failed(exc)
                with contextlib.suppress(*LINK_FAILURES):  # a link opened before the handshake failed is shut
                    await self.link.close()
                self._first_attempt.set()
                await self._id_ready.wait()
                await self._went_offline(delay)
                await asyncio.sleep(delay * random.uniform(0.8, 1.2))
                delay = min(delay * 2, high)
                continue
            self._first_attempt.set()
            await self._id_ready.wait()
            delay = low
            self._set_info()
            self.online = True
            log.info("%s online: %s %s", self.spec.name, self.info.model or self.spec.kind, self.spec.address)
            self._publish("online", info=self.info.to_dict())
            try:
                await self._monitor()
            except LINK_FAILURES as exc:
                self._failed(exc)
            finally:
                self.online = False
                await self.link.close()
            await self._went_offline(delay)
            await asyncio.sleep(delay * random.uniform(0.8, 1.2))

    def _failed(self, exc: BaseException) -> None:
        self._reason = str(exc) or type(exc).__name__
        self._reason_code = exit_code_of(exc)

    async def _went_offline(self, retry_in: float) -> None:
        self.online = False
        log.info("%s offline: %s", self.spec.name, self._reason)
        self._publish("offline", reason=self._reason, exit_code=self._reason_code, retry_in_s=round(retry_in, 2))
        summary = offline_summary(self._reason)
        self._set_state(online=False, summary=summary)
        self.agent.history.record_sample(self.info.id, time.time(), summary)

    async def _monitor(self) -> None:
        await self.link.poll_forever()

    def polled(self, status: dict[str, Any] | None, summary: dict[str, Any], at: float, lag: float,
               interval: float) -> None:
        """A scheduled poll's result, from the link (see `fabwire.agent.links.LinkOwner`)."""
        self.stats.record(lag, interval)
        if self.online:  # a result that arrives after the link went down is not news
            self._set_state(online=True, summary=summary, status=status)
            self.agent.history.record_sample(self.info.id, at, summary)

    def _set_state(self, *, online: bool, summary: dict[str, Any] | None, status: dict[str, Any] | None = None
                   ) -> None:
        previous = self.state
        if self._job is not None and summary is not None and online:
            note_course(self._job, summary, time.time())
        if previous and status is not None and status is previous["status"] and summary is previous["summary"] \
                and online == previous["online"] and self._job is previous["job"]:
            self.state = {**previous, "ts": now_iso()}  # the same objects as last time: nothing to compare
            return
        state = {"ts": now_iso(), "online": online, "device": self.info.id, "kind": self.spec.kind,
                 "name": self.spec.name, "summary": summary or previous.get("summary") or offline_summary(""),
                 "status": status if status is not None else previous.get("status"), "job": self._job}
        self.state = state
        if not previous or any(k != "ts" and value is not previous[k] and value != previous[k]
                               for k, value in state.items()):
            self._publish("state", state=state)

    def _publish(self, type_: Any, **payload: Any) -> None:
        if self.info.id:
            self.agent.publish(make_event(self.info.id, type_, **payload))

    def device_event(self, payload: dict[str, Any]) -> None:
        """Something the machine reported on its own, from the link."""
        self._publish("event", event=payload)

    # ------------------------------------------------------------------------------------------ actions

    def _require_online(self) -> None:
        if not self.online:
            raise LinkError(f"{self.spec.name} is offline ({self._reason})")

    def _offered(self, action: str) -> bool:
        offered = (self.state.get("summary") or {}).get("actions")
        return offered is None or action in offered

    async def _require_offered(self, action: str) -> None:
        """DeviceBusy (HTTP 409) naming the machine's state unless its summary's `actions` (the driver's table of
        what each state offers) holds `action`: what the machine cannot do now is refused before anything is sent,
        never accepted and then failed out of sight. A refusal is checked against a fresh poll first: the last
        one may be from before the machine became free (a job just ended)."""
        if self._offered(action):
            return
        await self._refresh_state()
        if self._offered(action):
            return
        summary = self.state.get("summary") or {}
        offered = summary.get("actions") or []
        state = summary.get("state") or "busy"
        text = summary.get("state_text")
        now = f"{state} ({text})" if text and text != state else state
        can = f"it offers {', '.join(offered)} now" if offered else "it offers no action until that ends"
        if action in JOB_ACTIONS:
            raise DeviceBusy(f"{self.spec.name} has nothing to {action}: it is {now}; {can}")
        if summary.get("busy"):
            raise DeviceBusy(f"{self.spec.name} is busy and cannot {action} now: it is {now}; {can}")
        raise DeviceBusy(f"{self.spec.name} cannot {action} now: it is {now}; {can}")

    async def act(self, action: str, params: dict[str, Any]) -> dict[str, Any]:
        spec = self.driver.action(action)
        if spec.confirm and params.get("confirm") is not True and not (action == "cancel" and self._job is not None):
            self._require_online()  # what cannot happen now is refused as such, never asked to be confirmed
            await self._require_offered(action)
        checked = checked_params(spec, params)
        self._require_online()
        if action == "cancel" and self._job is not None:  # the print is this agent's job: end the job with it
            return await self.cancel_job(self._job["id"], confirm=True)
        await self._require_offered(action)
        if spec.job:
            async with self.claim_job(None, action) as claim:
                job = await claim.start(checked)
            return {"started": action, "job": job}
        if spec.background:
            task = asyncio.create_task(self._background_action(action, checked))
            self._background.add(task)
            task.add_done_callback(self._background.discard)
            return {"started": action}
        result, polled = await self.link.act_then_poll(action, checked)
        if polled is not None and self.online:
            self._set_state(online=True, summary=polled[1], status=polled[0])
        return result

    async def _refresh_state(self) -> None:
        """The machine's state from a poll out of turn. A job's end is recorded after it, so whoever sees the job
        ended also sees the state the job left (a finished print on the bed), never a poll from before the job."""
        if not self.online:
            return
        polled = await self.link.poll_now()
        if polled is not None and self.online:
            self._set_state(online=True, summary=polled[1], status=polled[0])

    async def _background_action(self, action: str, params: dict[str, Any]) -> None:
        try:
            result = await self.link.act(action, params)
            self._publish("event", event={"event": "action-done", **result})
        except (*LINK_FAILURES, FabwireError) as exc:
            self._publish("error", message=f"{action}: {exc}", exit_code=exit_code_of(exc), action=action)

    # ------------------------------------------------------------------------------------------ jobs

    def claim_job(self, filename: str | None, job_type: str | None = None) -> JobClaim:
        """Claim the machine for one job, atomically (no await between the check and the claim): of any number
        of simultaneous requests exactly one gets the claim; the others get DeviceBusy (HTTP 409) saying why.

        `filename` is an upload's name (its extension picks the job type, InputError when the kind takes no such
        file); None with `job_type` is a job action (a Line-us text). LinkError when the machine is offline."""
        if filename is not None:
            require_plain_name(filename)
            suffix = Path(filename).suffix.lower() if "." in filename else ""
            job_type = self.driver.job_types.get(suffix)
            if job_type is None:
                accepted = ", ".join(sorted(self.driver.job_types))
                raise InputError(f"{self.spec.name} takes {accepted} files, not {excerpt(Path(filename).name, 80)}"
                                 if accepted else f"{self.spec.name} takes no files")
        if job_type is None:
            raise InputError("a job needs a file or an action")
        self._require_online()
        if filename is not None:  # 409 with the reason (a print still on the bed …), never accepted-then-failed
            self.agent.library.machines.require_ready(self.info.id)
        if self._job is not None:
            raise DeviceBusy(f"{self.spec.name} is busy with job {self._job['id']} ({self._job['state']}): "
                             "cancel it or wait")
        if self._claim is not None:
            raise DeviceBusy(f"{self.spec.name} is taking another job ({self._claim.what}): wait for it")
        self._claim = JobClaim(self, job_type, filename)
        return self._claim

    async def start_job(self, filename: str, data: bytes) -> dict[str, Any]:
        """Upload `data` as `filename` and start it: `claim_job`, `JobClaim.write`, `JobClaim.start`."""
        async with self.claim_job(filename) as claim:
            await claim.write(data)
            return await claim.start()

    def _begin(self, job: dict[str, Any]) -> dict[str, Any]:
        """The claim becomes the running job (called by JobClaim.start, with no await in between)."""
        self._claim = None
        self._job = job
        self.drawing = {"preview": [], "ink": []}
        self._job_task = asyncio.create_task(self._run_job(job), name=f"job-{job['id']}")
        self._set_state(online=self.online, summary=None)  # the device's state names its job from now on
        return dict(job)

    async def _run_job(self, job: dict[str, Any]) -> None:
        path = self.agent.jobs.path_of(job)
        await self._job_changed(state="running", started=now_iso())
        try:
            message = await self.link.run_job(path, job["type"], job.get("params") or {})
        except asyncio.CancelledError:
            if self._stopping:
                await self._job_changed(state="interrupted", message="the agent stopped while the job ran")
            else:
                await self._job_changed(state="cancelled", finished=now_iso(), message="cancelled")
            raise
        except (*LINK_FAILURES, FabwireError) as exc:
            if self._cancelling:
                await self._job_changed(state="cancelled", finished=now_iso(), message="cancelled")
            else:
                # the stored file's path is the agent's business: messages name the upload as it was sent
                shown = str(exc).replace(str(path), job["filename"] or "the upload") if path else str(exc)
                await self._refresh_state()
                await self._job_changed(state="failed", finished=now_iso(), message=shown)
                self._publish("error", message=f"job {job['id']}: {shown}", exit_code=exit_code_of(exc),
                              job=job["id"])
        else:
            await self._refresh_state()
            await self._job_changed(state="done", finished=now_iso(), progress_percent=100.0, time_left_s=0.0,
                                    message=message)
        finally:
            self._job = None
            self._cancelling = False
            self._set_state(online=self.online, summary=None)

    async def _job_changed(self, **fields: Any) -> None:
        if self._job is None:
            return
        self._job.update(fields)
        await self.agent.jobs.save(self._job)
        self._publish("job", job=dict(self._job))

    def job_progress(self, percent: float, time_left_s: float | None, message: str | None) -> None:
        """A running job's progress: it only goes forward (a printer that stops says 0, a da Vinci's `d:0,0,0` is
        "no job", and the job keeps how far it came: a cancelled print's figures are those at its end)."""
        if self._job is None:
            return
        percent = max(percent, float(self._job.get("progress_percent") or 0.0))
        self._job.update(progress_percent=round(percent, 1), time_left_s=time_left_s,
                         message=message or self._job.get("message"))
        now = time.monotonic()
        if now - self._last_job_event >= JOB_EVENT_EVERY_S or percent >= 100:
            self._last_job_event = now
            self._publish("job", job=dict(self._job))
            self._keep(self._save_progress(dict(self._job)))

    async def _save_progress(self, job: dict[str, Any]) -> None:
        """The job list shows progress too; a save that would come after the job's end is left out (the end's
        own save, queued first on the history's one thread, stands)."""
        current = self._job
        if current is not None and current["id"] == job["id"] and current.get("state") == "running":
            await self.agent.jobs.save(job)

    def _keep(self, work: Coroutine[Any, Any, None]) -> None:
        task = asyncio.create_task(work)
        self._background.add(task)
        task.add_done_callback(self._background.discard)

    def job_note(self, text: str) -> None:
        """A note the CLI would print for this job, kept in the record's `notes` (a list of words)."""
        if self._job is not None:
            self._job["notes"] = [*(self._job.get("notes") or []), text]
            self._publish("job", job=dict(self._job))

    def job_stroke(self, points: list[tuple[float, float]]) -> None:
        self.drawing["ink"].append(points)
        if self._job is not None:
            self._publish("job", job=dict(self._job), stroke=points)

    def job_preview(self, strokes: list[list[tuple[float, float]]]) -> None:
        self.drawing = {"preview": strokes, "ink": []}
        if self._job is not None:
            self._publish("job", job=dict(self._job), preview=strokes)

    async def cancel_job(self, job_id: str, *, confirm: bool) -> dict[str, Any]:
        if self._job is None or self._job["id"] != job_id or self._job_task is None:
            job = await self.agent.jobs.get(job_id)
            raise InputError(f"job {job_id} is not running (it is {job['state']})")
        if not confirm:
            raise InputError(f"cancelling job {job_id} stops it for good: send \"confirm\": true to go ahead")
        job = dict(self._job)
        task = self._job_task
        self._cancelling = True
        # The machine stops and the job's loop then winds down. Asked again while the job runs: a job still
        # sending its file has nothing to stop yet ("nothing to cancel"), and the print that file then starts
        # must be stopped too, not left heating and moving under a job that says "cancelled".
        loop = asyncio.get_running_loop()
        deadline = loop.time() + STOP_WAIT_S
        pending: set[asyncio.Task[None]] = {task}
        refused: BaseException | None = None
        while pending and (left := deadline - loop.time()) > 0:
            try:
                await self.link.stop_job()
                refused = None
            except (*LINK_FAILURES, FabwireError) as exc:
                refused = exc
            _, pending = await asyncio.wait({task}, timeout=min(STOP_AGAIN_S, max(left, 0.0)))
        if pending and refused is not None:
            self._publish("error", message=f"stopping job {job_id}: {refused}", exit_code=exit_code_of(refused))
        if pending:  # it would not stop: cut it off, and start the link afresh (a command may be half-answered)
            task.cancel()
            with contextlib.suppress(BaseException):
                await task
            await self.link.close()
        return await self.agent.jobs.get(job_id)


class JobClaim:
    """The machine, claimed for one job that is still arriving (see `Session.claim_job`).

        async with agent.claim_job(device, "part.gcode") as claim:    # DeviceBusy (409) if taken
            async for chunk in request.stream():
                await claim.write(chunk)                               # UploadTooLarge 413, DiskFull 507
            job = await claim.start()                                  # the file checked (400), the job runs

    Leaving the block without `start` (an error, a client gone) releases the machine and deletes what was
    written. `what` names the claim in the refusals others get."""

    def __init__(self, session: Session, job_type: str, filename: str | None) -> None:
        from fabwire.agent.jobs import new_job_id

        self.session = session
        self.job_type = job_type
        self.filename = filename
        self.job_id = new_job_id()
        self.what = f"upload of {excerpt(filename, 60)}" if filename else f"{job_type} job"
        self._upload = session.agent.jobs.writer(self.job_id, filename) if filename is not None else None
        self._started = False

    async def __aenter__(self) -> JobClaim:
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.release()

    @property
    def size(self) -> int:
        """Bytes received so far."""
        return self._upload.size if self._upload else 0

    async def write(self, chunk: bytes) -> None:
        """Append to the upload (written to disk in batches, never held whole)."""
        if self._upload is None:
            raise InputError(f"a {self.job_type} job takes no file")
        await self._upload.write(chunk)

    async def start(self, params: dict[str, Any] | None = None, *, file_meta: dict[str, Any] | None = None
                    ) -> dict[str, Any]:
        """Complete the upload, check it as the CLI would (InputError naming the upload), record the job (with the
        library's `file_meta` figures of its file, when it has them) and start it; returns the job record."""
        session = self.session
        if self._started or session._claim is not self:
            raise RuntimeError("this claim is already used or released")
        path = await self._upload.finish() if self._upload is not None else None
        if path is not None:
            await session.link.check_upload(self.filename or path.name, path)
        job = await session.agent.jobs.create(session.info.id, self.job_type, self.filename, self._upload,
                                              params or {}, job_id=self.job_id, file_meta=file_meta)
        self._started = True
        return session._begin(job)

    def release(self) -> None:
        """Give the machine back and delete the upload, unless the job started; safe to call twice."""
        if self._started:
            return
        if self._upload is not None:
            self._upload.discard()
        if self.session._claim is self:
            self.session._claim = None
