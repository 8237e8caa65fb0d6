"""`fabwire service`: run `fabwire serve` as a systemd service, and udev rules for the USB machines.

`service install` writes a unit that starts the agent at boot (or at login with `--user`), restarts it when it
fails, keeps its history and access token in systemd's state directory and passes the listen address, devices,
MQTT and notification options on. `service udev` writes rules that give the da Vinci printers and the MMU stable
`/dev/` names and let the `dialout` group open them; `USB_DEVICES` is the table of what is matched.
"""

from __future__ import annotations

import getpass
import os
import re
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import click

from fabwire import __version__
from fabwire.errors import InputError

UNIT_NAME = "fabwire.service"
SYSTEM_UNIT_DIR = Path("/etc/systemd/system")
UDEV_RULES = Path("/etc/udev/rules.d/70-fabwire.rules")
"""Before ModemManager's 77/80 rules, so its probing (which garbles a printer's link) is switched off in time."""
SERIAL_GROUP = "dialout"
"""The group that owns serial ports on Debian and Raspberry Pi OS."""
DEFAULT_LISTEN = "0.0.0.0:8765"
"""A service is there to be reached from the network; the access token is then always required."""
STOP_TIMEOUT_S = 45
"""systemd's wait for a clean stop: the agent gives a cancelled job 30 s to stop on its machine."""


@dataclass(frozen=True, slots=True)
class UsbDevice:
    kind: str
    vendor: int
    product: int | None
    """None: every product of the vendor."""
    what: str
    link: str
    """The stable name under /dev/, with udev's substitutions (`%s{serial}` is the USB serial number)."""
    source: str


USB_DEVICES: tuple[UsbDevice, ...] = (
    UsbDevice("xyz", 0x11F1, None, "XYZprinting da Vinci printers (every model: the vendor id)", "davinci-%s{serial}",
              "XYZprinting's USB vendor id: guysoft/OctoPi#218 dmesg of a da Vinci 1.0 Pro (11f1:2520) and a "
              "USB capture of XYZprint with a da Vinci nano (VID_11F1&PID_2519)"),
    UsbDevice("mmu", 0x2C99, 0x0004, "Prusa MMU2S/MMU3 (its firmware's USB serial port)", "prusa-mmu",
              "Prusa Research's vendor id 2c99, product 0004: prusa3d/MM-control-01 README, ModemManager rules"),
    UsbDevice("mmu", 0x2C99, 0x0003, "Prusa MMU2S/MMU3 bootloader (Caterina, a few seconds after reset)",
              "prusa-mmu-bootloader", "prusa3d/MM-control-01 README (2c99:0003), prusa3d/caterina"),
)


def udev_rules() -> str:
    """The rules file: each row of `USB_DEVICES` as one rule on the tty it creates."""
    lines = [f"# fabwire {__version__}: stable names and {SERIAL_GROUP} access for USB machines "
             "(`fabwire service udev` writes this file).",
             "# Then: sudo udevadm control --reload-rules && sudo udevadm trigger --subsystem-match=tty", ""]
    for device in USB_DEVICES:
        match = f'SUBSYSTEM=="tty", ATTRS{{idVendor}}=="{device.vendor:04x}"'
        if device.product is not None:
            match += f', ATTRS{{idProduct}}=="{device.product:04x}"'
        lines.append(f"# {device.what}")
        lines.append(f'{match}, GROUP="{SERIAL_GROUP}", MODE="0660", ENV{{ID_MM_DEVICE_IGNORE}}="1", '
                     f'SYMLINK+="{device.link}"')
    return "\n".join(lines) + "\n"


_PLAIN = re.compile(r"^[A-Za-z0-9_@+=:,./-]+$")


class Specifier(str):
    """An argument that holds a systemd specifier on purpose (`%S/fabwire`): written as it is."""

    __slots__ = ()


