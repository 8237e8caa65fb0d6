"""`fabwire xyz …` (drive a da Vinci printer) and `fabwire sim xyz` (be one)."""

from __future__ import annotations

import contextlib
import math
import sys
import threading
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, cast

import click

from fabwire import units
from fabwire.cli_support import (
    App,
    DeviceContext,
    FiniteRange,
    Lazy,
    confirm,
    device_group,
    pass_app,
    pass_device,
)
from fabwire.devices import XYZ
from fabwire.errors import CancelledAsAsked, FollowInterrupted, InputError, LinkError, LinkTimeout, PrintCancelled
from fabwire.files import read_bounded
from fabwire.simoptions import server_options
from fabwire.units import ABSENT, known
from fabwire.xyz import userinput
from fabwire.xyz.commands import JOG_LIMIT
from fabwire.xyz.models import PrinterModel, find_model
from fabwire.xyz.protocol import Link
from fabwire.xyz.status import Status

if TYPE_CHECKING:
    from rich.console import Console
    from rich.panel import Panel

    from fabwire.xyz.client import XYZPrinter

# The event loop, the client and the live view are imported by the commands that reach a printer: `xyz convert` and
# `xyz info` load this group too, and work on files alone.

T = TypeVar("T")


@device_group(XYZ, "XYZprinting da Vinci printers (XYZv3 over USB serial or Wi-Fi): status, print, maintenance.",
              lazy={"convert": Lazy("fabwire.xyz.threew_cli:convert", "Convert G-code to a .3w print file or back; the "
                                    "direction follows the files' types ('-' reads SRC from standard input)."),
                    "info": Lazy("fabwire.xyz.threew_cli:info", "Show what a .3w file holds (variant, CRC, model, "
                                 "print metadata), or what a G-code file would give ('-' reads standard input).")})
def xyz() -> None:
    """XYZprinting da Vinci printers."""


def _with_printer(dctx: DeviceContext, action: Callable[[XYZPrinter], Awaitable[T]]) -> T:
    import asyncio

    from fabwire.xyz.client import XYZPrinter

    async def main() -> T:
        async with dctx.open(XYZPrinter) as printer:
            return await action(printer)

    return asyncio.run(main())


async def _ask(message: str) -> None:
    """Wait for Enter on stdin; end of input means nobody is there to confirm."""
    import asyncio

    sys.stderr.write(f"{message} [press Enter] ")
    sys.stderr.flush()
    loop = asyncio.get_running_loop()
    answer: asyncio.Future[str] = loop.create_future()

    def settle(line: str) -> None:
        if not answer.done():
            answer.set_result(line)

    def read() -> None:
        line = sys.stdin.readline()
        with contextlib.suppress(RuntimeError):  # the loop is gone after Ctrl-C
            loop.call_soon_threadsafe(settle, line)

    # a daemon thread, so Ctrl-C does not wait for a line that may never come
    threading.Thread(target=read, daemon=True).start()
    line = await answer
    if not line:
        sys.stderr.write("\n")  # end the open prompt line: the error is a line of its own
        raise InputError("no confirmation on standard input; the step was stopped")


FIRMWARE_LIMIT = 64 << 20
"""Largest firmware image read (da Vinci images are a few MiB; an endless file such as /dev/zero is not one)."""
_UNCONFIRMED = " (sent; a printer on Wi-Fi does not confirm this setting)"


def _bool(value: bool | None) -> str:
    return ABSENT if value is None else "on" if value else "off"


def _state(status: Status) -> str:
    if status.state is None:
        return ABSENT
    code = f"{status.state_code}" + (f",{status.substate}" if status.substate is not None else "")
    return f"{status.state_name} ({code})"


