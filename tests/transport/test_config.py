"""Named devices from the TOML config file: good files resolve, bad ones name file, line and problem."""

from __future__ import annotations

from pathlib import Path

import pytest

from fabwire.config import MAX_CONFIG_BYTES, load_devices, resolve_target
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
    assert devices["office"].settings.link == "auto"  # the schema's default
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
    with pytest.raises(ConfigError, match="'arm' is a Line-us, not an XYZprinting"):
        resolve_target("arm", XYZ, path)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("[devices.x]\nkind = \n", "not valid TOML: .*line 2"),
        ("[printers.x]\nkind='xyz'\n", "unknown top-level key"),
        ("\n\n[devices.x]\nkind = 'toaster'\nurl='a'\n", "line 4: device 'x': 'kind' must be one of"),
        ("[devices.x]\nkind = 'xyz'\n", "line 1: device 'x': 'url' must be a non-empty string"),
        ("[devices.x]\nkind = 'xyz'\nurl = 'ftp://a'\n", "unknown scheme"),
        ("[devices.x]\nkind = 'mmu'\nurl = 'a'\n", "no default TCP port"),
        ("[devices.x]\nkind = 'xyz'\nurl = 'a'\ndefault = 'yes'\n", "'default': expected true or false, not text"),
        ("[devices.x]\nkind = 'mmu'\nurl = '/x'\nspeeds = [1]\n", r"unknown key 'speeds' \(did you mean 'speed'\?\)"),
        ("[devices.x]\nkind = 'xyz'\nurl = 'a'\ndefualt = 1\n", r"unknown key 'defualt' \(did you mean 'default'\?\)"),
        ("[devices.x]\nkind = 'mmu'\nurl = '/dev/x'\nspeed = 0\n", "'speed': expected a number at least 0.01"),
        ("[devices.x]\nkind = 'lineus'\nurl = 'a'\nlink = 'wifi'\n", "unknown key 'link'"),
        ("[devices.x]\nkind = 'xyz'\nurl = 'a'\nlink = 'usb'\n", "'link': expected one of 'auto', 'serial', 'wifi'"),
        ("[device.x]\nkind = 'xyz'\n", r"unknown top-level key 'device' \(did you mean 'devices'\?\)"),
        ("devices = 3\n", "must be a table"),
    ],
)
def test_bad_files_name_file_line_and_problem(tmp_path: Path, text: str, problem: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError, match=problem) as info:
        load_devices(path)
    assert str(path) in str(info.value)


OFFICE = "[devices.office]\nkind = \"xyz\"\nurl = \"192.168.1.50\"\n"
MMU_BENCH = "# the MMU on the bench\n[devices.bench]\nkind = 'mmu'\nurl = '/dev/ttyACM0'\n"


@pytest.mark.parametrize(("text", "line", "problem"), [
    (OFFICE + "defualt = true\n", 4, "unknown key 'defualt'"),
    (OFFICE + "\n# a comment\n  reply_timeout = -1\n", 6, "'reply_timeout'"),
    (OFFICE + "link = 'usb'\n\n" + MMU_BENCH, 4, "'link': expected one of"),
    (OFFICE + "\n" + MMU_BENCH + "speed = 2\naccept = ['3.0']\n", 10, "'accept[0]': expected text of the right form"),
    (OFFICE + "\n" + MMU_BENCH + "\"speed\" = 'fast'\n", 9, "'speed': expected a number, not text"),
    ("[devices.office]\nurl = '192.168.1.50'\n\nkind = 'xzy'\n", 4, "'kind' must be one of"),
    ("[devices.office]\nkind = 'xyz'\n\nurl = 'ftp://a'\n", 4, "unknown scheme"),
    ("[devices.office]\nkind = 'xyz'\n", 1, "'url' must be a non-empty string"),
    ("[devices]\n# one per line\noffice.kind = 'xyz'\noffice.url = 'a'\noffice.defualt = 1\n", 5, "'defualt'"),
    ("[devices]\n\noffice = { kind = 'xyz', url = 'a', lnk = 'wifi' }\n", 3, "unknown key 'lnk'"),
    ("devices.office.kind = 'xyz'\ndevices.office.url = 'a'\ndevices.office.timeout = 0\n", 3, "'timeout'"),
    ("[devices.\"the office\"]\nkind = 'xyz'\nurl = 'a'\n'model' = 3\n", 4, "'model'"),
], ids=["unknown-key", "indented-after-comment", "first-of-two", "second-of-two", "quoted-key", "kind",
        "url-scheme", "missing-url", "dotted-keys", "inline-table", "dotted-from-the-top", "quoted-name"])
