"""A da Vinci under the agent: `XYZPrinter.status()` each second, job control, and printing uploads."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

from fabwire import units
from fabwire.agent.drivers.base import Action, Driver, Identity, JobHandle, JobStopped, Param, summary
from fabwire.agent.opening import open_xyz
from fabwire.errors import InputError, LinkClosed
from fabwire.units import ZOFFSET_LIMIT_MM
from fabwire.xyz import intake, printjob
from fabwire.xyz.client import XYZPrinter
from fabwire.xyz.commands import JOG_LIMIT
from fabwire.xyz.status import CANCELLING, FILE_CHECK, IDLE, PAUSED, PRINT_DONE, Status, changed_fields
from fabwire.xyz.threew import inspect_3w

IDLE_ACTIONS = ("home", "jog", "load_filament", "unload_filament", "clean_nozzle", "calibrate", "zoffset",
                "zoffset_step")
PROMPT_ACTIONS = ["confirm", "stop_flow"]
PROMPT_LIMIT_S = 15 * 60.0
"""How long a flow waits for the owner at a prompt before it stops (and cancels the flow on the printer)."""
PRINT_STATES = range(9500, 9511)
BUSY_STATES = frozenset({9513, 9514, 9515, 9516, 9530, 9531, 9532, 9534, 9535, 9536, 9537, 9538, 9540, 9700, 30})
ERROR_STATES = frozenset({9517, 9533})


def _target(status: Status, key: str) -> int | None:
    value = (status.targets or {}).get(key)
    return int(value) if isinstance(value, int) or (isinstance(value, str) and value.isdigit()) else None


SUMMARY_FIELDS = frozenset({"state", "errors", "model_number", "progress", "temperatures", "targets", "bed",
                            "filament"})
"""The status fields `printer_summary` reads: a poll that changed none of them keeps the summary it had."""


def printer_summary(status: Status) -> dict[str, Any]:
    """The agent's common view of a status (`Status` is what `fabwire xyz status --json` prints)."""
    code = status.state_code
    errors = status.error_words
    if code in ERROR_STATES or errors:
        state = "error"
    elif code == PAUSED:
        state = "paused"
    elif code == PRINT_DONE:
        state = "done"
    elif code in PRINT_STATES or code in (FILE_CHECK, CANCELLING):
        state = "printing"
    elif code in BUSY_STATES:
        state = "busy"
    else:
        state = "idle" if code == IDLE else "busy"
    progress = status.progress
    percent = progress.percent if progress else None
    time_left_s = progress.remaining_min * 60 if progress and progress.remaining_min is not None else None
    if state == "done":  # "print finished" reports d:0,0,0: the print is whole, not at its start
        percent, time_left_s = 100, 0
    actions = {"idle": list(IDLE_ACTIONS), "printing": ["pause", "cancel"],
               "paused": ["resume", "cancel"], "done": ["acknowledge"], "busy": [], "error": []}[state]
    if state == "error" and code == PRINT_DONE:
        actions = ["acknowledge"]
    return summary(
        state=state, state_text=status.state_name,
        error="; ".join(w.meaning for w in errors) or None,
        error_code=f"0x{errors[0].raw:08X}" if errors else None,
        busy=state in ("printing", "paused", "busy"),
        progress_percent=percent,
        elapsed_s=progress.elapsed_min * 60 if progress else None,
        time_left_s=time_left_s,
        extruder_temp_c=status.extruder, extruder_target_c=status.extruder_target,
        bed_temp_c=status.bed, bed_target_c=_target(status, "bed"),
        filament_left_mm=status.filament_mm, actions=actions,
        extruder2_temp_c=status.temperatures.extruder2 if status.temperatures else None,
        filament2_left_mm=status.filament2_mm,
    )