def render_status(status: Status) -> Panel:
    from rich.panel import Panel
    from rich.table import Table

    table = Table.grid(padding=(0, 2))
    table.add_column(style="bold")
    table.add_column()
    model = status.model
    table.add_row("Model", f"{model.name if model else ABSENT} ({known(status.model_number)})")
    table.add_row("Name", known(status.name))
    table.add_row("Serial", known(status.serial))
    table.add_row("Firmware", known(status.firmware_version))
    table.add_row("State", _state(status))
    for word in status.error_words:
        table.add_row("Error", str(word))
    target = status.extruder_target
    table.add_row("Extruder", units.heating(status.extruder, target or None))
    if status.temperatures is not None and status.temperatures.count == 2:
        table.add_row("Extruder 2", units.heating(status.temperatures.extruder2, None))
    if status.bed is not None:
        table.add_row("Bed", units.temperature(status.bed))
    if status.progress and (status.progress.percent or status.progress.elapsed_min):
        left = status.progress.remaining_min
        table.add_row("Job", f"{status.progress.percent} %, {units.minutes(status.progress.elapsed_min)} elapsed, "
                      + ("time left unknown" if left is None else f"{units.minutes(left)} left"))
    cart = status.cartridge
    if cart is not None:
        spools = status.spools
        for index, spool in enumerate(spools):
            fil = spool["filament_left_mm"]
            text = "none" if not spool["present"] else f"{spool['serial']} {spool['colour'] or ''}".strip()
            table.add_row("Filament" + (f" {index + 1}" if len(spools) > 1 else ""),
                          text + (f", {units.filament(fil)} left" if fil is not None else ""))
    if status.nozzle:
        table.add_row("Nozzle", f"{known(status.nozzle.diameter_mm, ' mm')} (type {status.nozzle.kind})")
    table.add_row("Z offset", units.zoffset(status.zoffset))
    table.add_row("Auto-level", _bool(status.autolevel))
    table.add_row("Buzzer", _bool(status.buzzer))
    if status.network is not None:
        net = status.network
        table.add_row("Wi-Fi", f"{net.ip} {net.ssid or ''}".strip() if net.connected else "not connected")
    return Panel(table, title="da Vinci status", expand=False)


@xyz.command()
@click.option("--watch", is_flag=True, help="Keep polling and show live temperatures and progress (reconnects when "
                                            "the link is lost).")
@click.option("--interval", type=FiniteRange(min=0.05), default=1.0, show_default=True,
              help="Seconds between polls with --watch.")
@click.option("--count", type=click.IntRange(min=1), help="With --watch: stop after N polls.")
@pass_device
def status(dctx: DeviceContext, watch: bool, interval: float, count: int | None) -> None:
    """Show the printer's status (all fields with --json; one timestamped JSON line per poll with --watch)."""
    out = dctx.output
    if not watch:
        st = _with_printer(dctx, lambda printer: printer.status())
        out.result(st.to_dict(), lambda: out.out.print(render_status(st)))
        return
    _watch(dctx, interval, count)


RECONNECT_FIRST = 0.5
RECONNECT_MOST = 30.0
"""Seconds between reconnection attempts of `status --watch`: doubling from the first to the most."""


def _watch(dctx: DeviceContext, interval: float, count: int | None) -> None:
    """Poll until `count` statuses were shown; a lost link is reopened with backoff once the printer was reached."""
    from fabwire.xyz.live import JobView

    left = [count]
    reached = [False]
    delay = RECONNECT_FIRST
    with JobView(dctx.output, dctx.output.out, "da Vinci") as view:

        async def run(printer: XYZPrinter) -> None:
            async for st in printer.monitor(interval, left[0]):
                reached[0] = True
                view.show(st)
                if left[0] is not None:
                    left[0] -= 1

        while left[0] is None or left[0] > 0:
            try:
                _with_printer(dctx, run)
                return
            except (LinkError, LinkTimeout) as exc:
                if not reached[0]:
                    raise
                view.note(f"link lost ({exc}); reconnecting in {delay:g} s")
                time.sleep(delay)
                delay = min(delay * 2, RECONNECT_MOST)


