"""What a session needs from each kind of device: connect, poll, act, run a job — through the CLI's clients.

The summary is the one view the dashboard and the MQTT bridge read for every kind. Its keys (None when the
kind has no such thing, SI units in the names):
  state ("idle", "printing", "paused", "busy", "done", "error", "drawing", "offline"), state_text (words),
  error (words or None), error_code, busy (bool), progress_percent, elapsed_s, time_left_s,
  extruder_temp_c, extruder_target_c, bed_temp_c, bed_target_c, filament_left_mm,
  extruder2_temp_c, filament2_left_mm (a second extruder or spool: da Vinci 2.0 Duo, Jr. 2.0 Mix),
  position ({"x", "y", "z"} in the Line-us's own units), pen_down,
  active_slot, filament_position (words), selector_slot, idler_slot, finda,
  prompt (words a flow waits on the owner to confirm, e.g. "Lower the calibration detector, then confirm"),
  actions (names of the actions that apply now, for buttons).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Protocol

from fabwire.agent.core import DeviceSpec
from fabwire.errors import FabwireError, InputError

Emit = Callable[[dict[str, Any]], None]
"""Forwards a device's own event (an `"event"` payload) to the session."""

SUMMARY_KEYS = (
    "state", "state_text", "error", "error_code", "busy", "progress_percent", "elapsed_s", "time_left_s",
    "extruder_temp_c", "extruder_target_c", "bed_temp_c", "bed_target_c", "filament_left_mm", "position",
    "pen_down", "active_slot", "filament_position", "selector_slot", "idler_slot", "finda", "prompt", "actions",
    "extruder2_temp_c", "filament2_left_mm",
)


def summary(**values: Any) -> dict[str, Any]:
    """A summary with every key present (unknown keys are a programming error)."""
    unknown = set(values) - set(SUMMARY_KEYS)
    if unknown:
        raise KeyError(f"not summary keys: {sorted(unknown)}")
    out: dict[str, Any] = dict.fromkeys(SUMMARY_KEYS)
    out.update(values)
    out["busy"] = bool(out["busy"])
    out["actions"] = list(out["actions"] or [])
    return out


OFFLINE_TEXT = "offline: "
"""How an offline machine's `state_text` begins; the reason follows."""


def offline_summary(reason: str) -> dict[str, Any]:
    return summary(state="offline", state_text=f"{OFFLINE_TEXT}{reason}")


def offline_reason(state_text: str) -> str:
    """Why a machine is offline, from its `state_text` (for a place that already says "offline")."""
    return state_text.removeprefix(OFFLINE_TEXT)


@dataclass(frozen=True, slots=True)
class Identity:
    model: str | None
    serial: str | None
    firmware: str | None


@dataclass(frozen=True, slots=True)
class Param:
    name: str
    type: str
    """"int" | "float" | "str" | "bool"."""
    doc: str
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    nonzero: bool = False
    """A number that may not be 0 (a jog distance)."""


@dataclass(frozen=True, slots=True)
class Action:
    name: str
    doc: str
    params: tuple[Param, ...] = ()
    confirm: bool = False
    """Destructive: refused unless the request says `"confirm": true` (as the CLI asks)."""
    background: bool = False
    """Takes long (homing, a tool change): the request returns at once, the outcome arrives as events."""
    job: bool = False
    """Runs as a job (listed, cancellable, with progress) through `Driver.run_job`."""

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "doc": self.doc, "confirm": self.confirm, "background": self.background,
                "job": self.job,
                "params": [{"name": p.name, "type": p.type, "doc": p.doc, "min": p.low, "max": p.high,
                            "choices": list(p.choices) or None} for p in self.params]}


class JobStopped(FabwireError):
    """A job ended because it was cancelled."""


class JobHandle(Protocol):
    """How a running job reports back: progress, and (Line-us) the stroke just drawn."""

    def progress(self, percent: float, *, time_left_s: float | None = None, message: str | None = None) -> None: ...

    def stroke(self, points: list[tuple[float, float]]) -> None: ...

    def preview(self, strokes: list[list[tuple[float, float]]]) -> None: ...

    def note(self, text: str) -> None:
        """Something the owner should know about the job (what the planner left out of a drawing …)."""


