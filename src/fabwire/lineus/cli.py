"""`fabwire lineus …` (talk to a Line-us) and `fabwire sim lineus` (be one)."""

from __future__ import annotations

import asyncio
import contextlib
import math
import socket
from collections.abc import Awaitable, Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from fabwire.cli_support import App, DeviceContext, FiniteRange, Lazy, confirm, device_group, pass_app, pass_device
from fabwire.devices import LINEUS
from fabwire.errors import InputError, LocalProtocolError
from fabwire.lineus import protocol as p
from fabwire.units import json_key

if TYPE_CHECKING:
    from fabwire.lineus.client import LineUs, Position

T = TypeVar("T")


@device_group(LINEUS, "Line-us drawing robot: draw SVGs and text, preview, move the arm, stored drawings, Wi-Fi.",
              lazy={
    "draw": Lazy("fabwire.lineus.draw_cli:draw",
                 "Draw an SVG, SVGZ or Line-us G-code FILE ('-' reads it from standard input).", "lineus"),
    "text": Lazy("fabwire.lineus.draw_cli:text", "Write TEXT in a single-stroke font (\\n starts a new line, \\t moves "
                                                 "on to the next tab stop; '-' reads the text from standard input).",
                 "lineus"),
    "preview": Lazy("fabwire.lineus.draw_cli:preview", "Plan FILE ('-' reads standard input) and write a picture of "
                    "what the pen will do (pen-up travel dashed, parts hidden by clip paths faint), or the plan as "
                    "Line-us G-code; no device needed.", "lineus"),
    "shell": Lazy("fabwire.lineus.shell:shell", "An interactive session on one connection: moves, pen, position, "
                                                "G-code lines and their replies."),
})
def lineus() -> None:
    """Line-us drawing robot."""


def _with_arm(dctx: DeviceContext, action: Callable[[LineUs], Awaitable[T]], *, moves: str = "") -> T:
    """Run `action` on the connected arm; one that `moves` the arm (named in words, "a move") is refused while
    another program draws on this robot, and no drawing starts on it meanwhile."""
    from fabwire.lineus.client import LineUs  # with numpy's kinematics: not for help or completion
    from fabwire.lineus.drawing_lock import DrawingLock, robot_address

    async def main() -> T:
        async with dctx.open(LineUs) as arm:
            try:
                if not moves:
                    return await action(arm)
                with DrawingLock(robot_address(arm.transport), moves):
                    return await action(arm)
            finally:
                for notice in arm.notices:
                    dctx.output.note(notice)

    return asyncio.run(main())




_DIAGNOSTIC_LABELS = {"Serial": "Serial code (M122's own field, not the serial number)"}
"""M122 keys shown under other words: its `Serial` (`ikdBW+`) is not the machine's serial number."""


@lineus.command()
@pass_device
def info(dctx: DeviceContext) -> None:
    """Firmware, name, serial, connection mode and diagnostics."""

    async def action(arm: LineUs) -> dict[str, Any]:
        caps = await arm.capabilities()
        diag = await arm.diagnostics()
        hello = arm.hello
        # The hello's SERIAL is the ChipID M122 reports (reference §M122); either may be missing.
        return {"version": hello.version, "firmware_major": hello.firmware_major,
                "name": hello.name or diag.get("name", ""), "serial": hello.serial or diag.get("ChipID", ""),
                "capabilities": caps, "diagnostics": diag}

    data = _with_arm(dctx, action)

    def human() -> None:
        out = dctx.output.out
        out.print(f"Line-us {data['name'] or '(no name)'}  firmware {data['version'] or '(not given)'}  "
                  f"serial {data['serial'] or '(not given)'}")
        out.print(f"connect mode {data['capabilities'].get('CONNECTMODE', '?')}")
        for key, value in data["diagnostics"].items():
            if (key, value) in (("ChipID", data["serial"]), ("name", data["name"])):
                continue  # shown on the first line already
            out.print(f"  {_DIAGNOSTIC_LABELS.get(key, key)}: {value}")

    dctx.output.result(data, human)


