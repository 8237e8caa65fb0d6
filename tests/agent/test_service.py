"""`fabwire service`: the systemd unit (checked by systemd's own `systemd-analyze verify`) and the udev rules."""

from __future__ import annotations

import os
import re
import shutil
import stat
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import pytest

from clitools import cli_env
from fabwire.service import USB_DEVICES, systemd_word, udev_rules


def fabwire(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "fabwire", *args], capture_output=True, text=True, timeout=60,
                          env=env or cli_env())


def systemd_analyze() -> str:
    found = shutil.which("systemd-analyze")
    if found is None:
        pytest.fail("the service tests need systemd's systemd-analyze: run scripts/ensure-system-packages")
    return found


def verify(unit: Path, *, user: bool) -> None:
    """systemd-analyze verify: exit 0 and not one warning (a wrong value is only warned about)."""
    # a user manager's runtime directory of its own, short enough for the socket paths of the units it loads
    with tempfile.TemporaryDirectory(prefix="rt-", dir="/tmp") as runtime:
        env = {**os.environ, "XDG_RUNTIME_DIR": runtime}
        run = subprocess.run([systemd_analyze(), *(["--user"] if user else []), "verify", str(unit)],
                             capture_output=True, text=True, timeout=60, env=env, cwd=unit.parent)
    assert run.returncode == 0, run.stderr
    assert run.stderr.strip() == "", run.stderr


OPTIONS = ("--mqtt", "mqtt://homeassistant.local", "--mqtt-user", "fabwire", "--mqtt-discovery", "entity",
           "--notify", "ntfy://my-bench",
           "--notify", "json://127.0.0.1:9/hook", "--device", "desk:xyz=192.168.1.50", "--listen", "0.0.0.0:8765")


@pytest.mark.parametrize("user", [False, True], ids=["system", "user"])
def test_the_unit_passes_systemd_verify(tmp_path: Path, user: bool) -> None:
    unit = tmp_path / "fabwire.service"
    run = fabwire("service", "install", *(["--user"] if user else ["--run-as", "root"]), *OPTIONS,
                  "--config", str(tmp_path / "my devices" / "100% devices.toml"), "--output", str(unit))
    assert run.returncode == 0, run.stderr
    text = unit.read_text()
    verify(unit, user=user)
    service = dict(line.split("=", 1) for line in text.splitlines() if "=" in line and not line.startswith("#"))
    assert service["Restart"] == "on-failure"
    assert service["StateDirectory"] == "fabwire"
    assert service["RestartPreventExitStatus"] == "4"
    assert service["WantedBy"] == ("default.target" if user else "multi-user.target")
    command = service["ExecStart"]
    assert command.startswith(f"{sys.executable} -m fabwire serve --listen 0.0.0.0:8765 --state-dir %S/fabwire ")
    assert "--mqtt mqtt://homeassistant.local --mqtt-user fabwire --mqtt-discovery entity" in command
    assert "--notify" not in command  # an Apprise URL holds its service's secrets: the environment file has them
    assert "EnvironmentFile=" in text
    assert f'--config "{tmp_path}/my devices/100%% devices.toml"' in command  # % is a specifier in a unit
    assert ("User" in service) is not user
    assert ("SupplementaryGroups" in service) is not user


WORDS = [  # (argument, how the unit must carry it): systemd.service(5) "Command lines", systemd.unit(5) "Specifiers"
    ("plain/path.toml", "plain/path.toml"),
    ("with space", '"with space"'),
    ("50%", "\"50%%\""),
    ("$HOME", '"$$HOME"'),
    ('say "hi"', '"say \\"hi\\""'),
    ("back\\slash", '"back\\\\slash"'),
    ("semi;colon", '"semi;colon"'),
    ("", '""'),
]


@pytest.mark.parametrize(("word", "written"), WORDS)
def test_arguments_are_quoted_as_systemd_reads_them(tmp_path: Path, word: str, written: str) -> None:
    assert systemd_word(word) == written
    unit = tmp_path / "fabwire.service"
    unit.write_text(f"[Service]\nExecStart={systemd_word(sys.executable)} -c pass {written}\n")
    verify(unit, user=False)


def test_a_control_character_cannot_go_into_a_unit() -> None:
    run = fabwire("service", "install", "--output", "-", "--device", "desk:xyz=a\nb")
    assert run.returncode == 4
    assert len(run.stderr.strip().splitlines()) == 1, run.stderr


