"""Klipper's printer objects as the Moonraker-compatible door serves them: one row per attribute, with what Klipper
reports in each state of a job's life, and the public source that says so.

A row's rule for a state is either a literal (`"=…"`, the JSON after the `=`) or the name of a fact (`FACTS`) about
the machine and its job (`fabwire.agent.model.JobFigures`). The state is Klipper's print_stats.state: "standby",
"printing", "paused", "complete", "cancelled", "error". Klipper keeps a finished, cancelled or failed job's
print_stats until the next print starts (or SDCARD_RESET_FILE); virtual_sdcard closes the file at the end of a print
(file_path null, the position left at the end) and forgets it on a cancel (position and size 0).

Sources: Moonraker's docs/printer_objects.md ("Printer Objects", moonraker.readthedocs.io); Klipper's
docs/Status_Reference.md (klipper3d.org/Status_Reference.html) and, for what each state leaves, the modules it
documents (klippy/extras/print_stats.py, virtual_sdcard.py, idle_timeout.py, pause_resume.py, display_status.py).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from fabwire.agent.history import epoch
from fabwire.agent.model import JobFigures, MachineView, job_figures

STATES = ("standby", "printing", "paused", "complete", "cancelled", "error")
"""Klipper's print_stats.state values (Moonraker docs, "Print Stats State")."""

IDLE_TIMEOUT_S = 600.0
"""Klipper's default [idle_timeout] timeout (Config_Reference.md, idle_timeout: "timeout: 600")."""
MIN_EXTRUDE_TEMP_C = 170.0
"""Klipper's default min_extrude_temp (Config_Reference.md, extruder: "min_extrude_temp: 170")."""

END_STATE: dict[str, str] = {"done": "complete", "cancelled": "cancelled", "failed": "error"}
"""How a job ended (the agent's job state) → the print_stats.state Klipper keeps until the next print."""

PHASE_STATE: dict[str, str] = {
    "standby": "standby", "printing": "printing", "pausing": "printing", "paused": "paused",
    "resuming": "paused", "cancelling": "printing", "done": "complete", "busy": "standby", "error": "error",
    "offline": "error",
}
"""The machine's phase (`fabwire.agent.model`) → print_stats.state, when no ended job says more."""


def print_state(view: MachineView) -> str:
    """Klipper's print_stats.state: a machine standing by after a job keeps how that job ended ("complete",
    "cancelled", "error"; print_stats.py `_note_finish`, reset only by a new print or SDCARD_RESET_FILE); otherwise
    by the phase (a job here is "printing" from its start, as `note_start` is at SDCARD_PRINT_FILE)."""
    if view.phase in ("standby", "busy") and view.job is None and view.last_job is not None:
        return END_STATE.get(str(view.last_job["state"]), "standby")
    return PHASE_STATE[view.phase]


@dataclass(frozen=True, slots=True)
class Attribute:
    """One attribute of one printer object, and what it holds in each print_stats state."""

    obj: str
    name: str
    rules: Mapping[str, str]
    """print_stats.state → a literal ("=0.0", "=null", '="Ready"') or a fact's name (`FACTS`)."""
    source: str

    def value(self, state: str, facts: Mapping[str, Any]) -> Any:
        rule = self.rules[state]
        return json.loads(rule[1:]) if rule.startswith("=") else facts[rule]


def every(rule: str) -> dict[str, str]:
    """The same rule in every state."""
    return dict.fromkeys(STATES, rule)


def by_state(standby: str, printing: str, paused: str, complete: str, cancelled: str, error: str) -> dict[str, str]:
    return dict(zip(STATES, (standby, printing, paused, complete, cancelled, error), strict=True))


def job_then(empty: str, fact: str) -> dict[str, str]:
    """`empty` on standby, the job's `fact` in every other state (print_stats keeps it after the end)."""
    return by_state(empty, fact, fact, fact, fact, fact)


