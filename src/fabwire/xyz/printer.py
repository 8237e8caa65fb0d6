"""The simulated da Vinci: personality per model, persistent settings and the physical state machine.

Pure logic driven by `now` in printer seconds (the simulator scales wall time by its speed factor), so every
flow can be stepped in tests without sleeping. Action progress lines that a serial printer volunteers are
queued in `outbox`; the link decides whether to send them.
"""

from __future__ import annotations

import hashlib
import random
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fabwire.errors import InputError, excerpt
from fabwire.xyz import intake
from fabwire.xyz import protocol as p
from fabwire.xyz.models import FileFormat
from fabwire.xyz.personas import Personality
from fabwire.xyz.simstate import Settings
from fabwire.xyz.status import (
    CANCELLING,
    DOOR_OPEN,
    FILE_CHECK,
    FILE_REJECTED,
    HEATER_TIMEOUT,
    IDLE,
    LETTERS,
    NO_CARTRIDGE,
    PAUSED,
    PRINT_DONE,
    PRINTING,
    Cartridge,
    Lifetime,
    Network,
    Packet,
    Progress,
    Status,
    Temperatures,
)

AMBIENT = 22.0
HEAT_RATE = 6.0  # °C per printer second
COOL_RATE = 1.5
FLOW_TEMP = 200
PRINT_TEMP = 210
FAULTS = ("no-cartridge", "door-open", "file-rejected", "heater-failure", "link-drop", "stuck")


@dataclass
class Job:
    name: str
    data: bytes
    print_time: float
    filament_mm: float
    phase: str = "check"  # check → heat → print → done
    filament_start: int = 0
    used: float = 0.0
    started: float = 0.0
    printed: float = 0.0
    rejected: bool = False


@dataclass
class FileVerdict:
    ok: bool
    print_time: float = 60.0
    filament_mm: float = 0.0
    reason: str = ""