def _resolve_model(text: str | None) -> PrinterModel | None:
    return find_model(text) if text else None


@xyz.command("print")
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path, allow_dash=True))
@click.option("--no-wait", is_flag=True, help="Return once the printer has started the job.")
@click.option("--model", "model_text", metavar="MODEL", help="Convert for this model instead of the printer's own.")
@click.option("--name", "upload_name", metavar="NAME",
              help="Name the file is uploaded under (default: derived from the file name, ASCII only).")
@click.option("--save-to-sd", is_flag=True, help="Keep the file on the printer's SD card (XYZware's SaveToSD; some "
                                                 "Jr. 2.0 models need it).")
@click.option("--force", is_flag=True, help="Print G-code even when its extrusions reach beyond the printer's build "
                                            "volume.")
@pass_device
def print_cmd(dctx: DeviceContext, file: Path, no_wait: bool, model_text: str | None, upload_name: str | None,
              save_to_sd: bool, force: bool) -> None:
    """Print a G-code (converted to the printer's .3w) or a .3w file ('-' reads it from standard input)."""
    from fabwire.xyz import intake  # G-code scanning: loaded when a file is printed, not for a status

    model = _resolve_model(model_text)
    if upload_name is not None:
        userinput.upload_name(upload_name)
    with intake.input_file(file) as (path, shown):
        kind, head = intake.sniff(path, shown)
        intake.require_printable(kind, shown, head)  # before the printer is reached
        _print(dctx, path, Path(shown).name, no_wait, model, upload_name, save_to_sd, force)


def _print(dctx: DeviceContext, file: Path, shown: str, no_wait: bool, model: PrinterModel | None,
           upload_name: str | None, save_to_sd: bool, force: bool = False) -> None:
    from fabwire.xyz.live import JobKeys, JobView, now_iso

    out = dctx.output
    started = [False]

    async def run(printer: XYZPrinter) -> Status:
        chosen = model or _resolve_model(printer.settings.model)
        # off a terminal the view prints plain lines, which need no rich (PlainLines is the part of Console it uses)
        lines = cast("Console", out.lines_err())
        with JobView(out, lines, shown) as view, JobKeys(view, printer.pause, printer.resume, printer.cancel) as keys:
            def uploaded(done: int, total: int) -> None:
                started[0] = True  # the printer has taken the upload: from here on it has the job
                view.upload(done, total)

            try:
                return await printer.print_file(file, model=chosen, progress=uploaded,
                                                on_status=lambda st: view.show(st, {"event": "status"}),
                                                wait=not no_wait, name=upload_name, save_to_sd=save_to_sd,
                                                on_note=view.note, force=force)
            except PrintCancelled as exc:
                if not keys.cancel_sent:
                    raise
                raise CancelledAsAsked(f"{shown}: the print was cancelled as asked{exc.at}") from None

    try:
        final = _with_printer(dctx, run)
    except KeyboardInterrupt:
        if not started[0]:
            raise
        where = f" -d {dctx.device}" if dctx.device else ""
        raise FollowInterrupted(f"stopped following the print; the printer keeps printing {shown}. Follow it with "
                          f"`fabwire xyz{where} status --watch`, stop it with `fabwire xyz{where} cancel`") from None
    out.result({"event": "done", "time": now_iso(), "state": final.state_code, "state_name": final.state_name},
               f"{shown}: {final.state_name}")


def _simple(name: str, help_text: str, call: Callable[[XYZPrinter], Awaitable[Any]], done: str) -> None:
    @xyz.command(name, help=help_text)
    @pass_device
    def command(dctx: DeviceContext) -> None:
        _with_printer(dctx, call)
        dctx.output.result({"ok": True, "command": name}, done)


_simple("pause", "Pause the running print.", lambda pr: pr.pause(), "paused")
_simple("resume", "Resume a paused print.", lambda pr: pr.resume(), "resumed")
_simple("home", "Home all axes and wait until done.", lambda pr: pr.home(), "homed")
_simple("acknowledge", "Confirm the finished print was removed (leave 'print finished').",
        lambda pr: pr.acknowledge(), "ready")