def checked_params(action: Action, params: Mapping[str, Any]) -> dict[str, Any]:
    """Validate `params` against `action`: types, ranges and choices; unknown names are errors."""
    known = {p.name: p for p in action.params}
    extra = set(params) - set(known) - {"confirm"}
    if extra:
        raise InputError(f"{action.name} takes no parameter {sorted(extra)[0]!r}"
                         + (f" (it takes {', '.join(known)})" if known else ""))
    if action.confirm and params.get("confirm") is not True:
        what = action.doc.split(". ")[0].rstrip(".")
        raise InputError(f"{action.name} cannot be undone: send \"confirm\": true to {what[:1].lower()}{what[1:]}")
    out: dict[str, Any] = {}
    for param in action.params:
        if param.name not in params:
            raise InputError(f"{action.name} needs the parameter {param.name!r} ({param.doc})")
        out[param.name] = _coerce(action.name, param, params[param.name])
    return out


def _coerce(action: str, param: Param, value: Any) -> Any:
    where = f"{action}: {param.name}"
    if param.type == "str":
        if not isinstance(value, str) or not value.strip():
            raise InputError(f"{where} must be non-empty text")
        if param.choices and value not in param.choices:
            raise InputError(f"{where} must be one of {', '.join(param.choices)}, not {value!r}")
        return value
    if param.type == "bool":
        if not isinstance(value, bool):
            raise InputError(f"{where} must be true or false")
        return value
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"{where} must be a finite number, not {value!r}")
    if param.nonzero and value == 0:
        raise InputError(f"{where} must not be 0")
    if param.type == "int" and value != int(value):
        raise InputError(f"{where} must be a whole number, not {value!r}")
    if (param.low is not None and value < param.low) or (param.high is not None and value > param.high):
        raise InputError(f"{where} must be from {param.low:g} to {param.high:g}, not {value!r}")
    return int(value) if param.type == "int" else float(value)


class Driver(ABC):
    """One device kind's way of being monitored and commanded; a session owns one driver per device."""

    kind: ClassVar[str]
    interval_s: ClassVar[float]
    """How often `poll` runs while connected."""
    actions: ClassVar[tuple[Action, ...]]
    job_types: ClassVar[Mapping[str, str]] = {}
    """File extension (lower case, with the dot) → the kind of job it starts."""

    def __init__(self, spec: DeviceSpec, emit: Emit) -> None:
        self.spec = spec
        self.emit = emit

    def check_upload(self, name: str, path: Path) -> None:  # noqa: B027 - kinds without files check nothing
        """Refuse an upload (complete, at `path`) this device cannot run with the intake's InputError (naming
        it `name`), before it is accepted; kinds that take no files accept anything `job_types` lets through."""

    def describe_upload(self, name: str, path: Path, *, check: bool = True) -> dict[str, Any]:
        """`check_upload` (unless `check` is False: the job about to start checks the file itself), and what the
        file says about itself for a file library: any of `fabwire.agent.library.META_FIGURES` (absent where it
        does not say; kinds without such figures say nothing), and optionally `picture`, (PNG bytes, (width,
        height)), shown where the file carries no preview of its own."""
        if check:
            self.check_upload(name, path)
        return {}

    @abstractmethod
    async def connect(self) -> Identity:
        """Open the link and identify the machine; raises LinkError/LinkTimeout/RemoteProtocolError."""

    @abstractmethod
    async def poll(self) -> tuple[dict[str, Any] | None, dict[str, Any]]:
        """(the `--json status` dict, the summary); raises when the link is gone."""

    @abstractmethod
    async def close(self) -> None:
        """Close the link; never raises."""

    @abstractmethod
    async def act(self, action: str, params: dict[str, Any]) -> dict[str, Any]:
        """Run a checked action (see `checked_params`)."""

    async def run_job(self, path: Path | None, job_type: str, handle: JobHandle, params: dict[str, Any]) -> str:
        """Run a stored upload (or a job action with `params`) to its end; returns the closing words."""
        raise InputError(f"a {self.kind} takes no jobs")

    async def stop_job(self) -> None:  # noqa: B027 - kinds without jobs have nothing to stop
        """Stop the running job on the machine; `run_job` then ends (raising JobStopped or returning)."""

    def action(self, name: str) -> Action:
        for action in self.actions:
            if action.name == name:
                return action
        names = ", ".join(a.name for a in self.actions)
        raise InputError(f"{self.kind} devices have no action {name!r} (they have {names})")