PS = "Moonraker docs/printer_objects.md print_stats; Klipper Status_Reference.md print_stats; print_stats.py"
VS = "Moonraker docs/printer_objects.md virtual_sdcard; Klipper Status_Reference.md virtual_sdcard; virtual_sdcard.py"
IT = "Moonraker docs/printer_objects.md idle_timeout; Klipper Status_Reference.md idle_timeout; idle_timeout.py"

ATTRIBUTES: tuple[Attribute, ...] = (
    Attribute("webhooks", "state", every("klippy_state"),
              "Moonraker docs/printer_objects.md webhooks and external_api/printer.md Klippy state (ready, shutdown)"),
    Attribute("webhooks", "state_message", every("klippy_message"), "Moonraker docs/printer_objects.md webhooks"),
    Attribute("print_stats", "filename", job_then('=""', "filename"),
              PS + " (the file relative to gcodes; kept after the end until a new print or SDCARD_RESET_FILE)"),
    Attribute("print_stats", "total_duration", job_then("=0.0", "total_s"), PS + " (pauses included)"),
    Attribute("print_stats", "print_duration", job_then("=0.0", "print_s"), PS + " (does not include time paused)"),
    Attribute("print_stats", "filament_used", job_then("=0.0", "filament_used_mm"), PS + " (mm, for this job)"),
    Attribute("print_stats", "state", every("state"), PS + " (Print Stats State)"),
    Attribute("print_stats", "message", by_state('=""', '=""', '=""', '=""', '=""', "error"),
              PS + " (the error message of note_error, empty otherwise)"),
    Attribute("print_stats", "info.total_layer", job_then("=null", "layers"),
              PS + " (Print Stats Supplemental Info: null when the layer count is not known)"),
    Attribute("print_stats", "info.current_layer", job_then("=null", "current_layer"),
              PS + " (Print Stats Supplemental Info: null when not known; here from progress and the layer count)"),
    Attribute("virtual_sdcard", "file_path", by_state("=null", "filename", "filename", "=null", "=null", "filename"),
              VS + " (null once the file is closed: at the end of a print and on a cancel; kept on pause and error."
              " Klipper gives its full path on disk; here the name relative to gcodes: the agent's paths stay hidden)"),
    Attribute("virtual_sdcard", "progress", by_state("=0.0", "fraction", "fraction", "=1.0", "=0.0", "fraction"),
              VS + " (file_position / file_size; do_cancel sets both to 0)"),
    Attribute("virtual_sdcard", "is_active", by_state("=false", "=true", "=false", "=false", "=false", "=false"),
              VS + " (true only while the file is being processed)"),
    Attribute("virtual_sdcard", "file_position", by_state("=0", "position", "position", "size", "=0", "position"),
              VS + " (bytes; the end of the file once complete, 0 after a cancel)"),
    Attribute("virtual_sdcard", "file_size", by_state("=0", "size", "size", "size", "=0", "size"),
              VS + " (bytes; 0 after a cancel)"),
    Attribute("display_status", "progress", by_state("=0.0", "fraction", "fraction", "=1.0", "=0.0", "fraction"),
              "Moonraker docs/printer_objects.md display_status (M73, else virtual_sdcard.progress)"),
    Attribute("display_status", "message", every("machine_message"),
              "Moonraker docs/printer_objects.md display_status (the M117 message: here the machine's own words)"),
    Attribute("pause_resume", "is_paused", by_state("=false", "=false", "=true", "=false", "=false", "=false"),
              "Klipper Status_Reference.md pause_resume; pause_resume.py (cleared by RESUME and CANCEL_PRINT)"),
    Attribute("idle_timeout", "state",
              by_state("idle_state", '="Printing"', '="Ready"', "idle_state", "idle_state", "idle_state"),
              IT + " (Printing while busy, Ready until the timeout passes, then Idle)"),
    Attribute("idle_timeout", "printing_time", by_state("=0.0", "printing_s", "=0.0", "=0.0", "=0.0", "=0.0"),
              IT + " (seconds in the Printing state; 0 again once Ready)"),
    Attribute("idle_timeout", "idle_timeout", every(f"={IDLE_TIMEOUT_S}"), IT + " (the configured timeout)"),
    Attribute("toolhead", "homed_axes", every('=""'),
              "Klipper Status_Reference.md toolhead (the machines report no homing state: none known homed)"),
    Attribute("toolhead", "position", every("=[0.0, 0.0, 0.0, 0.0]"),
              "Klipper Status_Reference.md toolhead (the machines report no position)"),
    Attribute("toolhead", "print_time", job_then("=0.0", "total_s"), "Klipper Status_Reference.md toolhead"),
    Attribute("toolhead", "estimated_print_time", job_then("=0.0", "estimated_s"),
              "Klipper Status_Reference.md toolhead"),
    Attribute("extruder", "temperature", every("extruder_c"),
              "Moonraker docs/printer_objects.md extruder; Klipper Status_Reference.md extruder"),
    Attribute("extruder", "target", every("extruder_target_c"),
              "Moonraker docs/printer_objects.md extruder (0 when no target is set)"),
    Attribute("extruder", "power", every("=null"),
              "Moonraker docs/printer_objects.md extruder (heater PWM: these machines do not report it)"),
    Attribute("extruder", "can_extrude", every("can_extrude"),
              "Moonraker docs/printer_objects.md extruder (above min_extrude_temp, 170 C by default)"),
    Attribute("heater_bed", "temperature", every("bed_c"),
              "Moonraker docs/printer_objects.md heater_bed; Klipper Status_Reference.md heater_bed"),
    Attribute("heater_bed", "target", every("bed_target_c"), "Moonraker docs/printer_objects.md heater_bed"),
    Attribute("heater_bed", "power", every("=null"),
              "Moonraker docs/printer_objects.md heater_bed (heater PWM: these machines do not report it)"),
)
"""Every attribute the door serves. `extruder` and `heater_bed` are served only for a machine reporting that
heater's temperature (Klipper lists only the objects its configuration has)."""