def test_a_problem_names_the_line_of_the_key_at_fault(tmp_path: Path, text: str, line: int, problem: str) -> None:
    """The line in the message is the line of the key that is wrong (the section's own line only when the key
    is missing), however the entry is written: a [devices.NAME] section, dotted keys or an inline table."""
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_devices(path)
    message = str(info.value)
    assert message.startswith(f"{path}, line {line}: device "), message
    assert problem in message


def test_two_defaults_of_one_kind_is_an_error(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD.replace('url = "/dev/ttyACM0"', 'url = "/dev/ttyACM0"\ndefault = true'))
    with pytest.raises(ConfigError, match="'office' and 'bench' are both the default XYZprinting da Vinci"):
        load_devices(path)


def test_a_misspelt_name_is_not_looked_up_as_a_host(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD)
    with pytest.raises(ConfigError, match=r"no device named 'offfice' \(did you mean 'office'\?\)"):
        resolve_target("offfice", XYZ, path)
    assert resolve_target("printer.local", XYZ, path).endpoint.host == "printer.local"


@pytest.mark.parametrize(
    "text",
    [
        "[devices.x]\nkind = 'xyz'\nurl = 'a'\nmodel = " + "[" * 5000 + "]" * 5000 + "\n",
        "[devices.x]\nkind = 'xyz'\nurl = 'a'\nmodel = " + "{a=" * 3000 + "1" + "}" * 3000 + "\n",
        "[devices.x]\nkind = 'mmu'\nurl = '/dev/x'\nauto_retries = " + "9" * 5000 + "\n",
        "[devices.x]\nkind = 'mmu'\nurl = '/dev/x'\nspeed = 1e999999\n",
        "[devices.x]\nkind = 'xyz'\nurl = 'a'\nmodel = 12\n",
        "[devices.x]\nkind = 'xyz'\nurl = 'a'\ntimeout = 'soon'\n",
        "[devices.x]\nkind = 'mmu'\nurl = '/dev/x'\naccept = [[1]]\n",
        "[devices]\nx = 1\n",
        "devices = [1, 2]\n",
        "\x00\x01\x02",
    ],
    ids=["deep-arrays", "deep-tables", "huge-integer", "huge-float", "wrong-type", "string-for-number",
         "nested-list", "entry-not-a-table", "devices-not-a-table", "binary"],
)
def test_hostile_config_files_are_config_errors(tmp_path: Path, text: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_devices(path)
    assert str(path) in str(info.value)
    assert len(str(info.value)) < 400


def test_section_lines_are_found_for_every_device(tmp_path: Path) -> None:
    text = "".join(f"# printer {i}\n[devices.p{i}]\nkind = 'xyz'\nurl = '10.0.{i // 250}.{i % 250 + 1}'\n\n"
                   for i in range(2000))
    path = write(tmp_path, text + "[devices.bad]\nkind = 'xyz'\nurl = 'a'\nsped = 1\n")
    with pytest.raises(ConfigError, match=f"line {2000 * 5 + 4}: device 'bad'"):
        load_devices(path)
    devices = load_devices(write(tmp_path, text))
    assert len(devices) == 2000
    assert devices["p1999"].line == 1999 * 5 + 2


def test_an_endless_or_oversized_config_is_refused_after_a_bounded_read(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="too large for a config file"):
        load_devices(Path("/dev/zero"))
    path = tmp_path / "big.toml"
    path.write_text("# " + "x" * MAX_CONFIG_BYTES + "\n")
    with pytest.raises(ConfigError, match="too large for a config file"):
        load_devices(path)


def test_a_version_with_a_trailing_line_break_is_not_a_version(tmp_path: Path) -> None:
    path = write(tmp_path, "[devices.x]\nkind = 'mmu'\nurl = '/dev/x'\naccept = [\"3.0.3\\n\"]\n")
    with pytest.raises(ConfigError, match="accept"):
        load_devices(path)


@pytest.mark.parametrize(("schema_text", "words"), [
    ("speed = 1e300", "'speed': expected a number at most 10000"),
    ("speed = 'fast'", "'speed': expected a number, not text"),
    ("auto_retries = -1", "'auto_retries': expected a whole number at least 0"),
])
def test_a_bad_setting_is_described_in_words_not_in_schema_types(tmp_path: Path, schema_text: str,
                                                                 words: str) -> None:
    path = tmp_path / "devices.toml"
    path.write_text(f"[devices.x]\nkind = 'mmu'\nurl = '/dev/x'\n{schema_text}\n")
    with pytest.raises(ConfigError) as caught:
        load_devices(path)
    assert words in str(caught.value)
    assert "`" not in str(caught.value)
