"""`fabwire mmu …` (talk to an MMU3 as a printer would) and `fabwire sim mmu` (be one)."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import shlex
import sys
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import update_wrapper
from typing import Any, TypeVar

import click

from fabwire.cli_support import (
    LINK_OPTIONS,
    DeviceContext,
    FiniteRange,
    confirm,
    device_group,
    on_terminal,
    pass_app,
    pass_device,
)
from fabwire.devices import MMU as MMU_KIND
from fabwire.errors import EXIT_INTERRUPTED, InputError, LinkClosed, LinkTimeout, RemoteProtocolError, excerpt
from fabwire.mmu import codes
from fabwire.mmu.client import MMU, check_slot, resolve_register
from fabwire.mmu.errors import ErrorInfo, MMUError, describe_error, format_error, reset_line
from fabwire.mmu.faults import FAULT_NAMES, FAULTS, HANDS, PHYSICAL_BUTTONS, parse_fault
from fabwire.mmu.host import (
    ButtonPushed,
    ButtonSent,
    CommandFinished,
    CommandInterrupted,
    CommandRejected,
    ErrorRaised,
    HostEvent,
    LinkFailed,
    LinkLost,
    LinkUp,
    ProgressChanged,
    RegisterRead,
    RegisterWritten,
    Status,
    StatusUpdated,
)
from fabwire.mmu.units import DEFAULT_FLOAT, FLOAT_FORMATS
from fabwire.simoptions import parse_listen, server_options
from fabwire.simserve import serve
from fabwire.transport.tcp import serve_tcp

F = TypeVar("F", bound=Callable[..., Any])


def _error_fields(info: ErrorInfo) -> dict[str, Any]:
    """An MMU error for JSON: `error` is its one text form, the rest its parts."""
    return {"error": str(info), "code": f"{info.code:04x}", "name": info.name, "printer_code": info.printer_code,
            "title": info.title, "text": info.meaning, "action": info.action}


def describe(event: HostEvent) -> tuple[dict[str, Any], str]:
    """An event as a JSON-able dict and as one line of words."""
    if isinstance(event, ProgressChanged):
        return ({"event": "progress", "command": event.command, "code": event.code, "name": event.name,
                 "text": event.words}, f"{event.command}: {event.words}")
    if isinstance(event, ErrorRaised):
        info = event.info
        tail = " (retrying automatically)" if event.auto_retry else ""
        return ({"event": "error", "command": event.command, **_error_fields(info), "auto_retry": event.auto_retry},
                info.explained(command=event.command) + tail)
    if isinstance(event, CommandFinished):
        words = "finished" if event.result == 0 else "cancelled"
        return ({"event": "finished", "command": event.command, "result": event.result}, f"{event.command}: {words}")
    if isinstance(event, StatusUpdated):
        return {"event": "status", **status_dict(event.status)}, f"status: {status_line(event.status)}"
    if isinstance(event, LinkUp):
        return {"event": "link-up", "version": str(event.version)}, f"link up: MMU firmware {event.version}"
    if isinstance(event, LinkLost):
        return ({"event": "link-lost", "reason": event.reason, "drop_outs": event.drop_outs},
                f"link lost ({event.reason}); restarting")
    if isinstance(event, LinkFailed):
        return ({"event": "link-failed", **_error_fields(event.info), "detail": event.detail},
                event.info.explained(detail=f"link failed ({event.detail})"))
    if isinstance(event, ButtonPushed):
        name = codes.BUTTON_WORDS.get(event.button, str(event.button))
        return ({"event": "button", "command": event.command, "button": event.button},
                f"{event.command}: {name} button pressed on the MMU")
    if isinstance(event, ButtonSent):
        return {"event": "button-sent", "button": event.button}, f"pressed {codes.BUTTON_WORDS[event.button]}"
    if isinstance(event, CommandRejected):
        return ({"event": "rejected", "command": event.command, "attempts": event.attempts},
                f"{event.command}: rejected by the MMU")
    if isinstance(event, CommandInterrupted):
        return ({"event": "interrupted", "command": event.command, "reported": event.reported},
                f"{event.command}: interrupted (MMU reported {event.reported})")
    if isinstance(event, RegisterRead):
        return {"event": "read", "address": event.address, "value": event.value}, f"R{event.address:x} = {event.value}"
    assert isinstance(event, RegisterWritten)
    return ({"event": "write", "address": event.address, "value": event.value, "accepted": event.accepted},
            f"W{event.address:x} {event.value} {'accepted' if event.accepted else 'refused'}")


def _slot_words(value: int | None, park: str) -> str:
    if value is None:
        return "unknown"
    if value == 0xFF:
        return "position unknown"  # homing, or not moved since a reboot with filament loaded
    return park if value == 5 else f"slot {value}"


def status_line(status: Status) -> str:
    return (f"{status.command} {status.words}, FINDA {'on' if status.finda else 'off'}, "
            f"selector {_slot_words(status.selector, 'parked')}, idler {_slot_words(status.idler, 'disengaged')}")


def status_dict(status: Status) -> dict[str, Any]:
    data = dataclasses.asdict(status)
    data["pulley_mm"] = data.pop("pulley")  # register 0x1A, in mm (the firmware's pulley position)
    data["text"] = status.words
    return data




@dataclass(frozen=True, slots=True)
class SensorStep:
    """A step of a command that waits for the printer's filament sensor: with no host reporting it (the person
    stopped following the command) the MMU stops there with `error`."""

    commands: str
    error: int
    past: int
    """The progress code that shows the step is done."""
    words: str
    remedy: str
    needs_sensor_on: bool
    """The step waits for the sensor to go off, so only a sensor reported on can keep it waiting."""
    since: tuple[int, int, int]
    """First firmware version with the wait."""
    source: str

    def ahead(self, command: str, seen: set[int], sensor_on: bool, version: tuple[int, int, int]) -> bool:
        return (command[:1] in self.commands and self.past not in seen and version >= self.since
                and (sensor_on or not self.needs_sensor_on))


SENSOR_STEPS = (
    SensorStep("TUEK", 0x8004, codes.Progress.RETRACTING_FROM_FINDA, "Unloading to FINDA", "pull the filament out "
               "of the extruder", True, (3, 0, 4), "MMU:src/logic/unload_to_finda.cpp UnloadToFinda::Step "
               "(WaitingForFSensor: the sensor must go off within 4 s)"),
    SensorStep("T", 0x8003, codes.Progress.FEEDING_TO_NOZZLE, "Feeding to FSensor", "push the filament into the "
               "extruder", False, (3, 0, 0), "MMU:src/logic/feed_to_bondtech.cpp FeedToBondtech::Step "
               "(PushingFilamentToFSensor: Failed once the pulley has pushed its whole move without the sensor)"),
)
"""In the order a command meets them."""


def command_line(dctx: DeviceContext) -> str:
    """`fabwire mmu` as this command was run: its device, --timeout and the MMU's link options (--speed,
    --accept), so that a command a message advises works as typed."""
    flags = {f.setting.removeprefix("shared_"): f().opts[0] for f in LINK_OPTIONS["mmu"]}  # type: ignore[attr-defined]
    words = ["fabwire", "mmu"]
    if dctx.device:
        words += ["-d", dctx.device]
    if dctx.app.timeout is not None:
        words += ["--timeout", f"{dctx.app.timeout:g}"]
    for setting, value in dctx.app.link_options.items():
        for item in value if isinstance(value, list) else [value]:
            words += [flags[setting], f"{item:g}" if isinstance(item, float) else str(item)]
    return shlex.join(words)


def with_mmu(check: Callable[[dict[str, Any]], None] | None = None,
             **open_options: Any) -> Callable[[Callable[..., Any]], Any]:
    """Open the link and the host logic around an `async def cmd(dctx, mmu, **options)`.

    `check` validates the arguments first, so bad input fails before any byte is sent; `open_options` (such as
    auto_retries=0 for commands that only look or answer) go to `MMU.open`.
    """

    def decorate(func: Callable[..., Awaitable[None]]) -> Callable[..., None]:
        @pass_device
        def wrapper(dctx: DeviceContext, /, *args: Any, **kwargs: Any) -> None:
            if check is not None:
                check(kwargs)

            running: list[str] = []
            seen: dict[str, set[int]] = {}
            stops: list[int] = []

            def watch(event: HostEvent) -> None:  # which of the sensor steps has the command got past?
                if isinstance(event, ProgressChanged):
                    seen.setdefault(event.command, set()).add(event.code)

            async def main() -> None:
                async with dctx.open(MMU, **open_options) as mmu:
                    mmu.commands = command_line(dctx)
                    mmu.subscribe(watch)
                    try:
                        await func(dctx, mmu, *args, **kwargs)
                    except asyncio.CancelledError:  # Ctrl-C: is the MMU in the middle of a command?
                        status = mmu.logic.status
                        if status.kind in ("P", "E") and status.command[:1] in "TLUEKH":
                            running.extend((status.command, status.words))
                            version = mmu.logic.version
                            stops.extend(s.error for s in SENSOR_STEPS if s.ahead(
                                status.command, seen.get(status.command, set()), bool(mmu.logic.fsensor),
                                version.triple if version else (3, 0, 4)))
                        raise

            try:
                asyncio.run(main())
            except KeyboardInterrupt:
                if not running:
                    raise
                command, doing = running
                line = command_line(dctx)
                dctx.output.note(f"stopped following {command} ({doing}); the MMU goes on with it. Follow it with "
                                 f"`{line} monitor`")
                if stops:
                    info = describe_error(stops[0])
                    step = next(s for s in SENSOR_STEPS if s.error == stops[0])
                    dctx.output.note(f"warning: nothing reports the printer's filament sensor to the MMU now; unless a "
                                     f"host does (`{line} monitor` does), {command} will stop at {info} "
                                     f"({step.words}): then {step.remedy} and answer with `{line} "
                                     f"button retry`, or {reset_line(line)}")
                raise click.exceptions.Exit(EXIT_INTERRUPTED) from None

        return update_wrapper(wrapper, func)

    return decorate


def _slot_arg(kwargs: dict[str, Any]) -> None:
    check_slot(kwargs["slot"])


def _register_arg(kwargs: dict[str, Any]) -> None:
    resolve_register(kwargs["register"])


def _write_args(kwargs: dict[str, Any]) -> None:
    resolve_register(kwargs["register"], for_write=True)
    _parse_value(kwargs["value"])


@device_group(MMU_KIND, "Prusa MMU3, driven as the printer does: tool changes, buttons, registers, monitor.",
              LINK_OPTIONS["mmu"])
def mmu() -> None:
    pass


async def _command(dctx: DeviceContext, mmu_: MMU, run: Callable[..., Awaitable[CommandFinished]],
                   max_time: float) -> None:
    seen: list[dict[str, Any]] = []
    shown: list[str] = []

    def show(event: HostEvent) -> None:
        if isinstance(event, ErrorRaised) and not event.auto_retry:
            return  # the error the command ends in: said once, with what answers it, by whoever handles it
        if isinstance(event, ProgressChanged | ErrorRaised | ButtonPushed | LinkLost):
            data, text = describe(event)
            seen.append(data)
            shown.append(text)
            dctx.output.note(text)

    try:
        finished = await run(on_event=show, timeout=max_time)
    except MMUError as error:
        if dctx.output.json_mode or not on_terminal():
            error.args = (f"{error}; answer it with {error.info.answers(command_line(dctx))}",)
            raise
        finished = await _answer_on_terminal(dctx, mmu_, error, show, max_time, shown)
    factor = mmu_.logic.timing.too_fast
    if factor is not None:
        dctx.output.note(f"warning: the MMU moved {factor:.0f}× faster than this host assumes: its timing does not "
                         f"fit (give --speed {factor:.0f}, or the device's speed)")
    words = "finished" if finished.result == 0 else "cancelled"
    dctx.output.result({"command": finished.command, "result": finished.result, "text": words, "events": seen},
                       f"{finished.command} {words}")


async def _answer_on_terminal(dctx: DeviceContext, mmu_: MMU, error: MMUError, show: Callable[[HostEvent], None],
                              max_time: float, shown: list[str]) -> CommandFinished:
    """Offer the printer dialog's choices for the error, until the command ends or the person stops. `shown` is
    what `show` printed, so an error already on the screen is not printed twice."""
    while True:
        info = error.info
        choices = [c.label for c in info.choices if isinstance(c.button, int)]
        if "Stop" not in choices:
            choices.append("Stop")
        if not shown or shown[-1] != str(error):
            dctx.output.note(f"{error}")
        choice = await asyncio.to_thread(click.prompt, " / ".join(choices), type=click.Choice(
            [c.lower() for c in choices], case_sensitive=False), err=True)
        if choice.lower() == "stop":  # asked for: said as what it is, not as an error
            dctx.output.note(f"stopped: {error.command or 'the MMU'} stays in {info}; answer it later with "
                             f"{info.answers(command_line(dctx))}")
            raise click.exceptions.Exit(error.exit_code)
        try:
            finished = await mmu_.answer(choice, on_event=show, timeout=max_time)
        except MMUError as again:
            error = again
            continue
        if finished is None:
            raise error
        return finished


def _command_options(func: F) -> F:
    return click.option("--max-time", type=FiniteRange(min=0.1), default=600.0, show_default=True,
                        help="Give up if the command has not ended after this many seconds.")(func)


class ToolArgument(click.ParamType[int]):
    """A tool as MMU people type it: `1`, `T1` or `t1` (the printer's G-code and the wire both say T1)."""

    name = "SLOT"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> int:
        if isinstance(value, int):
            return value
        text = str(value).strip()
        digits = text[1:] if text[:1] in ("T", "t") else text
        if not digits.isascii() or not digits.isdigit() or len(digits) > 3:
            self.fail(f"a tool is a slot number 0 to 4, or T0 to T4, not {excerpt(text, 20)}", param, ctx)
        return int(digits)


@mmu.command("tool-change")
@click.argument("slot", type=ToolArgument())
@_command_options
@with_mmu(_slot_arg)
async def tool_change(dctx: DeviceContext, mmu_: MMU, slot: int, max_time: float) -> None:
    """Change to filament SLOT (0-4, or T0-T4): unload what is loaded, feed SLOT to the nozzle."""
    await _command(dctx, mmu_, lambda **kw: mmu_.tool_change(slot, **kw), max_time)


@mmu.command("load")
@click.argument("slot", type=int)
@_command_options
@with_mmu(_slot_arg)
async def load(dctx: DeviceContext, mmu_: MMU, slot: int, max_time: float) -> None:
    """Load filament SLOT (0-4) into the MMU (to FINDA and back)."""
    await _command(dctx, mmu_, lambda **kw: mmu_.load(slot, **kw), max_time)


@mmu.command("unload")
@_command_options
@with_mmu()
async def unload(dctx: DeviceContext, mmu_: MMU, max_time: float) -> None:
    """Unload the filament from the printer back to the MMU."""
    await _command(dctx, mmu_, mmu_.unload, max_time)


@mmu.command("eject")
@click.argument("slot", type=int)
@click.option("--continue-after", type=FiniteRange(min=0.0), metavar="SECONDS",
              help="Press Continue this many seconds after the filament is out (default: ask on a terminal, "
                   "else leave the MMU waiting for `fabwire mmu button continue`).")
@_command_options
@with_mmu(_slot_arg)
async def eject(dctx: DeviceContext, mmu_: MMU, slot: int, max_time: float, continue_after: float | None) -> None:
    """Eject filament SLOT (0-4) out of the MMU; it waits for you to take the filament, then continues."""
    try:
        await mmu_.eject(slot, timeout=max_time, confirm_eject=False,
                         on_event=lambda e: dctx.output.note(describe(e)[1]) if isinstance(e, ProgressChanged)
                         else None)
        raise InputError(f"E{slot} ended without ejecting")  # the MMU always stops at 'filament ejected'
    except MMUError as error:
        if error.info.code != 0x800C:
            raise
    if continue_after is None and not on_terminal():
        dctx.output.result({"command": f"E{slot}", "waiting": True, "printer_code": "04507"},
                           f"E{slot}: filament ejected — take it out, then `{mmu_.commands} button continue`")
        return
    if continue_after is None:
        await asyncio.to_thread(click.prompt, "Take the filament out of the MMU, then press Enter", default="",
                                show_default=False, err=True)
    else:
        dctx.output.note(f"E{slot}: filament ejected — continuing in {continue_after:g} s")
        await asyncio.sleep(continue_after)
    finished = await mmu_.answer("continue", timeout=max_time)
    dctx.output.result({"command": f"E{slot}", "result": 0, "text": "finished"}, f"E{slot} finished"
                       if finished is not None else f"E{slot} continued")


@mmu.command("cut")
@click.argument("slot", type=int)
@_command_options
@with_mmu(_slot_arg)
async def cut(dctx: DeviceContext, mmu_: MMU, slot: int, max_time: float) -> None:
    """Cut the tip of filament SLOT (0-4)."""
    await _command(dctx, mmu_, lambda **kw: mmu_.cut(slot, **kw), max_time)


@mmu.command("home")
@_command_options
@with_mmu()
async def home(dctx: DeviceContext, mmu_: MMU, max_time: float) -> None:
    """Re-home the idler and the selector."""
    await _command(dctx, mmu_, mmu_.home, max_time)


@mmu.command("version")
@with_mmu(auto_retries=0)
async def version(dctx: DeviceContext, mmu_: MMU) -> None:
    """Show the MMU firmware version and build."""
    v = await mmu_.version()
    dctx.output.result({"major": v.major, "minor": v.minor, "revision": v.revision, "build": v.build,
                        "version": str(v)}, f"MMU firmware {v}")


def _error_register_words(value: int) -> str:
    """Register 0x06 (the command's error code) in words: 0x0000 RUNNING and 0x0001 OK are no errors (reference
    §4, ErrorCode)."""
    return {0x0000: "running", 0x0001: "OK"}.get(value) or format_error(value)


@mmu.command("status")
@with_mmu(auto_retries=0)
async def status(dctx: DeviceContext, mmu_: MMU) -> None:
    """Show FINDA, filament sensor, slot, selector/idler, drive errors and the current command."""
    st = await mmu_.status()
    firmware = await mmu_.version()
    fsensor = await mmu_.read_register(0x09)
    filament = await mmu_.read_register(0x07)
    progress = await mmu_.read_register(0x05)
    error = await mmu_.read_register(0x06)
    slot = st.selector if st.selector is not None and st.selector < 5 else None
    data = {**status_dict(st), "fsensor": bool(fsensor), "filament": filament,
            "filament_text": codes.FILAMENT_WORDS.get(filament, str(filament)), "slot": slot,
            "progress": progress, "progress_text": codes.progress_words(progress), "error_code": error,
            "error_text": _error_register_words(error),
            "version": str(firmware)}

    def human() -> None:
        out = dctx.output.out
        rows = [
            ("firmware", str(firmware)),
            ("command", f"{st.command} {st.words}"),
            ("progress", codes.progress_words(progress)),
            ("FINDA", "on" if st.finda else "off"),
            ("fsensor", "on" if fsensor else "off"),
            ("filament", codes.FILAMENT_WORDS.get(filament, str(filament))),
            ("active slot", "none" if slot is None else str(slot)),
            ("selector", _slot_words(st.selector, "parked")),
            ("idler", _slot_words(st.idler, "disengaged")),
            ("drive errors", str(st.drive_errors)),
            ("pulley", f"{st.pulley} mm"),
        ]
        if st.kind == "E":
            rows.append(("error", describe_error(st.value).explained(command=st.command)))
        for key, value in rows:
            out.print(f"{key:<13} {value}")

    dctx.output.result(data, human)


@mmu.command("button")
@click.argument("button", type=click.Choice(["retry", "continue", "stop", "left", "middle", "right"]))
@click.option("--max-time", type=FiniteRange(min=0.1), default=600.0, show_default=True,
              help="Give up following the command after this many seconds.")
@with_mmu(auto_retries=0)
async def button(dctx: DeviceContext, mmu_: MMU, button: str, max_time: float) -> None:
    """Answer the MMU's error as the printer's dialog does (retry, continue, stop) and follow the command to its
    end; left/middle/right press a button as it is."""
    if button in ("left", "middle", "right"):
        await mmu_.press(button)
        number = codes.BUTTON_ALIASES[button]
        dctx.output.result({"button": button, "sent": number}, f"pressed {codes.BUTTON_WORDS[number]}")
        return
    pending = await mmu_.status()
    finished = await mmu_.answer(button, timeout=max_time,
                                 on_event=lambda e: dctx.output.note(describe(e)[1])
                                 if isinstance(e, ProgressChanged | ErrorRaised) else None)
    if finished is None:
        dctx.output.result({"button": button, "command": pending.command, "result": None},
                           f"{button}: left {pending.command} in its error")
        return
    words = "finished" if finished.result == 0 else "cancelled"
    dctx.output.result({"button": button, "command": finished.command, "result": finished.result},
                       f"{button}: {finished.command} {words}")


def _confirm_reset(kwargs: dict[str, Any]) -> None:
    confirm("erase the MMU's EEPROM (loaded slot, drive-error count, bowden length, StallGuard thresholds) and "
            "reboot it" if kwargs["erase"] else "reboot the MMU", kwargs["yes"])


@mmu.command("reset")
@click.option("--erase", is_flag=True, help="Also erase the MMU's EEPROM (X2a).")
@click.option("--yes", is_flag=True, help="Reset without asking (needed when not on a terminal).")
@with_mmu(_confirm_reset, auto_retries=0)
async def reset(dctx: DeviceContext, mmu_: MMU, erase: bool, yes: bool) -> None:
    """Reboot the MMU (X0) and wait until it answers again (asks first on a terminal)."""
    v = await mmu_.reset(erase=erase)
    words = "EEPROM erased and MMU reset" if erase else "MMU reset"
    dctx.output.result({"version": str(v), "erased": erase}, f"{words}; firmware {v} answering")


@mmu.command("registers")
@with_mmu(auto_retries=0)
async def registers(dctx: DeviceContext, mmu_: MMU) -> None:
    """List every register with its address, name, value, size, access and meaning."""
    version = (await mmu_.version()).triple
    rows, lines = [], []
    for reg in codes.REGISTERS:
        value = await mmu_.read_register(reg.address)
        access = "read/write" if reg.writable(version) else "read-only"
        rows.append({"address": reg.address, "name": reg.name, "value": value, "meant": reg.meant(value),
                     "bits": reg.bits, "access": access, "meaning": reg.meaning})
        lines.append(f"0x{reg.address:02x} {reg.name:<30} {reg.shown(value):>6}  {reg.bits:>2}-bit {access:<10}  "
                     f"{reg.meaning}")

    def human() -> None:
        for line in lines:
            dctx.output.out.print(line, highlight=False)

    dctx.output.result(rows, human)


@mmu.command("read")
@click.argument("register")
@with_mmu(_register_arg, auto_retries=0)
async def read(dctx: DeviceContext, mmu_: MMU, register: str) -> None:
    """Read REGISTER (a name such as bowden_length, or an address like 0x22)."""
    reg = resolve_register(register)
    value = await mmu_.read_register(reg.address)
    dctx.output.result({"address": reg.address, "name": reg.name, "value": value, "meant": reg.meant(value)},
                       f"0x{reg.address:02x} {reg.name} = {reg.shown(value)}")


@mmu.command("write")
@click.argument("register")
@click.argument("value")
@with_mmu(_write_args, auto_retries=0)
async def write(dctx: DeviceContext, mmu_: MMU, register: str, value: str) -> None:
    """Write VALUE to REGISTER (by name or address)."""
    reg = resolve_register(register, for_write=True)
    number = _parse_value(value)
    reads = await mmu_.write_register(reg.address, number)
    kept = "" if reads == number else f" (reads back {reads} through the firmware's units)"
    dctx.output.result({"address": reg.address, "name": reg.name, "value": number, "reads": reads},
                       f"0x{reg.address:02x} {reg.name} := {number}{kept}")


def _parse_value(text: str) -> int:
    number = codes.parse_word(text)
    if number is None:
        raise InputError(f"register value must be a number from 0 to 65535 (decimal, or hex like 0x1f), "
                         f"not {excerpt(text, 40)}")
    if not 0 <= number <= 0xFFFF:
        raise InputError(f"register value must be 0 to 65535, not {number}")
    return number


@mmu.command("monitor")
@click.option("--count", type=click.IntRange(min=1), help="Stop after this many status polls (shown or not).")
@click.option("--duration", type=FiniteRange(min=0.0), help="Stop after this many seconds.")
@click.option("--all", "every", is_flag=True, help="Show every status poll, not only the ones that changed.")
@with_mmu(auto_retries=0)
async def monitor(dctx: DeviceContext, mmu_: MMU, count: int | None, duration: float | None, every: bool) -> None:
    """Show live events with timestamps (status changes, progress, errors, buttons, link) until Ctrl-C, --count
    polls or --duration seconds."""
    polls = 0
    last_status: Status | None = None
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(duration):
            async for event in mmu_.events():
                if isinstance(event, RegisterRead):
                    continue
                if isinstance(event, StatusUpdated):
                    polls += 1
                    changed = event.status != last_status
                    last_status = event.status
                    if not (changed or every):
                        if count is not None and polls >= count:
                            break
                        continue
                data, text = describe(event)
                stamp = time.time()
                clock = time.strftime("%H:%M:%S", time.localtime(stamp)) + f".{int(stamp % 1 * 1000):03d}"
                dctx.output.event({"time": datetime.fromtimestamp(stamp, UTC).isoformat(timespec="milliseconds"),
                                   **data}, f"{clock} {text}")
                if count is not None and polls >= count:
                    break


@mmu.command("hands")
@click.argument("control")
@click.argument("action", type=click.Choice(list(HANDS)))
@click.argument("argument", required=False, default="")
@click.option("--timeout", type=FiniteRange(min=0.1), default=5.0, show_default=True,
              help="Seconds to wait for the simulator's answer.")
@pass_app
def hands(app: Any, control: str, action: str, argument: str, timeout: float) -> None:
    """Act on a simulated MMU as its owner would: remove a cause (remove finda-stuck; remove alone removes
    every cause), press one of its buttons (press left|middle|right), power-cycle it, inject a cause, or list the
    causes present. CONTROL is the address `fabwire sim mmu --control HOST:PORT` printed; the simulator may
    serve its MMU on TCP or on a pty."""
    if action == "press" and argument.lower() not in PHYSICAL_BUTTONS:
        raise InputError(f"press which button? left, middle or right, not {excerpt(argument, 20)}")
    if action in ("remove", "inject") and argument:
        parse_fault(argument)
    address = parse_listen(control.removeprefix("tcp://"), 0)
    if address.port == 0:
        raise InputError(f"control address {excerpt(control, 60)} needs a port: HOST:PORT as the simulator printed")
    answer = asyncio.run(_hands(address.host, address.port, f"{action} {argument}".strip(), timeout))
    if not answer.pop("ok", False):
        raise InputError(str(answer.get("error", "the simulator refused")))
    app.output.result(answer, _hands_words(action, answer))


HANDS_REPLY_LIMIT = 64 * 1024
"""Longest answer line `fabwire mmu hands` reads (the simulator's are short JSON objects)."""


async def _hands(host: str, port: int, line: str, timeout: float) -> dict[str, Any]:
    try:
        async with asyncio.timeout(timeout):
            reader, writer = await asyncio.open_connection(host, port, limit=HANDS_REPLY_LIMIT)
            try:
                writer.write(line.encode() + b"\n")
                await writer.drain()
                reply = await reader.readline()
            finally:
                writer.close()
    except ValueError:  # no newline within the limit: not an MMU simulator's control plane
        raise RemoteProtocolError(f"{host}:{port} is not an MMU simulator's control plane: it answered more "
                                  f"than {HANDS_REPLY_LIMIT} bytes without a line end") from None
    except TimeoutError:
        raise LinkTimeout(f"the simulator's control plane at {host}:{port} did not answer within {timeout:g} s") \
            from None
    except OSError as exc:
        raise LinkClosed(f"no simulator control plane at {host}:{port} ({exc.strerror or exc}): give the address "
                         "`fabwire sim mmu --control` printed") from None
    try:
        answer = json.loads(reply)
    except ValueError:
        raise RemoteProtocolError(f"{host}:{port} is not an MMU simulator's control plane: it answered "
                                  f"{excerpt(reply.decode('utf-8', 'replace'), 40)!r}") from None
    if not isinstance(answer, dict):
        raise RemoteProtocolError(f"{host}:{port} answered {excerpt(str(answer), 40)}, not an object")
    return answer


def _hands_words(action: str, answer: dict[str, Any]) -> str:
    causes = answer.get("causes", {})
    present = ", ".join(n if left < 0 else f"{n} ({left} more checks)" for n, left in causes.items()) or "none"
    if action == "remove":
        return f"removed {', '.join(answer['removed'])}; causes present: {present}"
    if action == "press":
        return f"pressed {answer['pressed']} on the MMU"
    if action == "power-cycle":
        return f"MMU power-cycled; causes present: {present}"
    if action == "inject":
        return f"{answer['injected']} is there now; causes present: {present}"
    return f"causes present: {present}"


@click.command("mmu")
@server_options(None)
@click.option("--speed", type=FiniteRange(min=0.01), default=1.0, show_default=True,
              help="Run the machine this many times faster than real time.")
@click.option("--fault", "faults", multiple=True, metavar="NAME[:N]",
              help="A cause present from power-on (repeatable); NAME stays until removed (`fabwire mmu hands`), "
                   "NAME:N fails N checks: " + ", ".join(sorted(n for n in FAULT_NAMES if
                                                                 not n.startswith("tmc-"))) +
                   ", tmc-KIND[-AXIS].")
@click.option("--version", "fw_version", type=click.Choice(sorted(codes.FIRMWARES)), default="3.0.4",
              show_default=True, help="Firmware version: the MK3 printer firmware accepts only 3.0.2, the Buddy "
                                      "firmware (MK4, MK3.5, XL) only 3.0.3, current Core One firmware 3.0.4.")
@click.option("--control", metavar="HOST:PORT",
              help="Also serve the control plane (`fabwire mmu hands`) on this TCP address (port 0: any free).")
@click.option("--arithmetic", type=click.Choice(list(FLOAT_FORMATS)), default=DEFAULT_FLOAT, show_default=True,
              help="Floating point of the firmware's unit conversions: pc (the firmware built for a PC) or avr "
                   "(the MMU board's 32-bit floats); they differ on some register values.")
@click.option("--phantom-requests", is_flag=True,
              help="A one-byte garbage line right after a request repeats that request, as the firmware's response "
                   "decoder repeats a response (to test hosts; a real MMU does not).")
@pass_app
def sim_mmu(app: Any, listen: tuple[str, ...], use_pty: bool, link: Any, speed: float, faults: tuple[str, ...],
            fw_version: str, control: str | None, arithmetic: str, phantom_requests: bool) -> None:
    """Simulate an MMU3 (no default TCP port: give --listen HOST:PORT or --pty)."""
    from fabwire.mmu.sim import MMUSimulator

    parsed = [parse_fault(fault) for fault in faults]
    for fault in parsed:  # when it shows: a cause from power-on meets the firmware only where its check runs
        kind = FAULTS.get(fault.name)
        told = f"{kind.where} → {format_error(kind.word)}" if kind else FAULT_NAMES[fault.name]
        click.echo(f"fault {fault.name}: {told}", err=True)
    hands_at = parse_listen(control, 0) if control is not None else None
    simulator = MMUSimulator(fw_version, speed=speed, faults=faults, arithmetic=arithmetic,
                             phantom_requests=phantom_requests)

    async def main() -> None:
        server = None
        if hands_at is not None:
            server = await serve_tcp(simulator.serve_hands, hands_at.host, hands_at.port, what="MMU control plane")
            host, port = server.sockets[0].getsockname()[:2]
            shown = f"[{host}]" if ":" in host else host
            where = f"tcp://{shown}:{port}"
            if app.json:
                sys.stdout.write(json.dumps({"simulator": "mmu", "control": where}) + "\n")
            else:
                sys.stdout.write(f"mmu simulator control on {where}\n")
            sys.stdout.flush()
        try:
            await serve("mmu", simulator.serve, listen=listen, use_pty=use_pty, link=link, default_port=None,
                        json_mode=app.json)
        finally:
            if server is not None:
                server.close()

    asyncio.run(main())