class XYZDriver(Driver):
    kind = "xyz"
    interval_s = 1.0
    actions = (
        Action("pause", "Pause the print."),
        Action("resume", "Resume a paused print."),
        Action("cancel", "Cancel the print.", confirm=True),
        Action("acknowledge", "Acknowledge a finished print (the printer's OK button)."),
        Action("home", "Home all axes.", background=True),
        Action("jog", "Move one axis.", (Param("axis", "str", "x, y or z", choices=("x", "y", "z")),
                                         Param("distance_mm", "float", "signed distance in mm", -JOG_LIMIT, JOG_LIMIT,
                                                               nonzero=True)),
               background=True),
        Action("unload_filament", "Heat and unload the filament.", background=True),
        Action("load_filament", "Heat and feed filament; confirm when it comes out of the nozzle.", background=True),
        Action("clean_nozzle", "Heat the nozzle for cleaning; confirm when it is clean.", background=True),
        Action("calibrate", "Level the bed with the detector: lower it and raise it when asked; the nine bed "
               "readings arrive in the status (calibration).", background=True),
        Action("confirm", "Answer the step a flow waits on (filament out, nozzle clean, detector lowered/raised)."),
        Action("stop_flow", "Stop the flow waiting on a step (the printer cancels it)."),
        Action("zoffset", "Set the Z offset in mm (0.01 mm steps).",
               (Param("mm", "float", "Z offset in mm", -ZOFFSET_LIMIT_MM, ZOFFSET_LIMIT_MM),)),
        Action("zoffset_step", "Move the Z offset one 0.01 mm step up or down.",
               (Param("direction", "str", "up or down", choices=("up", "down")),)),
    )
    job_types: ClassVar[Mapping[str, str]] = {".gcode": "print", ".gco": "print", ".g": "print", ".3w": "print"}

    def check_upload(self, name: str, path: Path) -> None:
        """The printer intake's refusal for what no printer takes (binary data, images, SVG, G-code without
        commands, G-code beyond this printer's build volume), so a bad file is refused at upload rather than
        failing the job later; read from disk in pieces, never whole."""
        self.describe_upload(name, path)

    def describe_upload(self, name: str, path: Path, *, check: bool = True) -> dict[str, Any]:
        """`check_upload`, and the figures the intake reads for the .3w header (a G-code's comments, or its
        moves where the comments are silent); with `check` False, only what the figures need is read. With
        `check`, a G-code that extrudes beyond the connected model's build volume, or whose arcs would grow it too
        much as segments, is refused (InputError) as `fabwire xyz print` refuses it, so the refusal is the answer
        to the upload or to the start."""
        kind, head = intake.sniff(path, name)
        intake.require_printable(kind, name, head)
        if kind is intake.Kind.GCODE:  # every line, and figures no print has, as `xyz print` checks them
            model = self._last[0].model if self._last is not None and check else None
            with intake.open_input(path, name) as source:
                try:  # arcs the print's conversion would refuse are refused now, in words for an API user
                    stated, computed = intake.stream_metadata(source, name, every_line=check, arcs_grow=check)
                except InputError as exc:
                    from fabwire.xyz import arcwork  # (loaded by the reading already: numpy waits for G-code)

                    if not isinstance(exc, arcwork.TooMuchGrowth):
                        raise
                    raise arcwork.too_much_growth(name, exc.arc, "slice it with arcs off and send it again") from None
                meta = stated.merged(computed) if computed is not None else stated
                if model is not None:  # as `xyz print` refuses it, in words for an API user
                    reach = meta
                    if computed is None:  # the comments told the figures: the moves are read for their extent
                        source.seek(0)
                        reach = intake.prepare(source, name, model, name, 0, None, force=True).metadata
                    beyond = intake.check_build_volume(reach, name, model, force=True)
                    if beyond is not None:  # (its last clause names the command line's --force)
                        raise InputError(f"{beyond.rpartition('; ')[0]}; slice it for this printer and send it "
                                         "again")
            return {"print_time_s": meta.print_time_s, "filament_mm": meta.filament_mm, "layers": meta.layers,
                    "slicer": meta.slicer}
        if kind is intake.Kind.THREEW and check:
            model = self._last[0].model if self._last is not None else None
            if model is not None:  # as `xyz print` refuses it: made for another model, or damaged
                printjob.check_3w_suits(path, name, model)
            else:
                printjob.check_intact(inspect_3w(path), name)
        return {}

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.printer: XYZPrinter | None = None
        self._last: tuple[Status, dict[str, Any], dict[str, Any]] | None = None
        self.prompt: str | None = None
        """The step a flow (load, clean, calibrate) waits on the owner to confirm."""
        self._answer: asyncio.Future[bool] | None = None
        """The previous poll's status and its two views: an idle printer answers the same each second, and
        converting it again would cost as much as the poll itself."""

    def _client(self) -> XYZPrinter:
        if self.printer is None:
            raise LinkClosed("the printer is not connected")
        return self.printer

    async def connect(self) -> Identity:
        self.printer = await open_xyz(self.spec.address, self.spec.options)
        status = await self.printer.status()
        model = status.model
        return Identity(model.name if model else status.model_number, status.serial, status.firmware_version)

    async def poll(self) -> tuple[dict[str, Any] | None, dict[str, Any]]:
        status = await self._client().status()
        last = self._last
        if last is None:
            last = (status, status.to_dict(), printer_summary(status))
        elif last[0] is not status and (changed := changed_fields(last[0], status)):
            # only what changed since the last poll is worked out again
            last = (status, status.to_dict(since=(last[0], last[1]), changed=changed),
                    printer_summary(status) if not changed.isdisjoint(SUMMARY_FIELDS) else last[2])
        self._last = last
        if self.prompt is not None:
            return last[1], {**last[2], "prompt": self.prompt, "actions": PROMPT_ACTIONS}
        return last[1], last[2]

    async def _ask(self, text: str) -> None:
        """The flows' prompt (as `fabwire xyz calibrate` asks on the terminal): shown in the summary until the
        `confirm` action; `stop_flow`, or no answer in PROMPT_LIMIT_S, stops the flow (InputError)."""
        self._answer = asyncio.get_running_loop().create_future()
        self.prompt = text
        self.emit({"event": "prompt", "text": text})
        try:
            async with asyncio.timeout(PROMPT_LIMIT_S):
                confirmed = await self._answer
        except TimeoutError:
            raise InputError(f"nobody confirmed '{text}' within {PROMPT_LIMIT_S / 60:.0f} min; the step was "
                             "stopped") from None
        finally:
            self.prompt = None
            self._answer = None
        if not confirmed:
            raise InputError(f"stopped at '{text}'")

    def _answered(self, confirmed: bool) -> None:
        if self._answer is None or self._answer.done():
            raise InputError("no step is waiting for an answer")
        self._answer.set_result(confirmed)

    async def close(self) -> None:
        printer, self.printer = self.printer, None
        if printer is not None:
            await printer.close()

    async def act(self, action: str, params: dict[str, Any]) -> dict[str, Any]:
        printer = self._client()
        if action == "pause":
            await printer.pause()
        elif action == "resume":
            await printer.resume()
        elif action == "cancel":
            await printer.cancel()
        elif action == "acknowledge":
            await printer.acknowledge()
        elif action == "home":
            await printer.home()
        elif action == "jog":
            await printer.jog(params["axis"], params["distance_mm"])
        elif action == "unload_filament":
            await printer.unload_filament()
        elif action == "load_filament":
            await printer.load_filament(self._ask)
        elif action == "clean_nozzle":
            await printer.clean_nozzle(self._ask)
        elif action == "calibrate":
            values = await printer.calibrate(self._ask)
            return {"ok": True, "action": action, "calibration": list(values)}
        elif action in ("confirm", "stop_flow"):
            self._answered(action == "confirm")
        elif action == "zoffset":
            value = await printer.set_zoffset(units.parse_zoffset(f"{params['mm']:.2f}mm"))
            return {"ok": True, "action": action, "zoffset_mm": value / 100}
        elif action == "zoffset_step":
            value = await printer.nudge_zoffset(params["direction"] == "up")
            return {"ok": True, "action": action, "zoffset_mm": value / 100}
        return {"ok": True, "action": action}

    async def run_job(self, path: Path | None, job_type: str, handle: JobHandle, params: dict[str, Any]) -> str:
        printer = self._client()
        if path is None:
            raise InputError("a print job needs a file")
        began = time.monotonic()

        def uploaded(done: int, total: int) -> None:
            handle.progress(0.0, message=f"uploading {done * 100 // max(total, 1)} %")

        def followed(status: Status) -> None:
            progress = status.progress
            percent = 100.0 if status.state_code == PRINT_DONE else float(progress.percent) if progress else 0.0
            left = progress.remaining_min * 60.0 if progress and progress.remaining_min is not None else None
            handle.progress(percent, time_left_s=left, message=status.state_name)

        final = await printer.print_file(path, progress=uploaded, on_status=followed)
        if final.state_code != PRINT_DONE:
            raise JobStopped(f"the printer became {final.state_name} before the print finished")
        return f"{final.state_name} after {time.monotonic() - began:.0f} s"

    async def stop_job(self) -> None:
        """Cancel the print on the printer; following it then sees the printer go idle."""
        await self._client().cancel()