@lineus.command()
@click.option("--servos", is_flag=True, help="Report servo angles in degrees (M114 S) instead of coordinates.")
@pass_device
def position(dctx: DeviceContext, servos: bool) -> None:
    """Where the arm is (M114)."""
    if servos:
        angles = _with_arm(dctx, lambda arm: arm.servo_angles())
        dctx.output.result({json_key(k.lower(), "deg"): v for k, v in angles.items()},
                           "  ".join(f"{k} {v:.2f}°" for k, v in angles.items()))
        return
    where = _with_arm(dctx, lambda arm: arm.position())
    dctx.output.result(where.as_dict(), where.text())


@lineus.command()
@pass_device
def status(dctx: DeviceContext) -> None:
    """The arm at a glance: name, firmware, where the pen is, and who is drawing on it now (any program of this
    host: another `fabwire`, `fabwire serve`, vpype's `lineus-draw`)."""
    from fabwire.lineus.drawing_lock import current_drawer, robot_address

    async def action(arm: LineUs) -> dict[str, Any]:
        where = await arm.position()
        drawer = current_drawer(robot_address(arm.transport))
        drawing = None if drawer is None else {
            "what": drawer.what, "command": drawer.command, "pid": drawer.pid, "user": drawer.user,
            "since": datetime.fromtimestamp(drawer.started, tz=UTC).isoformat(timespec="seconds"),
            json_key("progress", "percent"): round(drawer.progress_percent, 1), "progress": drawer.progress,
            "words": drawer.words()}
        return {"name": arm.hello.name, "firmware": arm.hello.version, "position": where.as_dict(),
                "drawing": drawing}

    data = _with_arm(dctx, action)

    def human() -> None:
        out = dctx.output.out
        out.print(f"Line-us {data['name'] or '(no name)'}  firmware {data['firmware'] or '(not given)'}")
        place = data["position"]
        out.print(f"pen {place['pen']} at {place['x_mm']:g}, {place['y_mm']:g} mm")
        out.print(f"drawing {data['drawing']['words']}" if data["drawing"] else
                  "idle: no program of this host is drawing on it")

    dctx.output.result(data, human)


@lineus.command()
@pass_device
def home(dctx: DeviceContext) -> None:
    """Send the arm home (1000, 1000), pen up."""
    where = _with_arm(dctx, lambda arm: arm.home(), moves="going home")
    dctx.output.result(where.as_dict(), where.text())


@lineus.command(context_settings={"ignore_unknown_options": True})
@click.argument("x", type=FiniteRange())
@click.argument("y", type=FiniteRange())
@click.option("--pen", type=click.Choice(["up", "down"]), help="Pen state for the move (default: unchanged).")
@click.option("--z", "z", type=FiniteRange(0, 1000), help="Explicit pen height 0 (down) … 1000 (up).")
@pass_device
def move(dctx: DeviceContext, x: float, y: float, pen: str | None, z: float | None) -> None:
    """Move the pen to machine coordinates X Y (G01); a target outside the area is clamped and the pen lifted.

    Negative coordinates work as they are (`move 1200 -300`)."""
    if pen is not None and z is not None:
        raise InputError("give --pen or --z, not both")
    height = z if z is not None else (1000.0 if pen == "up" else 0.0 if pen == "down" else None)
    try:
        p.Move(x, y, height)
    except LocalProtocolError as exc:
        raise InputError(str(exc)) from None
    from fabwire.lineus import kinematics as kin

    async def moved(arm: LineUs) -> tuple[Position, bool]:
        return await arm.move(x, y, height), arm.guard_body

    where, guarded = _with_arm(dctx, moved, moves=f"a move to ({x:g}, {y:g})")
    clamped = abs(where.x - x) > 0.01 or abs(where.y - y) > 0.01
    if clamped and (note := kin.clamp_note(x, y, notch_guarded=guarded)):
        dctx.output.note(note)
    dctx.output.result({**where.as_dict(), "clamped": clamped}, where.text())