def systemd_word(text: str) -> str:
    """One ExecStart= argument as systemd reads it: quoted when needed, `%` and `$` escaped (systemd.service(5),
    "Command lines"; systemd.unit(5), "Specifiers"). InputError for control characters no unit can hold."""
    if any(ord(c) < 32 or ord(c) == 127 for c in text):
        raise InputError(f"{text[:40]!r} holds a control character, which a systemd unit cannot carry")
    if isinstance(text, Specifier):
        return str(text)
    escaped = text.replace("%", "%%").replace("$", "$$")
    if text and _PLAIN.match(text):
        return escaped
    return '"' + escaped.replace("\\", "\\\\").replace('"', '\\"') + '"'


@dataclass(frozen=True, slots=True)
class ServiceSpec:
    user_mode: bool
    serve_args: tuple[str, ...]
    """Everything after `fabwire serve`."""
    run_as: str | None
    """System units: the account the agent runs as."""
    environment_file: Path | None
    python: str = sys.executable

    def unit(self) -> str:
        """The unit file's text (systemd.service(5), systemd.exec(5))."""
        command = " ".join(systemd_word(w) for w in (self.python, "-m", "fabwire", "serve", *self.serve_args))
        service = ["Type=exec", f"ExecStart={command}", "StateDirectory=fabwire", "StateDirectoryMode=0700",
                   "Restart=on-failure", "RestartSec=5",
                   "# exit code 4 is a usage error (a bad option or devices file): restarting would not mend it",
                   "RestartPreventExitStatus=4", f"TimeoutStopSec={STOP_TIMEOUT_S}", "Environment=PYTHONUNBUFFERED=1"]
        if self.environment_file is not None:
            service.append(f"EnvironmentFile={self.environment_file}")
        if not self.user_mode:
            service[1:1] = [f"User={self.run_as}", f"SupplementaryGroups={SERIAL_GROUP}"]
            service += ["NoNewPrivileges=yes", "ProtectSystem=full", "PrivateTmp=yes"]
        target = "default.target" if self.user_mode else "multi-user.target"
        return "\n".join([
            f"# Written by `fabwire service install` (fabwire {__version__}); run it again to change the options.",
            "[Unit]",
            "Description=fabwire agent: dashboard, API, MQTT and notifications for da Vinci printers, Line-us, MMU3",
            "Wants=network-online.target",
            "After=network-online.target",
            "",
            "[Service]",
            *service,
            "",
            "[Install]",
            f"WantedBy={target}",
            "",
        ])


def unit_dir(user_mode: bool) -> Path:
    if not user_mode:
        return SYSTEM_UNIT_DIR
    config = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(config) / "systemd" / "user"


def _state_dir(user_mode: bool) -> str:
    """Where systemd's StateDirectory= puts it (the `%S` specifier: /var/lib, or ~/.local/state for a user)."""
    if not user_mode:
        return "/var/lib/fabwire"
    state = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return f"{state}/fabwire"


def _write(path: Path, text: str, mode: int) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        path.chmod(mode)
    except PermissionError:
        raise InputError(f"cannot write {path}: permission denied (run with sudo, or install with --user)") from None
    except OSError as exc:
        raise InputError(f"cannot write {path}: {exc.strerror or exc}") from None


