"""Named devices from the TOML config file: good files resolve, bad ones name file, line and problem."""

from __future__ import annotations

from pathlib import Path

import pytest

from fabwire.config import load_devices, resolve_target
from fabwire.devices import LINEUS, MMU, XYZ
from fabwire.errors import ConfigError
from fabwire.transport import Endpoint

GOOD = """
[devices.office]
kind = "xyz"
url = "192.168.1.50"
default = true
model = "miniMaker"

[devices.bench]
kind = "xyz"
url = "/dev/ttyACM0"

[devices.arm]
kind = "lineus"
url = "line-us.local"
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "devices.toml"
    path.write_text(text)
    return path


def test_good_file_resolves_names_and_defaults(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD)
    devices = load_devices(path)
    assert set(devices) == {"office", "bench", "arm"}
    assert devices["office"].options == {"model": "miniMaker"}
    office = resolve_target("office", XYZ, path)
    assert office.endpoint == Endpoint("tcp", host="192.168.1.50", port=9100)
    assert office.name == "office"
    assert resolve_target(None, XYZ, path).name == "office"  # the default one
    assert resolve_target(None, LINEUS, path).endpoint.port == 1337  # the only one of its kind
    assert resolve_target("bench", XYZ, path).endpoint == Endpoint("serial", path="/dev/ttyACM0")


def test_addresses_bypass_the_file(tmp_path: Path) -> None:
    path = write(tmp_path, "this is not toml")
    assert resolve_target("10.0.0.9:9100", XYZ, path).endpoint.host == "10.0.0.9"
    assert resolve_target("sim://xyz", XYZ, path).endpoint.scheme == "sim"


def test_missing_file_means_no_devices(tmp_path: Path) -> None:
    assert load_devices(tmp_path / "absent.toml") == {}
    with pytest.raises(ConfigError, match="pass -d ADDRESS"):
        resolve_target(None, MMU, tmp_path / "absent.toml")


def test_device_of_another_kind_is_refused(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD)
    with pytest.raises(ConfigError, match="'arm' is a Line-us, not a XYZprinting"):
        resolve_target("arm", XYZ, path)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("[devices.x]\nkind = \n", "not valid TOML: .*line 2"),
        ("[printers.x]\nkind='xyz'\n", "unknown top-level key"),
        ("\n\n[devices.x]\nkind = 'toaster'\nurl='a'\n", "line 3: device 'x': 'kind' must be one of"),
        ("[devices.x]\nkind = 'xyz'\n", "line 1: device 'x': 'url' must be a string"),
        ("[devices.x]\nkind = 'xyz'\nurl = 'ftp://a'\n", "unknown scheme"),
        ("[devices.x]\nkind = 'mmu'\nurl = 'a'\n", "no default TCP port"),
        ("[devices.x]\nkind = 'xyz'\nurl = 'a'\ndefault = 'yes'\n", "'default' must be true or false"),
        ("[devices.x]\nkind = 'xyz'\nurl = 'a'\nspeeds = [1]\n", "option 'speeds' must be"),
        ("devices = 3\n", "must be a table"),
    ],
)
def test_bad_files_name_file_line_and_problem(tmp_path: Path, text: str, problem: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError, match=problem) as info:
        load_devices(path)
    assert str(path) in str(info.value)