@lineus.command()
@click.argument("words", nargs=-1, required=True)
@pass_device
def send(dctx: DeviceContext, words: tuple[str, ...]) -> None:
    """Send one G-code command (checked against the protocol first) and print the reply."""
    try:
        command = p.parse_command(" ".join(words))
    except Exception as exc:
        raise InputError(f"not a Line-us command: {exc}") from None
    moving = isinstance(command, p.Move | p.RawMove | p.Home)
    reply = _with_arm(dctx, lambda arm: arm.send(command), moves=f"G-code {command.text()!r}" if moving else "")
    dctx.output.result({"ok": reply.ok, "fields": reply.as_dict()}, reply.text())


@lineus.group()
def files() -> None:
    """Drawings stored on the machine (slots 1-32)."""


@files.command("list")
@pass_device
def files_list(dctx: DeviceContext) -> None:
    """List stored drawings (M20)."""
    drawings = _with_arm(dctx, lambda arm: arm.list_drawings())
    rows = [{"slot": d.slot, "size_bytes": d.size, "path": d.path} for d in drawings]
    text = "\n".join(f"{d.slot:>3}  {d.size:>8} bytes  {d.path}" for d in drawings) or "no stored drawings"
    dctx.output.result(rows, text)


@files.command("save")
@click.argument("gcode", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument("slot", type=click.IntRange(1, 32))
@click.option("--yes", is_flag=True, help="Overwrite a drawing already stored in SLOT without asking.")
@pass_device
def files_save(dctx: DeviceContext, gcode: Path, slot: int, yes: bool) -> None:
    """Store a G-code FILE as drawing SLOT (M28 … M29); every line is checked first.

    Lines are read as the machine reads them (the interpreter `draw` and `preview` use too): comments are left
    out, and a line the Line-us would refuse stops the upload before anything is sent. A drawing already stored
    in SLOT is only replaced when confirmed (typed "y", or --yes)."""
    from fabwire.lineus.interpreter import read_program

    try:
        text = gcode.read_text(encoding="utf-8-sig")
    except (UnicodeDecodeError, OSError) as exc:
        raise InputError(f"{gcode}: cannot read as a text G-code file: {exc}") from None
    program = read_program(text, name=str(gcode))
    lines = [line.text for line in program.lines]
    if not lines:
        raise InputError(f"{gcode}: no G-code lines")
    note = program.skipped_note()
    if note is not None:
        dctx.output.note(note.replace("skipped", "left out", 1))
    async def save(arm: LineUs) -> int:
        stored = {d.slot: d for d in await arm.list_drawings()}
        if slot in stored:
            confirm(f"overwrite drawing {slot} stored on the Line-us ({stored[slot].size} bytes)", yes)
        return await arm.save_drawing(slot, lines)

    count = _with_arm(dctx, save)
    dctx.output.result({"slot": slot, "lines": count}, f"stored {count} lines as drawing {slot}")


@files.command("delete")
@click.argument("slot", type=click.IntRange(1, 32))
@pass_device
def files_delete(dctx: DeviceContext, slot: int) -> None:
    """Delete stored drawing SLOT (M30)."""
    _with_arm(dctx, lambda arm: arm.delete_drawing(slot))
    dctx.output.result({"slot": slot, "deleted": True}, f"deleted drawing {slot}")


@lineus.command()
@click.argument("new", required=False)
@pass_device
def name(dctx: DeviceContext, new: str | None) -> None:
    """Show the machine name, or set it to NEW (letters, digits, '-'; reached as NEW.local afterwards)."""
    if new is not None:
        try:
            p.MachineName(new)
        except LocalProtocolError as exc:
            raise InputError(str(exc)) from None

        async def rename(arm: LineUs) -> str:
            await arm.set_name(new)
            return await arm.name()

        current = _with_arm(dctx, rename)
    else:
        current = _with_arm(dctx, lambda arm: arm.name())
    dctx.output.result({"name": current}, current)


@lineus.group()
def wifi() -> None:
    """Wi-Fi networks the machine knows."""


@wifi.command("list")
@pass_device
def wifi_list(dctx: DeviceContext) -> None:
    """Networks in range and networks with a stored password (M587)."""
    networks = _with_arm(dctx, lambda arm: arm.wifi_networks())
    rows = [{"ssid": n.ssid, "visible": n.visible, "known": n.known} for n in networks]

    def state(visible: bool, known: bool) -> str:
        return "known, in range" if visible and known else "in range" if visible else "known, not in range"

    text = "\n".join(f"{n.ssid}  ({state(n.visible, n.known)})" for n in networks) or "no networks"
    dctx.output.result(rows, text)


@wifi.command("add")
@click.argument("ssid")
@click.option("--password", help="The network's password (omit for an open network).")
@pass_device
def wifi_add(dctx: DeviceContext, ssid: str, password: str | None) -> None:
    """Store network SSID (M587)."""
    try:
        p.Wifi(ssid, password)
    except LocalProtocolError as exc:
        raise InputError(str(exc)) from None
    _with_arm(dctx, lambda arm: arm.add_wifi(ssid, password))
    dctx.output.result({"ssid": ssid, "stored": True}, f"stored network {ssid}")


@wifi.command("forget")
@click.argument("ssid", required=False)
@click.option("--all", "forget_all", is_flag=True, help="Forget every stored network.")
@pass_device
def wifi_forget(dctx: DeviceContext, ssid: str | None, forget_all: bool) -> None:
    """Forget network SSID, or --all (M588)."""
    if forget_all == (ssid is not None):
        raise InputError("give an SSID or --all")
    target = "*" if forget_all else str(ssid)
    _with_arm(dctx, lambda arm: arm.forget_wifi(target))
    dctx.output.result({"forgotten": target}, "forgot every network" if forget_all else f"forgot {target}")


@lineus.command()
@click.option("--yes", is_flag=True, help="Really overwrite the stored calibration.")
@click.option("--clear", is_flag=True, help="Clear the XY calibration instead of saving it.")
@pass_device
def calibrate(dctx: DeviceContext, yes: bool, clear: bool) -> None:
    """Save the arm's current point as the XY calibration point (M374), or --clear it. Needs --yes."""
    if not yes:
        raise InputError("calibration overwrites the stored XY calibration: add --yes to go ahead")
    _with_arm(dctx, lambda arm: arm.calibrate(clear=clear, confirm=True))
    dctx.output.result({"calibration": "cleared" if clear else "saved"},
                       "calibration cleared" if clear else "calibration saved")


@lineus.command("update")
@click.option("--yes", is_flag=True, help="Really let the machine download new firmware and restart.")
@pass_device
def firmware_update(dctx: DeviceContext, yes: bool) -> None:
    """Ask the machine to download and install the latest firmware (M997). Needs --yes.

    The machine fetches the firmware itself from the maker's update server and restarts; it answers `error`
    when that server cannot be reached."""
    if not yes:
        raise InputError("a firmware update downloads new firmware and restarts the machine: add --yes to go ahead")
    _with_arm(dctx, lambda arm: arm.firmware_update(confirm=True))
    dctx.output.result({"firmware_update": "started"}, "firmware update started; the machine restarts when done")


@lineus.command()
@click.option("--wait", type=FiniteRange(min=0.1, max=60), default=3.0, show_default=True,
              help="Seconds to listen for answers.")
@click.option("--interface", "interfaces", multiple=True, help="Only browse on this local address (repeatable).")
@pass_app
def discover(app: App, wait: float, interfaces: tuple[str, ...]) -> None:
    """Find Line-us machines on the network by mDNS (_lineus._tcp.local.)."""
    from fabwire.lineus.discovery import discover as browse

    found = asyncio.run(browse(wait, interfaces=interfaces or None))
    rows = [{"name": f.name, "host": f.host, "address": f.address, "port": f.port} for f in found]
    text = "\n".join(f"{f.name}  {f.host}  {f.address}:{f.port}" for f in found) or "no Line-us found"
    app.output.result(rows, text)




# -- the simulator ---------------------------------------------------------------------------------------------------


def _free_port(host: str) -> int:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


def _check_record_path(record: Path) -> None:
    """Refuse (InputError, exit 4) a --record file the drawing could not be saved to when the simulator stops."""
    import tempfile

    from fabwire.lineus.render import PICTURE_SUFFIXES, picture_suffix_problem

    if record.suffix.lower() not in PICTURE_SUFFIXES:
        raise InputError(f"--record {record}: {picture_suffix_problem(record)}")
    try:  # a real file in the same folder: existence, permissions, read-only mounts, all at once
        with tempfile.NamedTemporaryFile(dir=record.parent, prefix=f".{record.name}.", suffix=".probe"):
            pass
    except OSError as exc:
        raise InputError(f"--record {record}: cannot write there: {exc.strerror or exc}") from None


@click.command("lineus")
@click.option("--listen", "listen", multiple=True, metavar="HOST:PORT",
              help="Serve on TCP (default 127.0.0.1:1337); repeat for several addresses.")
@click.option("--speed", type=FiniteRange(min=0, open_ended=True), default=1.0, show_default=True,
              help="Motion speed-up factor; 0 or inf = no motion delay.")
@click.option("--version", "version", default="3.x", show_default=True,
              help="Firmware personality: 1.0.1 (integer replies, one command at a time) "
                   "or 3.x (decimals, look-ahead).")
@click.option("--name", default="line-us", show_default=True, help="Machine name (hello NAME, M550).")
@click.option("--serial", default="123456", show_default=True, help="Serial number in the hello.")
@click.option("--reply", type=click.Choice(["complete", "accept"]), default="complete", show_default=True,
              help="Answer a move when it has finished, or when the motion queue took it.")
@click.option("--record", type=click.Path(dir_okay=False, path_type=Path),
              help="On exit, write what the pen drew to FILE (.svg or .png).")
@click.option("--advertise", is_flag=True, help="Advertise _lineus._tcp.local. by mDNS.")
@pass_app
def sim_lineus(app: App, listen: tuple[str, ...], speed: float, version: str, name: str, serial: str, reply: str,
               record: Path | None, advertise: bool) -> None:
    """A Line-us on TCP that the official clients cannot tell from the robot."""
    from fabwire.lineus.discovery import Advertiser
    from fabwire.lineus.sim import LineUsSim, SimOptions, farewell, resolve_version
    from fabwire.simoptions import parse_listen
    from fabwire.simserve import serve

    if record is not None:
        _check_record_path(record)
    try:
        options = SimOptions(version=resolve_version(version), name=name, serial=serial,
                             speed=math.inf if speed == 0 else speed,
                             reply="accept" if reply == "accept" else "complete")
    except ValueError as exc:
        raise InputError(str(exc)) from None
    sim = LineUsSim(options)
    addresses = list(listen) or [f"127.0.0.1:{LINEUS.default_port}"]
    advertised: list[tuple[str, int]] = []
    if advertise:
        fixed = []
        for text in addresses:
            where = parse_listen(text, LINEUS.default_port or 1337)
            port = where.port or _free_port(where.host)
            advertised.append((where.host, port))
            fixed.append(f"[{where.host}]:{port}" if ":" in where.host else f"{where.host}:{port}")
        addresses = fixed

    async def main() -> None:
        advertisers = [Advertiser(name, host, port) for host, port in advertised]
        try:
            for adv in advertisers:
                await adv.start()
            await serve("lineus", sim.serve, listen=tuple(addresses), use_pty=False, link=None,
                        default_port=LINEUS.default_port, json_mode=app.json, farewell=farewell)
        finally:
            for adv in advertisers:
                with contextlib.suppress(Exception):
                    await adv.stop()
            await sim.close()

    try:
        asyncio.run(main())
    finally:
        if record is not None:
            written = sim.write_record(record)
            older = f" (the oldest {sim.arm.ink.dropped} point(s) were not kept)" if sim.arm.ink.dropped else ""
            app.output.note(f"recorded {len(sim.arm.strokes)} stroke(s) to {written}{older}")