def serve_arguments(listen: str, state_dir: str, config: Path | None, devices: Sequence[str], mqtt: str | None,
                    mqtt_user: str | None, mqtt_tls: bool, notify: Sequence[str],
                    mqtt_discovery: str = "device") -> tuple[str, ...]:
    """The `fabwire serve` options for the unit, each checked as `serve` checks it."""
    from fabwire.agent.command import DEFAULT_PORT, parse_device_option
    from fabwire.simoptions import parse_listen

    parse_listen(listen, DEFAULT_PORT)
    args = ["--listen", listen, "--state-dir", state_dir]
    if config is not None:
        args += ["--config", str(config.expanduser().resolve())]
    for index, device in enumerate(devices, 1):
        parse_device_option(device, index)
        args += ["--device", device]
    if mqtt is not None:
        args += ["--mqtt", mqtt]
        if mqtt_user:
            args += ["--mqtt-user", mqtt_user]
        if mqtt_tls:
            args.append("--mqtt-tls")
        if mqtt_discovery != "device":
            args += ["--mqtt-discovery", mqtt_discovery]
    if notify:  # checked here, carried by the environment file: an Apprise URL holds its service's secrets
        from fabwire.agent.notify import check_urls

        check_urls(notify)
        for url in notify:
            if any(c.isspace() or c in '"\\' for c in url):
                scheme = url.partition("://")[0]  # the rest may hold the service's token
                raise InputError(f"--notify: a {scheme}:// URL with spaces, quotes or backslashes cannot go into "
                                 "the service's environment: percent-encode them")
    return tuple(args)


def secret_environment(mqtt_password: str | None, notify: Sequence[str]) -> str:
    """The environment file's text: what must not stand in a unit anyone may read (systemd.exec(5),
    EnvironmentFile=; `serve` reads FABWIRE_MQTT_PASSWORD and FABWIRE_NOTIFY, URLs separated by spaces)."""
    lines = []
    if mqtt_password:
        lines.append(f"FABWIRE_MQTT_PASSWORD={mqtt_password}\n")
    if notify:
        lines.append(f"FABWIRE_NOTIFY={' '.join(notify)}\n")
    return "".join(lines)


@click.group("service")
def service() -> None:
    """Run the agent (`fabwire serve`) as a systemd service, and give USB machines stable names."""


@service.command("install")
@click.option("--user", "user_mode", is_flag=True,
              help="A user service (~/.config/systemd/user), no root needed; starts at login, or at boot after "
                   "`loginctl enable-linger`.")
@click.option("--listen", default=DEFAULT_LISTEN, show_default=True, metavar="HOST:PORT",
              help="Where the dashboard and API listen (beyond loopback the access token is required).")
@click.option("--config", type=click.Path(dir_okay=False, path_type=Path), help="Named devices file.")
@click.option("--device", "devices", multiple=True, metavar="[NAME:]KIND=ADDRESS", help="A device to monitor.")
@click.option("--mqtt", "mqtt_url", metavar="URL", help="Also publish to this MQTT broker.")
@click.option("--mqtt-user", help="MQTT user name.")
@click.option("--mqtt-password", envvar="FABWIRE_MQTT_PASSWORD",
              help="MQTT password: kept in an environment file only root (or you, with --user) can read, not "
                   "in the unit.")
@click.option("--mqtt-tls", is_flag=True, help="Connect to the broker with TLS.")
@click.option("--mqtt-discovery", type=click.Choice(["device", "entity"]), default="device", show_default=True,
              help="Home Assistant discovery per machine (2024.11 or newer) or per entity (older).")
@click.option("--notify", multiple=True, metavar="URL", help="Apprise notification URL (repeatable).")
@click.option("--run-as", metavar="ACCOUNT", help="System service: the account it runs as (default: the one "
                                                  "that ran sudo, or yours).")
@click.option("--output", type=click.Path(dir_okay=False, allow_dash=True, path_type=Path),
              help="Write the unit here instead (`-` for standard output); nothing else is written.")