class Printer:
    """One machine shared by every connection to it."""

    def __init__(self, persona: Personality, *, state_file: Path | None = None, faults: tuple[str, ...] = (),
                 seed: int = 0) -> None:
        for fault in faults:
            if fault not in FAULTS:
                raise InputError(f"unknown fault {excerpt(fault, 30)}; known: {', '.join(FAULTS)}")
        self.persona = persona
        self.state_file = state_file
        defaults = Settings(name=persona.name, zoffset=persona.zoffset, ip=persona.ip,
                            machine_min=persona.lifetime[0], extruder_min=persona.lifetime[1])
        if not persona.model.wifi:
            defaults.ssid, defaults.ip = "", "0.0.0.0"
        self.settings = Settings.load(state_file, defaults)
        self.faults: set[str] = set(faults)
        self.rng = random.Random(seed)
        self.now = 0.0
        self.state = (IDLE, 0)
        self.extruder = AMBIENT
        self.target = 0
        self.errors: list[int] = []
        self.flow: str | None = None
        self.flow_since = 0.0
        self.job: Job | None = None
        self.last_job: Job | None = None
        self.job_ended_at: float | None = None
        self.outbox: list[str] = []
        self.stored: dict[str, bytes] = {}
        self.firmware_images: list[bytes] = []
        self._zoffset_shown = self.settings.zoffset
        self._apply_static_faults()

    # ------------------------------------------------------------------------------------------ control

    def inject(self, fault: str, on: bool = True) -> None:
        if fault not in FAULTS:
            raise InputError(f"unknown fault {excerpt(fault, 30)}; known: {', '.join(FAULTS)}")
        (self.faults.add if on else self.faults.discard)(fault)
        self.errors = [e for e in self.errors if e not in (NO_CARTRIDGE, DOOR_OPEN)]
        self._apply_static_faults()

    def _apply_static_faults(self) -> None:
        if "no-cartridge" in self.faults and NO_CARTRIDGE not in self.errors:
            self.errors.append(NO_CARTRIDGE)
        if "door-open" in self.faults and DOOR_OPEN not in self.errors:
            self.errors.append(DOOR_OPEN)

    def _save(self) -> None:
        self.settings.save(self.state_file)

    @property
    def busy(self) -> bool:
        return self.state[0] != IDLE

    def _stat(self, name: str, stat: str, *values: int, **extra: str) -> None:
        self.outbox.append(p.stat_line(name, stat, *values, **extra))

    def _set(self, code: int, sub: int = 0) -> None:
        self.state = (code, sub)

    def _idle(self) -> None:
        self._set(IDLE)
        self.target = 0
        self.flow = None

    # ----------------------------------------------------------------------------------------- physics

    def advance(self, now: float) -> None:
        """Move the machine forward to `now` (printer seconds), in small steps so flows see the ramp."""
        if self._settled():
            self.now = max(self.now, now)
            return
        coarse = max(0.5, (now - self.now) / 400)  # bound the work for a long gap at a high speed factor
        while self.now < now:
            step = min(coarse, now - self.now)
            self._step(step)
            self.now += step
            self._tick()

    def _settled(self) -> bool:
        """Nothing changes with time: idle, no flow or job, nozzle cold."""
        return self.flow is None and self.job is None and not self.target and self.extruder <= AMBIENT

    def _step(self, dt: float) -> None:
        goal = float(self.target) if self.target else AMBIENT
        if "heater-failure" in self.faults and self.target:
            goal = min(goal, 60.0)
        if self.extruder < goal:
            self.extruder = min(goal, self.extruder + HEAT_RATE * dt)
        else:
            self.extruder = max(goal, self.extruder - COOL_RATE * dt)
        if self.job and self.job.phase == "print" and self.state[0] == PRINTING:
            self.job.printed += dt
            self.job.used += self.job.filament_mm * dt / max(self.job.print_time, 1.0)
            self.settings.filament_mm = max(0, round(self.job.filament_start - min(self.job.used,
                                                                                   self.job.filament_mm)))

    def _hot(self) -> bool:
        return self.extruder >= self.target - 5

    def _elapsed(self) -> float:
        return self.now - self.flow_since

    def _heater_failed(self) -> bool:
        if "heater-failure" in self.faults and self.target and self._elapsed() > 60:
            if HEATER_TIMEOUT not in self.errors:
                self.errors.append(HEATER_TIMEOUT)
            return True
        return False

    def _tick(self) -> None:
        if "stuck" in self.faults:
            return
        code, sub = self.state
        flow = self.flow
        if flow == "home" and self._elapsed() >= 3:
            self._stat("home", "complete")
            self._idle()
        elif flow == "jog" and self._elapsed() >= self._jog_time:
            self._stat("jog", "complete")
            self._idle()
        elif flow == "load":
            if self._heater_failed():
                self._stat("load", "fail")
                self._idle()
            elif sub == 11 and self._hot():
                self._set(9530, 12)
                self.flow_since = self.now
                self._stat("load", "load")
            elif sub == 12 and self._elapsed() >= 90:
                self._stat("load", "complete")
                self._idle()
        elif flow == "unload":
            if self._heater_failed():
                self._stat("unload", "fail")
                self._idle()
            elif sub == 21 and self._hot():
                self._set(9531, 22)
                self.flow_since = self.now
                self.target = 100
                self._stat("unload", "unload")
            elif sub == 22 and self._elapsed() >= 20:
                self._stat("unload", "complete")
                self._idle()
        elif flow == "clean":
            if self._heater_failed():
                self._stat("cleannozzle", "fail")
                self._idle()
            elif sub == 51 and self._hot():
                self._set(9536, 52)
                self.flow_since = self.now
                self._stat("cleannozzle", "complete")
            elif sub == 52 and self._elapsed() >= 120:
                self._idle()
        elif flow == "calibrate":
            if sub == 40 and self._elapsed() >= 1:
                self._set(9535, 41)
                self._stat("calibratejr", "pressdetector")
            elif sub == 43 and self._elapsed() >= 8:
                self._set(9535, 44)
                values = [self.rng.randint(330, 460) for _ in range(9)]
                self.settings.calibration = values
                self._save()
                self._stat("calibratejr", "ok", *values)
        elif self.job is not None:
            self._tick_job(code)

    def _tick_job(self, code: int) -> None:
        job = self.job
        assert job is not None
        if job.phase == "check" and self._elapsed() >= 2:
            if job.rejected:
                job.phase = "done"
                self.errors.append(FILE_REJECTED)
                self._set(PRINT_DONE)
                self.flow_since = self.now
            else:
                job.phase = "heat"
                self.target = PRINT_TEMP
                self._set(PRINTING)
        elif job.phase == "heat" and code == PRINTING:
            if self._heater_failed():
                self._finish_job(PRINT_DONE)
            elif self._hot():
                job.phase = "print"
                job.started = self.now
        elif job.phase == "print" and job.printed >= job.print_time:
            self.settings.extruder_min += max(1, int(job.print_time // 60))
            self._finish_job(PRINT_DONE)
        elif code == CANCELLING and self._elapsed() >= 2:
            self._finish_job(IDLE)
        # A finished print (9509) waits for `print[complete]`: the bed must be cleared first.

    def busy_reply(self) -> int | None:
        """Firmware 3.x answers `E7$`, then `E4$`, to queries for a moment while a print winds down."""
        if not self.persona.fw3 or self.job_ended_at is None:
            return None
        since = self.now - self.job_ended_at
        return 7 if since < 3.0 else 4 if since < 6.0 else None

    def _finish_job(self, code: int) -> None:
        if self.job is not None and self.job.phase != "done":
            self.job_ended_at = self.now
        if self.job is not None:
            self.job.phase = "done"
        self.last_job = self.job
        self.target = 0
        self._set(code)
        self.flow_since = self.now
        self._save()
        if code == IDLE:
            self.job = None
            self.flow = None
            self.errors = [e for e in self.errors if e != FILE_REJECTED]

    # ---------------------------------------------------------------------------------------- commands

    def _begin(self, flow: str, code: int, sub: int, target: int = 0) -> None:
        self.flow = flow
        self.flow_since = self.now
        self._set(code, sub)
        self.target = target

    _jog_time = 0.5

    def refusal(self, command: p.Command) -> int | None:
        """An `E<n>$` code when the printer cannot take `command` now (busy, or not a command it knows)."""
        if isinstance(command, p.TagInfo | p.Signature | p.Uid) and not self.persona.fw3:
            return 1  # firmware 3.x commands
        allowed = p.Query | p.Upload | p.UploadDidFinish | p.PrintControl | p.SimControl
        if self.persona.status_and_upload_only and not isinstance(command, allowed):
            return 1
        if isinstance(command, p.Home | p.Jog) and self.busy:
            return 3
        if isinstance(command, p.Flow) and command.op == "new" and self.busy:
            return 3
        if isinstance(command, p.Upload) and (self.busy or self.job is not None):
            return 3
        return None

    def execute(self, command: p.Command) -> list[str]:
        """Apply `command`; return the reply lines a serial link sends now (before `$`)."""
        s = self.settings
        if isinstance(command, p.SetAutoLevel):
            s.autolevel = command.on
        elif isinstance(command, p.SetBuzzer):
            s.buzzer = command.on
        elif isinstance(command, p.SetZOffset):
            s.zoffset = command.value
            self._zoffset_shown = s.zoffset
        elif isinstance(command, p.NudgeZOffset):
            s.zoffset += 1 if command.up else -1
        elif isinstance(command, p.GetZOffset):
            shown = self._zoffset_shown  # the firmware answers with the value from before a nudge
            self._zoffset_shown = s.zoffset
            return [str(shown)]
        elif isinstance(command, p.SetName):
            s.name = command.name
        elif isinstance(command, p.SetLanguage):
            s.language = command.code
        elif isinstance(command, p.SetEnergy):
            s.energy = command.minutes
        elif isinstance(command, p.RestoreDefaults):
            keep = (s.machine_min, s.extruder_min, s.filament_mm)
            self.settings = Settings(name=self.persona.name, zoffset=self.persona.zoffset)
            self.settings.machine_min, self.settings.extruder_min, self.settings.filament_mm = keep
        elif isinstance(command, p.JoinWifi):
            s.ssid, s.ip = command.ssid, "192.168.1.118"
        elif isinstance(command, p.LeaveWifi):
            s.ssid, s.ip = "", "0.0.0.0"
        elif isinstance(command, p.PrintControl):
            return self._print_control(command.op)
        elif isinstance(command, p.TagInfo):
            return [f"taginfo:{{{self.persona.serial}}}"]
        elif isinstance(command, p.Uid):
            return [p.raw_reply_line(command, self._machine_bytes(b"uid")[:4])]
        elif isinstance(command, p.Signature):
            return [p.raw_reply_line(command, self._machine_bytes(b"signature"))]
        elif isinstance(command, p.Home):
            self._begin("home", 9534, 5)
            return [p.stat_line("home", "start")]
        elif isinstance(command, p.Jog):
            self._begin("jog", 9532, 30)
            self._jog_time = max(0.3, abs(command.distance) / 20)
            return [p.stat_line("jog", "start")]
        elif isinstance(command, p.Flow):
            return self._flow(command)
        self._save()
        return ["ok"] if command.expect is p.Expect.ACK else []

    def _machine_bytes(self, what: bytes) -> bytes:
        """Stable per-machine raw bytes for `uid`/`signature` (their meaning on real firmware is unknown; what
        clients see is a fixed binary value per printer, any byte value allowed — `\n` and `"` included)."""
        return hashlib.sha256(what + b":" + self.persona.serial.encode()).digest()

    def _print_control(self, op: str) -> list[str]:
        code = self.state[0]
        if op == "pause" and code == PRINTING:
            self._set(PAUSED)
        elif op == "resume" and code == PAUSED:
            self._set(PRINTING)
        elif op == "cancel" and code in (PRINTING, PAUSED, FILE_CHECK):
            self._set(CANCELLING)
            self.target = 0
            self.flow_since = self.now
        elif op == "complete" and code == PRINT_DONE:
            self._finish_job(IDLE)
        return ["ok"]

    def _flow(self, command: p.Flow) -> list[str]:
        name, op = command.flow, command.op
        if name in ("load", "unload"):
            heat_stat = [p.stat_line(name, "heat", extemp=str(int(self.extruder)))]
            if op in ("new", "retry"):
                if NO_CARTRIDGE in self.errors and name == "load":
                    return [p.stat_line(name, "fail")]
                sub = 11 if name == "load" else 21
                self._begin(name, 9530 if name == "load" else 9531, sub, FLOW_TEMP)
                self.outbox.extend(heat_stat)
                return [p.stat_line(name, "start")]
            if op == "cancel" and self.flow == name:
                self._idle()
                if name == "unload":
                    self._stat("unload", "complete")
                    return []
                return [p.stat_line(name, "complete")]
            return [p.stat_line(name, "complete")] if name == "load" else []
        if name == "cleannozzle":
            if op == "new":
                self._begin("clean", 9536, 51, FLOW_TEMP)
                return [p.stat_line(name, "start")]
            if self.flow == "clean":
                self._idle()
            return [p.stat_line(name, "ok")]
        # calibratejr
        if op == "new":
            self._begin("calibrate", 9535, 40)
            self.outbox.append(p.stat_line(name, "pressdetector"))
            self._set(9535, 41)
            return [p.stat_line(name, "start")]
        if op == "detectorok" and self.state == (9535, 41):
            self._set(9535, 43)
            self.flow_since = self.now
            return [p.stat_line(name, "processing")]
        if op == "getdata":
            return ["calibratejr:{" + ",".join(str(v) for v in self.settings.calibration) + "}"]
        if op == "release" and self.flow == "calibrate":
            self._idle()
            return [p.stat_line(name, "complete")]
        return [p.stat_line(name, "fail")]

    # ------------------------------------------------------------------------------------------ uploads

    def check_file(self, data: bytes) -> FileVerdict:
        """What the firmware decides in state 9520: can this model print these bytes?"""
        from fabwire.xyz.threew import inspect_3w

        if "file-rejected" in self.faults:
            return FileVerdict(False, reason="rejected on demand")
        kind = intake.identify(data[:intake.SNIFF], len(data))  # the printer decodes no base64 (XYZware did)
        if kind is not intake.Kind.THREEW:
            accepted = kind is intake.Kind.GCODE and self.persona.accepts_gcode
            return FileVerdict(accepted, reason=f"{kind.value}, not a .3w file")
        try:
            info = inspect_3w(data)
        except InputError as exc:
            return FileVerdict(False, reason=str(exc))
        fmt = FileFormat.V2_ZIP if info.zipped else FileFormat.V5 if info.container == 5 else FileFormat.V2
        accepts = self.persona.accepts or (self.persona.model.file_format,)
        machine = (info.machine or "").strip()
        if not info.crc_ok or fmt not in accepts or machine.lower() != self.persona.model.file_id.lower():
            return FileVerdict(False, reason=f"{fmt.value} file for {machine or 'unknown machine'}")
        return FileVerdict(True, float(info.print_time_s or 60), float(info.filament_mm or 0.0))

    def start_job(self, name: str, data: bytes, verdict: FileVerdict) -> None:
        self.stored = {name: data}  # the printer keeps the file it prints, not every file it was sent
        self.job = Job(name, data, max(verdict.print_time, 1.0), verdict.filament_mm, rejected=not verdict.ok,
                       filament_start=self.settings.filament_mm)
        self.errors = [e for e in self.errors if e != FILE_REJECTED]
        self._begin("print", FILE_CHECK, 0)
        self.flow = None

    # ------------------------------------------------------------------------------------------- status

    def scan(self) -> list[dict[str, str]]:
        """What a `query=W` Wi-Fi scan finds: the joined network first, then the neighbours."""
        nearby = [("TUCKER_HOME", "54:8c:a0:06:7e:01", "6", "39"), ("Neighbour-5G", "a4:2b:b0:11:22:33", "36", "71"),
                  ("PrinterLab", "10:fe:ed:4c:8a:90", "11", "58")]
        if self.settings.ssid and self.settings.ssid not in [n[0] for n in nearby]:
            nearby.insert(0, (self.settings.ssid, "54:8c:a0:06:7e:02", "1", "45"))
        return [{"ssid": ssid, "bssid": bssid, "channel": channel, "rssiValue": rssi, "PHY": "11n",
                 "security": "WPA2-PSK"} for ssid, bssid, channel, rssi in nearby]

    def status(self, *, scan: bool = False) -> Status:
        """The status letters of this personality; `scan` adds a `W:` Wi-Fi scan (sent only when asked)."""
        persona, s = self.persona, self.settings
        code, sub = self.state
        job = self.job
        progress = Progress(0, 0, 0)
        if job is not None and job.phase in ("heat", "print") and code in (PRINTING, PAUSED):
            pct = min(99, int(100 * job.printed / job.print_time))
            progress = Progress(pct, int(job.printed // 60), int(max(0.0, job.print_time - job.printed) // 60) + 1)
        present = NO_CARTRIDGE not in self.errors and persona.cartridge_tags
        settings = dict(persona.settings)
        if "buzzer" in settings:
            settings["buzzer"] = "on" if s.buzzer else "off"
        if "dr" in settings:
            settings["dr"] = {"top": "on" if DOOR_OPEN in self.errors else "off", "front": "off"}
        temps: tuple[int, tuple[int | None, ...]] = (
            (1, (int(self.extruder), self.target)) if persona.target_in_t else (1, (int(self.extruder),)))
        if not persona.sensors:
            temps = (1, (None, None))
        lifetime = Lifetime(1, s.machine_min + int(self.now // 60), s.extruder_min,
                            int(self.now // 60) if persona.lifetime_last else None)
        fields: dict[str, Any] = {
            "bed": int(AMBIENT) - 2,
            "calibration": tuple(str(v) for v in s.calibration) + persona.calibration_tail,
            "progress": progress,
            "cartridge": Cartridge(1, (persona.cartridge if present else p.NO_CARTRIDGE_SERIAL,)),
            "errors": tuple(self.errors) or persona.idle_errors,
            "filament": (1, s.filament_mm if present else -1) if persona.cartridge_tags else (1, 0),
            "serial": persona.serial,
            "state": (old_state_code(code) if persona.old_states else code, sub if persona.substates else None),
            "lifetime": lifetime,
            "m": (0, 0, 0),
            "packet": Packet(8, "1", persona.packet_c, s.autolevel if persona.autolevel_in_o else None),
            "targets": {"nozzle": str(self.target), "bed": "0"},
            "model_number": persona.model.model_number,
            "settings": settings,
            "temperatures": Temperatures(temps[0], temps[1]),
            "firmware": persona.firmware,
            "name": s.name,
            "nozzle": persona.nozzle,
            "language": s.language,
            "zoffset": s.zoffset,
            "wifi_firmware": persona.wifi_firmware,
            "network": (Network(s.ip, s.ssid, "0", 39, "54:8c:a0:06:7e:48") if persona.network_json
                        else Network(s.ip, json_form=False)),
        }
        if persona.second_cartridge and persona.cartridge_tags:  # two spools: both tags, both lengths
            fields["cartridge"] = Cartridge(2, (persona.cartridge if present else p.NO_CARTRIDGE_SERIAL,
                                                persona.second_cartridge))
            fields["filament"] = (2, s.filament_mm if present else -1, s.filament2_mm)
        if scan and persona.model.wifi:
            fields["networks"] = self.scan()
        if persona.fw3:
            last = self.job or self.last_job
            fields["print_file"] = {"PrintFile": last.name if last else "", "Complete": 0}
        wanted = {letter: spec[0] for letter, spec in LETTERS.items()}
        order = persona.order + ("Z" if persona.fw3 else "") + ("W" if "networks" in fields else "")
        values = {wanted[letter]: fields[wanted[letter]] for letter in order if wanted.get(letter) in fields}
        dashed = frozenset() if persona.sensors else frozenset({"b"})
        if dashed:
            values.pop("bed", None)
        return Status(order=tuple(order), dashed=dashed, **values)


_OLD_STATES = {9500 + n: n for n in range(5)} | {9501 + n: n for n in range(5, 11)} | {
    9505: 11, **{9500 + n: n for n in range(12, 18)}}


def old_state_code(code: int) -> int:
    """The pre-95xx code old firmware reports (9511 → 10); codes without an old form stay as they are."""
    if code == FILE_CHECK:
        return 0  # "print initial": the closest old state to the file check
    if code == CANCELLING:
        return 12  # "print stop"
    return _OLD_STATES.get(code, code)