@xyz.command()
@click.option("--yes", is_flag=True, help="Cancel without asking (needed when not on a terminal).")
@pass_device
def cancel(dctx: DeviceContext, yes: bool) -> None:
    """Cancel the running print (asks first on a terminal)."""
    _with_printer(dctx, lambda pr: pr.cancel(confirm=lambda: confirm("cancel the running print", yes)))
    dctx.output.result({"ok": True, "command": "cancel"}, "cancelling")


@xyz.command()
@click.argument("axis", type=click.Choice(["x", "y", "z"], case_sensitive=False))
@click.argument("distance", type=FiniteRange())
@pass_device
def jog(dctx: DeviceContext, axis: str, distance: float) -> None:
    """Move AXIS by DISTANCE mm (negative = towards the minimum)."""
    if not (math.isfinite(distance) and 0 < abs(distance) <= JOG_LIMIT):
        raise InputError(f"jog distance must be a non-zero number of mm up to {JOG_LIMIT}, not {distance:g}")
    _with_printer(dctx, lambda pr: pr.jog(axis.lower(), distance))
    dctx.output.result({"ok": True, "axis": axis, "distance_mm": distance}, f"moved {axis} by {distance:g} mm")


def _progress_note(dctx: DeviceContext) -> Callable[[Status], None]:
    from fabwire.xyz.live import job_line

    last = [""]

    def note(st: Status) -> None:
        line = job_line(st)
        if line != last[0]:
            last[0] = line
            dctx.output.note(line)

    return note


@xyz.command()
@pass_device
def calibrate(dctx: DeviceContext) -> None:
    """Level the bed with the detector (you lower and raise it when asked)."""
    values = _with_printer(dctx, lambda pr: pr.calibrate(_ask, on_status=_progress_note(dctx),
                                                         on_stop=dctx.output.note))
    dctx.output.result({"calibration": list(values)}, f"calibration values: {', '.join(map(str, values))}")


@xyz.command("clean-nozzle")
@pass_device
def clean_nozzle(dctx: DeviceContext) -> None:
    """Heat the nozzle for cleaning; confirm when done."""
    _with_printer(dctx, lambda pr: pr.clean_nozzle(_ask, on_status=_progress_note(dctx)))
    dctx.output.result({"ok": True}, "nozzle clean finished")


@xyz.command()
@click.option("--retry", is_flag=True, help="Retry after a failed or finished load.")
@pass_device
def load(dctx: DeviceContext, retry: bool) -> None:
    """Load filament: heats, feeds, and stops when you confirm it comes out of the nozzle."""
    _with_printer(dctx, lambda pr: pr.load_filament(_ask, on_status=_progress_note(dctx), retry=retry))
    dctx.output.result({"ok": True}, "filament loaded")


@xyz.command()
@click.option("--retry", is_flag=True, help="Retry after a failed or finished unload.")
@pass_device
def unload(dctx: DeviceContext, retry: bool) -> None:
    """Unload filament (heats, then backs it out)."""
    _with_printer(dctx, lambda pr: pr.unload_filament(on_status=_progress_note(dctx), retry=retry))
    dctx.output.result({"ok": True}, "filament unloaded")


@xyz.command("set")
@click.argument("setting", type=click.Choice(["autolevel", "buzzer"]))
@click.argument("value", type=click.Choice(["on", "off"]))
@pass_device
def set_cmd(dctx: DeviceContext, setting: str, value: str) -> None:
    """Turn auto bed-levelling or the print-finished buzzer on or off."""
    on = value == "on"

    async def run(pr: XYZPrinter) -> None:
        await (pr.set_autolevel(on) if setting == "autolevel" else pr.set_buzzer(on))

    _with_printer(dctx, run)
    dctx.output.result({setting: value}, f"{setting} {value}")