OPTIONAL: dict[str, Callable[[MachineView], bool]] = {
    "extruder": lambda v: v.extruder_c is not None or v.extruder_target_c is not None,
    "heater_bed": lambda v: v.bed_c is not None or v.bed_target_c is not None,
}
"""Objects a machine has only when it reports them."""


def facts(view: MachineView, figures: JobFigures | None, filename: str, now: float | None = None) -> dict[str, Any]:
    """What the rules name: the machine's state and its shown job's figures (zeros without a job)."""
    now = time.time() if now is None else now
    ended = figures.finished if figures is not None else None
    recent = ended is not None and now - ended < IDLE_TIMEOUT_S
    return {
        "state": print_state(view), "filename": filename,
        "total_s": figures.total_s if figures else 0.0, "print_s": figures.print_s if figures else 0.0,
        "printing_s": figures.printing_s if figures else 0.0,
        "filament_used_mm": figures.filament_used_mm if figures else 0.0,
        "fraction": figures.fraction if figures else 0.0, "position": figures.position if figures else 0,
        "size": figures.size if figures else 0, "layers": figures.layers if figures else None,
        "current_layer": figures.current_layer if figures else None,
        "estimated_s": figures.estimated_s or 0.0 if figures else 0.0,
        "error": view.error or view.message,
        "klippy_state": "ready" if view.online else "shutdown",
        "klippy_message": "Printer is ready" if view.online else view.message,
        "machine_message": view.message, "idle_state": "Ready" if recent else "Idle",
        "extruder_c": view.extruder_c, "extruder_target_c": view.extruder_target_c or 0.0,
        "can_extrude": view.extruder_c is not None and view.extruder_c >= MIN_EXTRUDE_TEMP_C,
        "bed_c": view.bed_c, "bed_target_c": view.bed_target_c or 0.0,
    }