def test_user_install_writes_the_unit_and_a_private_password_file(tmp_path: Path) -> None:
    env = {**cli_env(), "XDG_CONFIG_HOME": str(tmp_path / "config"), "XDG_STATE_HOME": str(tmp_path / "state"),
           "FABWIRE_MQTT_PASSWORD": "s3cret pass"}
    run = fabwire("service", "install", "--user", "--mqtt", "mqtt://broker", "--mqtt-user", "me", env=env)
    assert run.returncode == 0, run.stderr
    unit = tmp_path / "config" / "systemd" / "user" / "fabwire.service"
    secrets = tmp_path / "config" / "fabwire" / "service.env"
    assert f"EnvironmentFile={secrets}" in unit.read_text()
    assert "s3cret" not in unit.read_text()
    assert secrets.read_text() == "FABWIRE_MQTT_PASSWORD=s3cret pass\n"
    assert stat.S_IMODE(secrets.stat().st_mode) == 0o600
    verify(unit, user=True)
    assert "systemctl --user daemon-reload && systemctl --user enable --now fabwire" in run.stdout
    assert f"cat {tmp_path}/state/fabwire/access-token" in run.stdout  # how to read the token
    assert "loginctl enable-linger" in run.stdout
    again = fabwire("service", "install", "--user", "--notify", "tgram://123456:SECRETBOTTOKEN/987",
                    env={**env, "FABWIRE_MQTT_PASSWORD": ""})
    assert again.returncode == 0, again.stderr
    assert "SECRETBOTTOKEN" not in unit.read_text()
    assert secrets.read_text() == "FABWIRE_NOTIFY=tgram://123456:SECRETBOTTOKEN/987\n"  # the old password gone
    assert stat.S_IMODE(secrets.stat().st_mode) == 0o600
    verify(unit, user=True)
    fabwire("service", "install", "--user", env={**env, "FABWIRE_MQTT_PASSWORD": ""})
    assert not secrets.exists()  # nothing secret left to keep


@pytest.mark.parametrize(("args", "words"), [
    (("--listen", "0.0.0.0:99999"), "port must be a number"),
    (("--device", "toaster=1.2.3.4"), "--device takes"),
    (("--notify", "bogus://x"), "Apprise cannot send"),
    (("--user", "--run-as", "pi"), "--run-as is for a system service"),
])
def test_bad_options_are_one_line_and_exit_4(tmp_path: Path, args: tuple[str, ...], words: str) -> None:
    run = fabwire("service", "install", "--output", str(tmp_path / "unit"), *args)
    assert run.returncode == 4, run.stderr
    assert words in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert not (tmp_path / "unit").exists()


# ---------------------------------------------------------------------------------------------- udev rules

RULE_TERM = re.compile(r'\s*([A-Z_]+)(?:\{([^}]+)\})?\s*(==|!=|\+=|:=|=)\s*"([^"]*)"\s*(?:,|$)')


def parse_rules(text: str) -> list[list[tuple[str, str | None, str, str]]]:
    rules = []
    for line in text.splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        terms, at = [], 0
        while at < len(line):
            match = RULE_TERM.match(line, at)
            assert match is not None, f"not udev rule syntax at {line[at:]!r}"
            terms.append((match.group(1), match.group(2), match.group(3), match.group(4)))
            at = match.end()
        rules.append(terms)
    return rules


def apply_rules(text: str, subsystem: str, parents: dict[str, str]) -> dict[str, Any]:
    """What udev(7) does with a tty whose USB parent has `parents` as attributes: the keys this file uses."""
    result: dict[str, Any] = {"SYMLINK": []}
    for terms in parse_rules(text):
        matched = True
        for key, attr, op, value in terms:
            if op == "==":
                seen = subsystem if key == "SUBSYSTEM" else parents.get(attr or "") if key == "ATTRS" else None
                assert key in ("SUBSYSTEM", "ATTRS"), key
                matched = matched and seen == value
        if not matched:
            continue
        for key, attr, op, value in terms:
            value = re.sub(r"%s\{(\w+)\}", lambda m: parents.get(m.group(1), ""), value)
            if key == "SYMLINK":
                assert op == "+="
                result["SYMLINK"].append(value)
            elif op == "=":
                result[f"{key}{{{attr}}}" if attr else key] = value
    return result


@pytest.mark.parametrize("device", USB_DEVICES, ids=[f"{d.vendor:04x}:{d.product or 0:04x}" for d in USB_DEVICES])
def test_each_usb_machine_gets_a_stable_name_and_group_access(device: Any) -> None:
    serial = "3F1AWPUS5TH5AQ0074"
    parents = {"idVendor": f"{device.vendor:04x}", "idProduct": f"{device.product or 0x2520:04x}", "serial": serial}
    done = apply_rules(udev_rules(), "tty", parents)
    assert done["SYMLINK"] == [device.link.replace("%s{serial}", serial)]
    assert done["GROUP"] == "dialout"
    assert done["MODE"] == "0660"
    assert done["ENV{ID_MM_DEVICE_IGNORE}"] == "1"  # ModemManager keeps its probes off the port


@pytest.mark.parametrize(("subsystem", "parents"), [
    ("tty", {"idVendor": "0403", "idProduct": "6001", "serial": "FTDI"}),  # someone else's adapter
    ("tty", {"idVendor": "2c99", "idProduct": "0001"}),  # a Prusa printer, not its MMU
    ("block", {"idVendor": "11f1", "idProduct": "2520"}),  # not a serial port
])
def test_other_devices_are_left_alone(subsystem: str, parents: dict[str, str]) -> None:
    assert apply_rules(udev_rules(), subsystem, parents) == {"SYMLINK": []}


def test_udev_command_writes_the_rules(tmp_path: Path) -> None:
    out = tmp_path / "70-fabwire.rules"
    run = fabwire("service", "udev", "--output", str(out))
    assert run.returncode == 0, run.stderr
    assert out.read_text() == udev_rules()
    assert "udevadm control --reload-rules" in run.stdout