@xyz.command()
@click.argument("value", required=False)
@pass_device
def zoffset(dctx: DeviceContext, value: str | None) -> None:
    """Show the Z offset, set it (2.45mm, or whole 1/100 mm such as 245 or -12), or nudge it one step: up / down."""
    if value is not None and value not in ("up", "down"):
        number = units.parse_zoffset(value)

    async def run(pr: XYZPrinter) -> int:
        if value is None:
            st = await pr.status("z")
            return st.zoffset if st.zoffset is not None else await pr.zoffset()
        if value in ("up", "down"):
            return await pr.nudge_zoffset(value == "up")
        return await pr.set_zoffset(number)

    result = _with_printer(dctx, run)
    dctx.output.result({"zoffset_mm": result / 100}, f"z offset {units.zoffset(result)}")


@xyz.command()
@click.argument("new", required=False)
@pass_device
def name(dctx: DeviceContext, new: str | None) -> None:
    """Show or set the printer's name (up to 16 characters)."""

    if new is not None:
        userinput.printer_name(new)

    async def run(pr: XYZPrinter) -> str | None:
        if new is not None:
            await pr.set_name(new)
        st = await pr.status("n")
        return st.name

    result = _with_printer(dctx, run)
    dctx.output.result({"name": result}, known(result))


@xyz.command()
@click.argument("code")
@pass_device
def language(dctx: DeviceContext, code: str) -> None:
    """Set the display language (en, fr, it, de, es, jp)."""
    code = userinput.language(code)
    _with_printer(dctx, lambda pr: pr.set_language(code))
    dctx.output.result({"language": code}, f"language {code}")


@xyz.command()
@click.argument("minutes", type=int)
@pass_device
def energy(dctx: DeviceContext, minutes: int) -> None:
    """Set energy saving: minutes of idle before the lights go off (0-9)."""
    userinput.energy_minutes(minutes)
    confirmed = _with_printer(dctx, lambda pr: pr.set_energy(minutes))
    dctx.output.result({"energy_saving_s": minutes * 60, "confirmed": confirmed},
                       f"energy saving after {units.minutes(minutes)} idle{_UNCONFIRMED * (not confirmed)}")


@xyz.command("restore-defaults")
@click.option("--yes", is_flag=True, help="Reset without asking (needed when not on a terminal).")
@pass_device
def restore_defaults(dctx: DeviceContext, yes: bool) -> None:
    """Reset the printer's settings to factory defaults."""
    confirm("reset every setting of the printer to factory defaults", yes)
    confirmed = _with_printer(dctx, lambda pr: pr.restore_defaults())
    dctx.output.result({"ok": True, "confirmed": confirmed},
                       f"settings restored to defaults{_UNCONFIRMED * (not confirmed)}")


@xyz.group()
def wifi() -> None:
    """The printer's Wi-Fi connection."""


@wifi.command("info")
@pass_device
def wifi_info(dctx: DeviceContext) -> None:
    """Show the printer's network address and SSID."""
    st = _with_printer(dctx, lambda pr: pr.wifi_info())
    net = st.network
    data = net.as_dict() if net else {"connected": False}
    human = (f"{net.ip} on {net.ssid or '?'} (signal {net.signal_percent if net.signal_percent is not None else '?'} %)"
             if net and net.connected else "not connected (or no Wi-Fi on this model)")
    dctx.output.result(data, human)


@wifi.command("scan")
@pass_device
def wifi_scan(dctx: DeviceContext) -> None:
    """List the Wi-Fi networks the printer can see."""
    networks = _with_printer(dctx, lambda pr: pr.scan_wifi())

    def human() -> None:
        if not networks:
            dctx.output.out.print("no networks found (or no Wi-Fi on this model)")
        for net in found:
            dbm = "?" if net["rssi_dbm"] is None else net["rssi_dbm"]
            channel = "?" if net["channel"] is None else net["channel"]
            dctx.output.out.print(f"{net['ssid'] or '?':<32} channel {channel:>3}  {dbm} dBm  {net['security']}")

    found = [_scanned(net) for net in networks]
    dctx.output.result(found, human)