def install(user_mode: bool, listen: str, config: Path | None, devices: tuple[str, ...], mqtt_url: str | None,
            mqtt_user: str | None, mqtt_password: str | None, mqtt_tls: bool, mqtt_discovery: str,
            notify: tuple[str, ...], run_as: str | None, output: Path | None) -> None:
    """Write a systemd unit that runs `fabwire serve` at boot, restarts it on failure and keeps its state.

    As root, the system unit also comes with the udev rules (`fabwire service udev`). Then enable it with the
    commands printed at the end.
    """
    state_dir = Specifier("%S/fabwire")  # systemd's state directory for this unit, whoever runs it
    args = serve_arguments(listen, state_dir, config, devices, mqtt_url, mqtt_user, mqtt_tls, notify, mqtt_discovery)
    if user_mode and run_as:
        raise InputError("--run-as is for a system service; a --user service runs as you")
    account = run_as or os.environ.get("SUDO_USER") or getpass.getuser()
    secrets = secret_environment(mqtt_password, notify)
    env_path = (unit_dir(True).parent.parent / "fabwire" if user_mode else Path("/etc/fabwire")) / "service.env"
    env_file = env_path if secrets else None
    spec = ServiceSpec(user_mode, args, None if user_mode else account, env_file)
    if output is not None:
        if str(output) == "-":
            click.echo(spec.unit(), nl=False)
        else:
            _write(output, spec.unit(), 0o644)
            click.echo(f"wrote {output}", err=True)
        return
    if env_file is not None:
        _write(env_file, secrets, 0o600)
    elif env_path.exists():  # an earlier install's secrets, no longer meant to be used
        env_path.unlink()
        click.echo(f"removed {env_path} (no password or notification URL to keep)")
    path = unit_dir(user_mode) / UNIT_NAME
    _write(path, spec.unit(), 0o644)
    click.echo(f"wrote {path}")
    if env_file is not None:
        click.echo(f"wrote {env_file} (the MQTT password and notification URLs, readable only by its owner)")
    if not user_mode and os.geteuid() == 0:
        _write(UDEV_RULES, udev_rules(), 0o644)
        click.echo(f"wrote {UDEV_RULES}: USB printers appear as /dev/davinci-SERIAL, the MMU as /dev/prusa-mmu")
    click.echo(_next_steps(user_mode, account, listen))


def _next_steps(user_mode: bool, account: str, listen: str) -> str:
    from fabwire.agent.auth import TOKEN_FILE, is_loopback
    from fabwire.agent.command import DEFAULT_PORT
    from fabwire.simoptions import parse_listen

    ctl = "systemctl --user" if user_mode else "sudo systemctl"
    journal = "journalctl --user -u fabwire" if user_mode else "sudo journalctl -u fabwire"
    token = f"{_state_dir(user_mode)}/{TOKEN_FILE}"
    steps = ["", "Start it now and at every boot:", f"    {ctl} daemon-reload && {ctl} enable --now fabwire"]
    if user_mode:
        steps += ["    loginctl enable-linger   # run without anyone logged in",
                  f"    sudo usermod -aG {SERIAL_GROUP} $USER   # USB printers and the MMU (log in again after)",
                  "    sudo fabwire service udev   # stable /dev names for them"]
    steps += ["", f"Its log: {journal} -f"]
    address = parse_listen(listen, DEFAULT_PORT)
    if not is_loopback(address.host):
        reader = "cat" if user_mode else "sudo cat"
        steps += ["", "The dashboard asks for the access token, made at the first start:",
                  f"    {reader} {token}", f"(also shown once in the log: {journal} | grep 'access token')"]
    if not user_mode and account == "root":
        steps += ["", "It runs as root: give --run-as ACCOUNT to run it as an ordinary user."]
    return "\n".join(steps)


@service.command("udev")
@click.option("--output", type=click.Path(dir_okay=False, allow_dash=True, path_type=Path),
              default=str(UDEV_RULES), show_default=True, help="Where to write the rules (`-` for standard output).")
def udev(output: Path) -> None:
    """Write udev rules: da Vinci printers as /dev/davinci-SERIAL, the MMU as /dev/prusa-mmu, group dialout."""
    if str(output) == "-":
        click.echo(udev_rules(), nl=False)
        return
    _write(output, udev_rules(), 0o644)
    click.echo(f"wrote {output}\nThen: sudo udevadm control --reload-rules && sudo udevadm trigger "
               "--subsystem-match=tty")