def printer_objects(view: MachineView, figures: JobFigures | None, filename: str,
                    now: float | None = None) -> dict[str, dict[str, Any]]:
    """Every printer object the machine has, every attribute by `ATTRIBUTES` (a dotted name is a nested one)."""
    known = facts(view, figures, filename, now)
    state = known["state"]
    out: dict[str, dict[str, Any]] = {}
    for attribute in ATTRIBUTES:
        has = OPTIONAL.get(attribute.obj)
        if has is not None and not has(view):
            continue
        target = out.setdefault(attribute.obj, {})
        *parents, leaf = attribute.name.split(".")
        for parent in parents:
            target = target.setdefault(parent, {})
        target[leaf] = attribute.value(state, known)
    return out


HISTORY_STATUS: dict[str, str] = {
    "queued": "in_progress", "running": "in_progress", "done": "completed", "failed": "error",
    "cancelled": "cancelled", "interrupted": "interrupted",
}
"""The agent's job state → Moonraker's history job status (docs/external_api/history.md, Job Status: in_progress,
completed, cancelled, error, klippy_shutdown, klippy_disconnect, interrupted)."""

HISTORY_STATES = ("in_progress", "completed", "cancelled", "error", "interrupted")


def by_status(in_progress: str, ended: str, interrupted: str) -> dict[str, str]:
    return {"in_progress": in_progress, "completed": ended, "cancelled": ended, "error": ended,
            "interrupted": interrupted}


HS = "Moonraker docs/external_api/history.md, Job History entry"

HISTORY_FIELDS: tuple[Attribute, ...] = (
    Attribute("job", "job_id", dict.fromkeys(HISTORY_STATES, "job_id"), HS),
    Attribute("job", "user", dict.fromkeys(HISTORY_STATES, "=null"), HS + " (null when no user is known)"),
    Attribute("job", "filename", dict.fromkeys(HISTORY_STATES, "filename"), HS + " (relative to gcodes)"),
    Attribute("job", "exists", dict.fromkeys(HISTORY_STATES, "exists"), HS + " (the file is still kept)"),
    Attribute("job", "status", dict.fromkeys(HISTORY_STATES, "status"), HS + " (Job Status)"),
    Attribute("job", "start_time", dict.fromkeys(HISTORY_STATES, "start_time"), HS + " (unix time)"),
    Attribute("job", "end_time", by_status("=null", "end_time", "=null"),
              HS + " (null while in progress and when interrupted before its end)"),
    Attribute("job", "print_duration", dict.fromkeys(HISTORY_STATES, "print_s"), HS + " (time not paused)"),
    Attribute("job", "total_duration", dict.fromkeys(HISTORY_STATES, "total_s"), HS + " (time paused included)"),
    Attribute("job", "filament_used", dict.fromkeys(HISTORY_STATES, "filament_used_mm"),
              HS + " (mm; print_stats.filament_used at the end)"),
    Attribute("job", "metadata", dict.fromkeys(HISTORY_STATES, "metadata"),
              HS + " (the file's gcode metadata at the time of the job: docs/external_api/file_manager.md)"),
    Attribute("job", "auxiliary_data", dict.fromkeys(HISTORY_STATES, "=[]"), HS + " (no sensors supply any here)"),
)
"""Every field of a job in `server.history.list`, by the job's status."""


def history_job(job: dict[str, Any], kept: set[str], now: float | None = None) -> dict[str, Any]:
    """One job record (`fabwire.agent.jobs`) as a Moonraker history entry; `kept` holds the names of the files
    still kept."""
    figures = job_figures(job, now)
    meta = job.get("file_meta") or {}
    status = HISTORY_STATUS.get(figures.state, "error")
    known = {"job_id": job["id"], "filename": figures.filename or job["type"],
             "exists": job.get("filename") in kept, "status": status,
             "start_time": figures.started or epoch(job["created"]), "end_time": figures.finished,
             "print_s": figures.print_s, "total_s": figures.total_s, "filament_used_mm": figures.filament_used_mm,
             "metadata": {"size": job.get("size_bytes"), "estimated_time": meta.get("print_time_s"),
                          "filament_total": meta.get("filament_mm"), "layer_count": meta.get("layers"),
                          "slicer": meta.get("slicer")}}
    return {field.name: field.value(status, known) for field in HISTORY_FIELDS}