def _scanned(net: dict[str, Any]) -> dict[str, Any]:
    """One network of a Wi-Fi scan for JSON: the firmware's strings typed, dBm negative as in `status`, and
    the firmware's own fields kept under `raw`."""
    def number(key: str) -> int | None:
        text = str(net.get(key, "")).strip()
        return int(text) if text.isascii() and text.isdigit() and len(text) < 6 else None

    rssi = number("rssiValue")
    return {"ssid": str(net.get("ssid", "")), "channel": number("channel"),
            "rssi_dbm": None if rssi is None else -rssi, "security": str(net.get("security", "")), "raw": net}


@wifi.command("join")
@click.argument("ssid")
@click.option("--password", help="Network password (empty for an open network); asked for on a terminal if left out.")
@click.option("--channel", type=click.IntRange(0, 165), default=0, show_default=True)
@pass_device
def wifi_join(dctx: DeviceContext, ssid: str, password: str | None, channel: int) -> None:
    """Join a Wi-Fi network (do this over USB)."""
    userinput.ssid(ssid)
    if password is None:
        if not sys.stdin.isatty():
            raise InputError("no password given (use --password)")
        password = str(click.prompt("Password", default="", hide_input=True, show_default=False))
    userinput.wifi_password(password)
    _with_printer(dctx, lambda pr: pr.join_wifi(ssid, password, channel))
    dctx.output.result({"ok": True, "ssid": ssid}, f"joining {ssid}")


@wifi.command("leave")
@pass_device
def wifi_leave(dctx: DeviceContext) -> None:
    """Disconnect from the Wi-Fi network."""
    _with_printer(dctx, lambda pr: pr.leave_wifi())
    dctx.output.result({"ok": True}, "left the Wi-Fi network")


@xyz.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--yes", is_flag=True, help="Flash without asking (needed when not on a terminal).")
@pass_device
def firmware(dctx: DeviceContext, file: Path, yes: bool) -> None:
    """Flash a firmware image (.bin with its `<model>+<version>` header). Can brick the printer."""
    confirm(f"flash {file.name} (a wrong image can brick the printer)", yes)
    try:
        image = read_bounded(file, FIRMWARE_LIMIT)
    except OSError as exc:
        raise InputError(f"cannot read {file}: {exc.strerror}") from exc
    if image is None:
        raise InputError(f"{file} is over {FIRMWARE_LIMIT >> 20} MiB: not a da Vinci firmware image")
    result = _with_printer(dctx, lambda pr: pr.upload_firmware(image, confirm=True))
    dctx.output.result({"ok": True, "size_bytes": result.size}, f"sent {result.size} bytes of firmware")


@xyz.command()
@click.option("--host", "hosts", multiple=True, metavar="HOST[:PORT]",
              help="Probe this host, on --port unless given (repeat).")
