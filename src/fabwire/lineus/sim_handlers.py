"""The simulated Line-us's answers to its non-moving commands (settings, files, names, Wi-Fi, reports), and what
the firmware keeps per connection.

Each handler takes the machine, the parsed command and the connection's session and returns the reply (or a
function that builds it when its turn comes, for reports that must see the arm after the moves ahead of them).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from fabwire.lineus import kinematics as kin
from fabwire.lineus import protocol as p
from fabwire.lineus.arm import Job
from fabwire.lineus.interpreter import Interpreter

if TYPE_CHECKING:
    from fabwire.lineus.sim import LineUsSim

FS_TOTAL = 1_953_282
"""Flash bytes for files (M122/M39 FSTotal on a 3.2.0 machine): stored drawings cannot grow past it."""


@dataclass
class Session:
    """What the firmware keeps per connection: its G54 (in the interpreter) and its M28 recording."""

    interpreter: Interpreter
    saving: int | None = None
    saved: list[str] = field(default_factory=list)
    saved_bytes: int = 0
    backlog: int = 0
    """Replies handed to the writer and not yet sent."""


def error_reply(text: str) -> p.Reply:
    clean = "".join(ch if 32 <= ord(ch) < 127 and ch != '"' else "'" for ch in text)[:200]
    return p.Reply(False, (("INFO", clean),))


ReplySource = p.Reply | Callable[[], p.Reply] | Job
"""A reply now, one computed when its turn comes (M114), or a move's, due when the move ends."""


Handler = Callable[["LineUsSim", p.Command, Session], ReplySource]


def _zmap(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.ZMap)
    if c.clear:
        sim.zmap = (0.0, 0.0, 0.0, 0.0)
    elif c.corners is not None:
        sim.zmap = c.corners
    else:
        return p.Reply(True, (("ZMap", ";".join(p.format_number(v) for v in sim.zmap)),))
    return p.Reply(True)


def _origin(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.SetOrigin)
    s.interpreter.set_origin(c)
    return p.Reply(True)


def _speed(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.SetSpeed)
    model = sim.arm.model
    sim.arm.model = dataclasses.replace(
        model,
        draw_step=c.draw if c.draw is not None else model.draw_step,
        travel_step=c.travel if c.travel is not None else model.travel_step,
    )
    return p.Reply(True)


def _list_files(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    return p.Reply(True, (("FS", sim.file_listing()),))


def _memory(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.MemoryDrawing)
    sim.memory_mode = c.mode
    return p.Reply(True)


def _start_save(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.StartSave)
    s.saving, s.saved = c.slot, []
    sim.files[c.slot] = ""
    return p.Reply(True)


def _end_save(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    return error_reply("M29 without M28: not saving a drawing")


def _delete(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.DeleteFile)
    if sim.files.pop(c.slot, None) is None:
        return error_reply(f"no drawing {c.slot}")
    return p.Reply(True)


def _usage(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    used = sim.fs_used()
    return p.Reply(True, (("FSUsed", str(used)), ("FSTotal", str(FS_TOTAL)), ("FSFree", str(FS_TOTAL - used)),
                          ("FSPercent", str(used * 100 // FS_TOTAL))))


def _demo(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.TimedDemo)
    if c.drawing is not None and c.drawing not in sim.files:
        return error_reply(f"no drawing {c.drawing}")
    sim.set_demo((c.seconds, c.period, c.drawing) if c.period > 0 and c.seconds > 0 else None)
    return p.Reply(True)


def _position(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.GetPosition)

    def report() -> p.Reply:
        x, y, z = sim.arm.position
        if not c.servos:
            return sim.position_reply(sim.arm.position)
        shoulder, elbow = kin.servo_angles(x, y)
        pen = 45.0 + 90.0 * z / kin.Z_UP
        return p.Reply(True, (("S", f"{shoulder:.2f}"), ("E", f"{elbow:.2f}"), ("P", f"{pen:.2f}")))

    return report


def _capabilities(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    return p.Reply(True, (("CONNECTMODE", "ST"), ("MACHINENAME", sim.name)))


def _diagnostics(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    return sim.diagnostics()


def _reserved(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    return error_reply(f"{c.text()} is reserved for the factory")


def _reset(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.FactoryReset)
    sim.factory_reset(c.wipe_files)
    return p.Reply(True)


def _reverse(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    sim.servo_reverse = [1 - v for v in sim.servo_reverse]
    return p.Reply(True)


def _gestures(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.Gestures)
    sim.gestures = c.on
    return p.Reply(True)


def _calibrate(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.SaveCalibration)
    if c.clear:
        sim.calibration = (0.0, 0.0, 0.0)
    else:
        x, y, _ = sim.arm.position
        sim.calibration = (round((x - kin.HOME[0]) / 20, 5), round((y - kin.HOME[1]) / 20, 5), 0.0)
    return p.Reply(True)


def _name(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.MachineName)
    if c.name is None:
        return p.Reply(True, (("MACHINENAME", sim.name),))
    sim.name = c.name
    return p.Reply(True, (("MACHINENAME", sim.name),))


def _startup(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.StartupMode)
    sim.startup = (c.mode or sim.startup[0], c.ap_name or sim.startup[1])
    return p.Reply(True)


def _wifi(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.Wifi)
    if c.ssid is None:
        return sim.wifi_list()
    if ":" in c.ssid:
        return error_reply("an SSID with ':' cannot be listed")
    sim.known_wifi[c.ssid] = c.password or ""
    return p.Reply(True)


def _forget(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    assert isinstance(c, p.ForgetWifi)
    if c.ssid == "*":
        sim.known_wifi.clear()
    elif sim.known_wifi.pop(c.ssid, None) is None:
        return error_reply(f"no stored network {c.ssid}")
    return p.Reply(True)


def _update(sim: LineUsSim, c: p.Command, s: Session) -> ReplySource:
    return error_reply("firmware update server unreachable")


HANDLERS: dict[type[p.Command], Handler] = {
    p.ZMap: _zmap, p.SetOrigin: _origin, p.SetSpeed: _speed, p.ListFiles: _list_files, p.MemoryDrawing: _memory,
    p.StartSave: _start_save, p.EndSave: _end_save, p.DeleteFile: _delete, p.StorageUsage: _usage,
    p.TimedDemo: _demo, p.GetPosition: _position, p.Capabilities: _capabilities, p.Diagnostics: _diagnostics,
    p.Reserved: _reserved, p.FactoryReset: _reset, p.ReverseServos: _reverse, p.Gestures: _gestures,
    p.SaveCalibration: _calibrate, p.MachineName: _name, p.StartupMode: _startup, p.Wifi: _wifi,
    p.ForgetWifi: _forget, p.FirmwareUpdate: _update,
}
