"""The maintenance side of a da Vinci client: homing and jogging, filament load and unload, nozzle cleaning, bed
calibration, and every setting (auto-level, buzzer, Z offset, name, language, energy saving, Wi-Fi), each flow
driven by polling the printer's state, which works the same on serial and Wi-Fi links."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import TYPE_CHECKING, Any

from fabwire.errors import DeviceError, FabwireError, LinkTimeout, RemoteProtocolError, excerpt
from fabwire.xyz import protocol as p
from fabwire.xyz import userinput
from fabwire.xyz.protocol import Reply
from fabwire.xyz.status import Status

StatusCallback = Callable[[Status], None]
Prompt = Callable[[str], Awaitable[None]]
STATUS_AND_UPLOAD_ONLY = frozenset({"dvF110B000"})
"""Models whose XYZv3 covers status and printing only (the 1.1 Plus speaks the older protocol for the rest)."""
_PRINTING_COMMANDS = (p.Query, p.Upload, p.UploadDidFinish, p.PrintControl, p.SimControl)
CALIBRATION_POINTS = 9
"""`calibratejr:getdata` reports 9 bed readings (reference, calibrate bed; cf. `c:`)."""
CONFIRM_LIMIT = 5.0
"""Seconds a Wi-Fi printer has to show a setting in its status (it does not answer settings there)."""
_READBACK: dict[type[p.Command], tuple[str, Callable[[Any, Status], bool]]] = {
    p.SetAutoLevel: ("o", lambda c, st: st.autolevel == c.on),
    p.SetBuzzer: ("s", lambda c, st: st.buzzer == c.on),
    p.SetZOffset: ("z", lambda c, st: st.zoffset == c.value),
    p.SetName: ("n", lambda c, st: st.name is not None and st.name.strip() == c.name.strip()),
    p.SetLanguage: ("l", lambda c, st: st.language == c.code),
}
"""Settings a Wi-Fi printer confirms only through its status: the letter that carries each, and when it shows it."""


def _shown(status: Status, letter: str) -> str:
    line = status.line(letter) if letter in status.order else None
    return "(nothing)" if line is None else line[2:42]


class Maintenance:
    """Flows and settings, on top of the client's requests and status queries."""

    poll_interval: float
    link: p.Link
    reconnects: int
    clock: Callable[[], float]
    last_status: Status
    timeout: float

    if TYPE_CHECKING:  # provided by XYZPrinter
        async def status(self, letters: str = "a") -> Status: ...
        async def request(self, command: p.Command, *, timeout: float | None = None) -> Reply: ...
        async def require_idle(self, doing: str, command: p.Command | None = None) -> Status: ...

    # --------------------------------------------------------------------------------------------- flows

    async def _wait_state(self, done: Callable[[Status], bool], doing: str, limit: float,
                          on_status: StatusCallback | None = None) -> Status:
        end = self.clock() + limit
        while True:
            try:
                status = await self.status()
            except LinkTimeout:
                status = self.last_status  # some firmware goes quiet mid-action; ask again
            if on_status:
                on_status(status)
            for word in status.error_words:
                raise DeviceError(f"0x{word.raw:08X}", word.meaning, action=f"while {doing}")
            if done(status):
                return status
            if self.clock() > end:
                raise LinkTimeout(f"the printer did not finish {doing} within {limit:g} s ({status.state_name})")
            await asyncio.sleep(self.poll_interval)

    async def home(self, *, limit: float = 120.0) -> Status:
        await self.require_idle("home", p.Home())
        await self.request(p.Home())
        return await self._wait_state(lambda s: s.idle, "homing", limit)

    async def jog(self, axis: str, distance: float, *, limit: float = 120.0) -> Status:
        command = p.Jog(axis.lower(), distance)
        await self.require_idle("jog", command)
        await self.request(command)
        return await self._wait_state(lambda s: s.idle, "jogging", limit)

    async def _flow(self, flow: str, op: str) -> Reply:
        reply = await self.request(p.Flow(flow, op))
        for line in reply.lines:
            stat = p.parse_stat_line(line)
            if stat is not None and stat.stat == "fail":
                status = await self.status()
                words = status.error_words
                meaning = words[0].meaning if words else f"the printer reports {flow} failed"
                raise DeviceError(f"0x{words[0].raw:08X}" if words else flow, meaning, action=f"{flow} failed")
        return reply

    async def load_filament(self, ready: Prompt, *, on_status: StatusCallback | None = None,
                            retry: bool = False, limit: float = 360.0) -> Status:
        """Heat, feed, then `ready(...)` returns once filament comes out of the nozzle; we then stop feeding."""
        await self.require_idle("load filament", p.Flow("load", "new"))
        await self._flow("load", "retry" if retry else "new")
        async with self._cancelled_if_stopped("load"):
            status = await self._wait_state(lambda s: s.state == (9530, 12) or s.idle, "loading filament", limit,
                                            on_status)
        if status.idle:
            return status  # the printer finished feeding on its own before anyone confirmed
        try:
            await ready("Filament is feeding: confirm when it comes out of the nozzle")
        finally:
            await self._flow("load", "cancel")
        return await self._wait_state(lambda s: s.idle, "finishing the load", 30.0, on_status)

    @contextlib.asynccontextmanager
    async def _cancelled_if_stopped(self, flow: str) -> AsyncIterator[None]:
        """While the printer heats for a flow: an error, a timeout or Ctrl-C cancels the flow on the printer before
        it goes on, so a stopped command never leaves the nozzle heating (`<flow>:cancel`, MM:v3)."""
        try:
            yield
        except BaseException:
            with contextlib.suppress(FabwireError):
                await self.request(p.Flow(flow, "cancel"))
            raise

    async def cancel_flow(self, flow: str) -> None:
        """Stop a running load, unload or nozzle clean."""
        await self.request(p.Flow(flow, "cancel"))

    async def unload_filament(self, *, on_status: StatusCallback | None = None, retry: bool = False,
                              limit: float = 360.0) -> Status:
        await self.require_idle("unload filament", p.Flow("unload", "new"))
        await self._flow("unload", "retry" if retry else "new")
        async with self._cancelled_if_stopped("unload"):
            await self._wait_state(lambda s: s.state == (9531, 22) or s.idle, "heating to unload", limit, on_status)
            return await self._wait_state(lambda s: s.idle, "unloading filament", limit, on_status)

    async def clean_nozzle(self, ready: Prompt, *, on_status: StatusCallback | None = None,
                           limit: float = 360.0) -> Status:
        await self.require_idle("clean the nozzle", p.Flow("cleannozzle", "new"))
        await self._flow("cleannozzle", "new")
        async with self._cancelled_if_stopped("cleannozzle"):
            await self._wait_state(lambda s: s.state == (9536, 52) or s.idle, "heating the nozzle", limit,
                                   on_status)
        try:
            await ready("The nozzle is hot: clean it, then confirm")
        finally:
            await self._flow("cleannozzle", "cancel")
        return await self._wait_state(lambda s: s.idle, "finishing the nozzle clean", 30.0, on_status)

    async def calibrate(self, prompt: Prompt, *, on_status: StatusCallback | None = None,
                        on_stop: Callable[[str], None] | None = None, limit: float = 240.0) -> tuple[int, ...]:
        """Bed calibration with the detector; `prompt` asks the user to lower, then raise it.

        Returns the 9 bed readings. The flow has no cancel op: a host ends it with `calibratejr:release` at any
        step (XYZware sends it before the detector is raised; the printer goes to 9511), so an unconfirmed or
        interrupted calibration is released that way before the error (InputError, DeviceError, cancellation)
        goes on. Source: miniMover/XYZware calibratejr sequence, state 9535,40-44."""
        await self.require_idle("calibrate", p.Flow("calibratejr", "new"))
        await self._flow("calibratejr", "new")
        try:
            await self._wait_state(lambda s: s.state == (9535, 41), "starting calibration", limit, on_status)
            await prompt("Lower the calibration detector, then confirm")
            await self._flow("calibratejr", "detectorok")
            await self._wait_state(lambda s: s.state == (9535, 44), "measuring the bed", limit, on_status)
            reply = await self.request(p.Flow("calibratejr", "getdata"))
            stat = p.parse_stat_line(reply.lines[0]) if reply.lines else None
            values = stat.values if stat else ()
            if len(values) != CALIBRATION_POINTS:
                raise RemoteProtocolError(f"the printer answered 'calibratejr:getdata' with "
                                          f"{excerpt((reply.lines or ['nothing'])[0], 60)}, not {CALIBRATION_POINTS} "
                                          "bed readings")
            await prompt("Raise the calibration detector, then confirm")
        except BaseException:
            released = await self._release_calibration()
            if released and on_stop is not None:
                on_stop("calibration stopped: the detector flow was released and the printer is idle again")
            raise
        await self._flow("calibratejr", "release")
        await self._wait_state(lambda s: s.idle, "finishing calibration", 30.0, on_status)
        return values

    async def _release_calibration(self) -> bool:
        """End a calibration flow early (`calibratejr:release`, back to 9511); False if the printer did not."""
        try:
            await self.request(p.Flow("calibratejr", "release"))
            return (await self._wait_state(lambda s: s.idle, "stopping calibration", 30.0)).idle
        except FabwireError:
            return False

    # -------------------------------------------------------------------------------------------- config

    async def _supports(self, command: p.Command) -> None:
        """Refuse, in words, what this model cannot do over XYZv3 (Wi-Fi printers would just stay silent)."""
        if isinstance(command, _PRINTING_COMMANDS):
            return
        status = self.last_status if self.last_status.model_number else await self.status()
        if status.model_number in STATUS_AND_UPLOAD_ONLY:
            model = status.model
            raise DeviceError("unsupported", f"the {model.name if model else status.model_number} takes only status "
                              "queries and prints over XYZv3", action=f"cannot send {command.body!r}")

    async def _config(self, command: p.Command) -> bool:
        """Send a setting; True once the printer confirmed it, False if it cannot (Wi-Fi, no status field).

        On serial the `ok` is the confirmation. A Wi-Fi printer answers settings with nothing, so where the status
        carries the value it is read back until it shows the new one; a printer that ignored the command is a
        DeviceError, never success."""
        await self._supports(command)
        readback = _READBACK.get(type(command))
        if command.expects(self.link) is not p.Expect.NOTHING or readback is None:
            await self.request(command)
            return command.expects(self.link) is not p.Expect.NOTHING
        letter, applied = readback
        await self._send_confirmed(command, letter, lambda st: applied(command, st))
        return True

    async def _send_confirmed(self, command: p.Command, letter: str, applied: Callable[[Status], bool], *,
                              repeatable: bool = True) -> Status:
        """Send `command` and wait for its effect in status `letter`. A link opened again after the command went
        out may have lost it: a `repeatable` setting is then sent again at once if the status lacks it; a step
        (not repeatable) only after the status showed it missing for CONFIRM_LIMIT s, so it is never taken twice."""
        reconnects = self.reconnects
        await self.request(command)
        if repeatable:
            status = await self.status(letter)
            if applied(status):
                return status
            if self.reconnects != reconnects:
                await self.request(command)
            return await self._confirm(command, letter, applied)
        try:
            return await self._confirm(command, letter, applied)
        except DeviceError:
            if self.reconnects == reconnects:
                raise
        await self.request(command)
        return await self._confirm(command, letter, applied)

    async def _confirm(self, command: p.Command, letter: str, applied: Callable[[Status], bool]) -> Status:
        """Poll status `letter` until `applied` holds (firmware applies some settings a moment late, SEED)."""
        end = self.clock() + CONFIRM_LIMIT
        while True:
            status = await self.status(letter)
            if applied(status):
                return status
            if self.clock() > end:
                raise DeviceError("not applied", f"the printer did not apply {command.body!r}: its status still "
                                  f"reads {letter}:{_shown(status, letter)} after {CONFIRM_LIMIT:g} s",
                                  action="nothing was changed")
            await asyncio.sleep(self.poll_interval)

    async def set_autolevel(self, on: bool) -> bool:
        return await self._config(p.SetAutoLevel(on))

    async def set_buzzer(self, on: bool) -> bool:
        return await self._config(p.SetBuzzer(on))

    async def zoffset(self) -> int:
        await self._supports(p.GetZOffset())
        reply = await self.request(p.GetZOffset())
        if not reply.lines:
            raise LinkTimeout("the printer sent no z offset")
        try:
            return int(reply.lines[0])
        except ValueError:
            raise RemoteProtocolError(f"the printer answered 'zoffset:get' with {excerpt(reply.lines[0], 40)}, not a "
                                      "number") from None

    async def set_zoffset(self, value: int) -> int:
        await self._config(p.SetZOffset(value))
        return value

    async def nudge_zoffset(self, up: bool) -> int:
        """One 0.01 mm step; returns the new offset once the status reports it (a DeviceError if it never does)."""
        command = p.NudgeZOffset(up)
        await self._supports(command)
        before = (await self.status("z")).zoffset
        if before is None:
            raise RemoteProtocolError("the printer reports no z offset (z:), so a step cannot be confirmed")
        after = await self._send_confirmed(command, "z", lambda st: st.zoffset == before + (1 if up else -1),
                                           repeatable=False)
        assert after.zoffset is not None  # checked by the predicate
        return after.zoffset

    async def set_name(self, name: str) -> bool:
        return await self._config(p.SetName(userinput.printer_name(name)))

    async def set_language(self, code: str) -> bool:
        return await self._config(p.SetLanguage(userinput.language(code)))

    async def set_energy(self, minutes: int) -> bool:
        """False: sent to a Wi-Fi printer, which neither answers nor reports energy saving in its status."""
        return await self._config(p.SetEnergy(userinput.energy_minutes(minutes)))

    async def restore_defaults(self) -> bool:
        """False: sent to a Wi-Fi printer, which does not confirm it."""
        return await self._config(p.RestoreDefaults())

    async def wifi_info(self) -> Status:
        return await self.status("4")

    async def scan_wifi(self) -> list[dict[str, Any]]:
        """The networks the printer can see (`query=W`; it takes a few seconds, as XYZware allows)."""
        reply = await self.request(p.Query("W"), timeout=max(self.timeout, 5.0))
        self.last_status = self.last_status.update(reply.lines)
        return self.last_status.wifi_networks

    async def tag_info(self) -> str:
        """Firmware 3.x `config=taginfo`: the text between the braces of `taginfo:{…}`."""
        reply = await self.request(p.TagInfo())
        line = reply.lines[0] if reply.lines else ""
        return line.removeprefix("taginfo:").strip("{}")

    async def _raw(self, command: p.Signature | p.Uid) -> bytes:
        reply = await self.request(command)
        value = p.raw_reply_value(command, reply.lines[0]) if reply.lines else None
        if value is None:
            raise RemoteProtocolError(f"the printer answered {command.body!r} with {reply.lines[:1]!r}")
        return value

    async def signature(self) -> bytes:
        """Firmware 3.x `config=signature:[get]`: 32 raw bytes (their use is not documented)."""
        return await self._raw(p.Signature())

    async def uid(self) -> bytes:
        """Firmware 3.x `config=uid`: 4 raw bytes."""
        return await self._raw(p.Uid())

    async def sim_control(self, op: str) -> tuple[str, ...]:
        """Drive a fabwire simulator's faults in-band (`fault:<name>:on|off`, `clear`, `faults`); a real printer
        refuses it. Returns the faults now active."""
        reply = await self.request(p.SimControl(op))
        line = reply.lines[0] if reply.lines else ""
        value = line.removeprefix("simctl:")
        if not line.startswith("simctl:") or value.startswith("E"):
            raise DeviceError("simctl", value[1:].strip() if value.startswith("E") else "not a fabwire simulator")
        return tuple(f for f in value.split("+") if f)

    async def join_wifi(self, ssid: str, password: str, channel: int = 0) -> None:
        command = p.JoinWifi(userinput.ssid(ssid), userinput.wifi_password(password), channel)
        await self._supports(command)
        await self._config(p.LeaveWifi())
        await self.request(command, timeout=25.0)

    async def leave_wifi(self) -> None:
        await self._config(p.LeaveWifi())