@click.option("--subnet", metavar="CIDR", help="Probe every address in CIDR, e.g. 192.168.1.0/24.")
@click.option("--port", type=click.IntRange(1, 65535), default=9100, show_default=True)
@click.option("--probe-timeout", type=FiniteRange(min=0.05), default=1.0, show_default=True)
@click.option("--concurrency", type=click.IntRange(1, 1024), default=64, show_default=True)
@pass_app
def discover(app: App, hosts: tuple[str, ...], subnet: str | None, port: int, probe_timeout: float,
             concurrency: int) -> None:
    """List XYZprinting USB serial ports, and with --host or --subnet the printers answering on TCP 9100."""
    import asyncio

    import msgspec

    from fabwire.transport.urls import parse_url
    from fabwire.xyz.discovery import Found, hosts_in, probe_hosts, this_subnet, usb_printers

    probed = msgspec.structs.replace(XYZ, default_port=port)  # a bare host is probed on --port
    named = [(e.host, e.port) for e in (parse_url(text, probed) for text in hosts)]
    if any(not host for host, _ in named):
        raise InputError("--host takes a host name or address, with an optional :PORT")
    targets = named + [(host, port) for host in (hosts_in(subnet) if subnet else [])]
    found = usb_printers()
    if targets:
        results = asyncio.run(probe_hosts(targets, timeout=probe_timeout, concurrency=concurrency,
                                          named=len(named)))
        found += [r for r in results if isinstance(r, Found)]
        for result in results[:len(named)]:  # a host asked for by name is told about; a subnet's silence is not
            if not isinstance(result, Found):
                app.output.note(f"{result.address}: not a da Vinci printer: {result.reason}")
    data = [{"address": f.address, "model_number": f.model_number, "model": f.name, "serial": f.serial,
             "detail": f.detail} for f in found]

    def human() -> None:
        if not found:
            app.output.out.print("no printers found" + ("" if targets else " on USB"))
        if not found and not targets:  # the network is searched only where asked: say how
            subnet = this_subnet() or "192.168.1.0/24"
            app.output.note(f"to search the network too: fabwire xyz discover --subnet {subnet} (or --host ADDRESS)")
        for f in found:
            app.output.out.print(f"{f.address}  {f.name or '?'}  {f.serial or ''}  {f.detail}")

    app.output.result(data, human)




@click.command("xyz")
@server_options(XYZ.default_port)
@click.option("--model", "model_text", default="dv1MW0A000", show_default=True,
              help="Model personality (model number or name, e.g. miniMaker, nano, 'mini w', 1.0 Pro).")
@click.option("--speed", type=FiniteRange(min=0.01), default=1.0, show_default=True,
              help="Time speed-up factor for heating, flows and prints.")
@click.option("--fault", "faults", multiple=True, metavar="NAME",
              help="Start with a fault: no-cartridge, door-open, file-rejected, heater-failure, link-drop, stuck.")
@click.option("--state", "state_file", type=click.Path(dir_okay=False, path_type=Path),
              help="Keep settings in this JSON file across runs.")
@click.option("--store", type=click.Path(file_okay=False, path_type=Path), help="Save received files here.")
@click.option("--strict", is_flag=True, help="Require a correct CRC-32 trailer on every upload block.")
@click.option("--link-style", type=click.Choice(["auto", "serial", "wifi"]), default="auto", show_default=True,
              help="Reply framing: auto = serial on the pty, Wi-Fi on TCP.")
@click.option("--no-control", is_flag=True, help="Refuse in-band fault triggers (XYZv3/simctl=…).")
@click.option("--max-upload", "max_upload_mb", type=click.IntRange(min=1), default=256, show_default=True,
              help="Largest upload taken, in MiB (a larger declared size is refused before any block is held).")
@pass_app
def sim_xyz(app: App, listen: tuple[str, ...], use_pty: bool, link: Path | None, model_text: str, speed: float,
            faults: tuple[str, ...], state_file: Path | None, store: Path | None, strict: bool,
            link_style: str, no_control: bool, max_upload_mb: int) -> None:
    """A da Vinci printer on TCP 9100 and/or a raw pty that real clients cannot tell from the machine."""
    import asyncio

    from fabwire.simserve import serve
    from fabwire.xyz.sim import XYZSimulator

    sim = XYZSimulator(model_text, speed=speed, faults=faults, state_file=state_file, store=store, strict=strict,
                       link=None if link_style == "auto" else Link(link_style), control=not no_control,
                       max_upload=max_upload_mb << 20)
    started = time.monotonic()
    asyncio.run(serve("xyz", sim.serve, listen=listen, use_pty=use_pty, link=link,
                      default_port=XYZ.default_port, json_mode=app.json))
    app.output.note(f"xyz simulator stopped after {time.monotonic() - started:.0f} s, "
                    f"{sim.completed_uploads} upload(s)")
