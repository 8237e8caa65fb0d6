"""`fabwire devices list|show|add|remove` edit devices.toml in place, validated, and the names work at once."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from clitools import cli_env, run_cli
from fabwire.errors import ConfigError, InputError


def env_for(path: Path) -> dict[str, str]:
    env = cli_env()
    env["FABWIRE_CONFIG"] = str(path)
    return env


def test_add_list_show_use_and_remove(tmp_path: Path) -> None:
    path = tmp_path / "conf" / "devices.toml"
    env = env_for(path)
    assert run_cli("devices", "list", "--json", env=env).stdout.strip() == "[]"
    added = run_cli("devices", "add", "bench", "sim://mmu?speed=50", "--kind", "mmu", "--default",
                    "--set", "speed=50", "--set", 'accept=["3.0.4"]', env=env)
    assert added.returncode == 0, added.stderr
    assert run_cli("devices", "add", "arm", "sim://lineus?speed=inf", "--kind", "lineus", env=env).returncode == 0
    rows = json.loads(run_cli("devices", "list", "--json", env=env).stdout)
    assert rows == [{"name": "bench", "kind": "mmu", "url": "sim://mmu?speed=50", "default": True},
                    {"name": "arm", "kind": "lineus", "url": "sim://lineus?speed=inf", "default": False}]
    shown = json.loads(run_cli("devices", "show", "bench", "--json", env=env).stdout)
    assert shown["speed"] == 50
    assert shown["accept"] == ["3.0.4"]
    assert shown["auto_retries"] == 3  # the schema's default, shown
    version = run_cli("mmu", "version", "--json", env=env)  # the default MMU, at its configured speed
    assert version.returncode == 0, version.stderr
    assert run_cli("lineus", "-d", "arm", "position", env=env).returncode == 0
    assert run_cli("devices", "remove", "bench", env=env).returncode == 0
    assert [r["name"] for r in json.loads(run_cli("devices", "list", "--json", env=env).stdout)] == ["arm"]


def test_edits_keep_the_users_comments(tmp_path: Path) -> None:
    path = tmp_path / "devices.toml"
    path.write_text("# my printers\n[devices.office]  # upstairs\nkind = \"xyz\"\nurl = \"10.0.0.5\"\n\n"
                    "# the old one\n[devices.garage]\nkind = \"xyz\"\nurl = \"10.0.0.6\"\n")
    env = env_for(path)
    assert run_cli("devices", "add", "bench", "/dev/ttyACM0", "--kind", "xyz", env=env).returncode == 0
    assert run_cli("devices", "remove", "office", env=env).returncode == 0
    text = path.read_text()
    assert text.startswith("# my printers\n")
    assert "# the old one\n[devices.garage]" in text
    assert "office" not in text
    assert '[devices.bench]\nkind = "xyz"\nurl = "/dev/ttyACM0"\n' in text


def test_bad_edits_are_refused_and_leave_the_file_alone(tmp_path: Path) -> None:
    path = tmp_path / "devices.toml"
    path.write_text('[devices.office]\nkind = "xyz"\nurl = "10.0.0.5"\ndefault = true\n')
    before = path.read_text()
    env = env_for(path)
    second = run_cli("devices", "add", "garage", "10.0.0.6", "--kind", "xyz", "--default", env=env)
    assert second.returncode == ConfigError.exit_code
    assert second.stderr.strip() == ("fabwire: error: 'office' is the default XYZprinting da Vinci already: add "
                                     "'garage' without --default, then `fabwire devices default garage`")
    typo = run_cli("devices", "add", "bench", "sim://mmu", "--kind", "mmu", "--set", "sped=5", env=env)
    assert typo.returncode == InputError.exit_code
    assert "no setting 'sped' (did you mean 'speed'?)" in typo.stderr
    bad_value = run_cli("devices", "add", "bench", "sim://mmu", "--kind", "mmu", "--set", "speed=fast", env=env)
    assert bad_value.returncode == InputError.exit_code  # a bad --set is bad input, like a misspelt one
    assert "'speed': expected a number" in bad_value.stderr
    gone = run_cli("devices", "remove", "ofice", env=env)
    assert gone.returncode == ConfigError.exit_code
    assert "(did you mean 'office'?)" in gone.stderr
    assert path.read_text() == before


def test_an_endless_config_or_text_that_is_not_utf8_is_one_line_of_error(tmp_path: Path) -> None:
    env = env_for(Path("/dev/zero"))
    for args in (("devices", "list"), ("devices", "add", "z", "1.2.3.4", "--kind", "xyz"), ("devices", "remove", "z")):
        done = run_cli(*args, env=env)
        assert (done.returncode, done.stdout) == (ConfigError.exit_code, "")
        assert done.stderr.strip().splitlines() == [
            "fabwire: error: /dev/zero: over 4 MiB, too large for a config file"]
    path = tmp_path / "devices.toml"
    for args in (("b", "1.2.3.4", "--set", os.fsdecode(b"model=\xff")), (os.fsdecode(b"n\xff"), "1.2.3.4")):
        done = run_cli("devices", "add", *args, "--kind", "xyz", env=env_for(path))
        assert (done.returncode, done.stdout) == (InputError.exit_code, "")
        assert done.stderr.count("\n") == 1
        assert "is not valid text" in done.stderr
        assert not path.exists()


@pytest.mark.parametrize(("setting", "accepted"), [
    ("accept=3.0.3", ["3.0.3"]),
    ("accept=3.0.3,3.0.4", ["3.0.3", "3.0.4"]),
    ("accept= 3.0.3 , 3.0.4 ", ["3.0.3", "3.0.4"]),
    ('accept=["3.0.3", "3.0.4"]', ["3.0.3", "3.0.4"]),
])
def test_a_list_setting_is_given_as_items_separated_by_commas_or_as_a_toml_list(
        tmp_path: Path, setting: str, accepted: list[str]) -> None:
    path = tmp_path / "devices.toml"
    added = run_cli("devices", "add", "bench", "/dev/ttyACM0", "--kind", "mmu", "--set", setting, env=env_for(path))
    assert added.returncode == 0, added.stderr
    assert json.loads(run_cli("devices", "show", "bench", "--json", env=env_for(path)).stdout)["accept"] == accepted


def test_the_help_of_add_shows_how_a_list_is_given(tmp_path: Path) -> None:
    shown = run_cli("devices", "add", "--help", env=env_for(tmp_path / "devices.toml"))
    assert "accept=3.0.3,3.0.4" in " ".join(shown.stdout.split())


def test_a_malformed_item_of_a_list_setting_is_named_with_an_example(tmp_path: Path) -> None:
    path = tmp_path / "devices.toml"
    refused = run_cli("devices", "add", "bench", "/dev/ttyACM0", "--kind", "mmu", "--set", "accept=3.0.3,3.0",
                      env=env_for(path))
    assert refused.returncode == InputError.exit_code
    assert refused.stderr == ("fabwire: error: Prusa MMU3: 'accept[1]': expected text of the right form "
                              "(such as '3.0.3')\n")
    assert not path.exists()


def test_a_bad_setting_is_refused_before_it_is_written(tmp_path: Path) -> None:
    path = tmp_path / "devices.toml"
    for setting, words in (("reply_timeout=-5", "'reply_timeout': expected a number above 0"),
                           ("reply_timout=5", "has no setting 'reply_timout' (did you mean 'reply_timeout'?)")):
        refused = run_cli("devices", "add", "bad", "127.0.0.1", "--kind", "xyz", "--set", setting, env=env_for(path))
        assert refused.returncode == InputError.exit_code
        assert words in refused.stderr
        assert "line" not in refused.stderr
        assert not path.exists()


def test_a_config_file_that_cannot_be_written_is_one_line_of_error(tmp_path: Path) -> None:
    for path in (Path("/proc/nope/devices.toml"), Path("/proc/self/devices.toml")):
        done = run_cli("devices", "add", "z", "127.0.0.1", "--kind", "xyz", env=env_for(path))
        assert done.returncode == ConfigError.exit_code
        assert done.stderr.startswith(f"fabwire: error: cannot write the config file {path}: ")
        assert done.stderr.count("\n") == 1


def test_the_broken_entry_itself_can_be_removed(tmp_path: Path) -> None:
    path = tmp_path / "devices.toml"
    path.write_text('[devices.good]\nkind = "xyz"\nurl = "127.0.0.1"\n\n'
                    '[devices.bad]\nkind = "xyz"\nurl = "127.0.0.1"\ndefualt = true\n')
    env = env_for(path)
    broken = run_cli("devices", "list", env=env)
    assert broken.returncode == ConfigError.exit_code
    assert "line 8: device 'bad': unknown key 'defualt' (did you mean 'default'?)" in broken.stderr
    assert run_cli("devices", "remove", "bad", env=env).returncode == 0
    assert json.loads(run_cli("devices", "list", "--json", env=env).stdout) == [
        {"name": "good", "kind": "xyz", "url": "127.0.0.1", "default": False}]
    missing = run_cli("devices", "remove", "bda", env=env)
    assert missing.returncode == ConfigError.exit_code
    assert "no device named 'bda'" in missing.stderr


def test_show_prints_the_entry_as_toml_that_reads_back(tmp_path: Path) -> None:
    import tomllib

    env = env_for(tmp_path / "devices.toml")
    added = run_cli("devices", "add", "office", "192.168.1.50", "--kind", "xyz", "--set", "link=wifi", env=env)
    assert added.returncode == 0, added.stderr
    shown = run_cli("devices", "show", "office", env=env)
    assert shown.returncode == 0, shown.stderr
    entry = tomllib.loads(shown.stdout)["devices"]["office"]
    assert entry == {"kind": "xyz", "url": "192.168.1.50", "default": False, "link": "wifi", "timeout": 5.0}
    assert "# reply_timeout: not set" in shown.stdout.splitlines()
    lines = shown.stdout.splitlines()  # what the file sets is told apart from a default
    assert 'link = "wifi"' in lines
    assert "timeout = 5.0  # default" in lines
    assert "default = false  # default" in lines


def test_a_name_that_reads_as_an_address_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "devices.toml"
    env = env_for(path)
    for name in ("127.0.0.1", "::1", "10.0.0.5:9100", "tcp://office", "/dev/ttyUSB0"):
        result = run_cli("devices", "add", name, "127.0.0.1:1", "--kind", "xyz", env=env)
        assert result.returncode == InputError.exit_code, name
        assert "reads as an address" in result.stderr
    assert not path.exists()
    kept = run_cli("devices", "add", "lab.mini", "127.0.0.1:9100", "--kind", "xyz", env=env)
    assert kept.returncode == 0, kept.stderr


@pytest.mark.parametrize(("args", "said"), [
    (["x6", "bad url with spaces", "--kind", "xyz"], "malformed device address 'bad url with spaces'"),
    (["x7", "127.0.0.1", "--kind", "xyz", "--set", "model=no such"], "unknown printer model 'no such'"),
    (["x8", "127.0.0.1", "--kind", "xyz", "--set", "model=mini\nw"], "model: "),
])
def test_an_entry_that_cannot_work_is_refused_before_the_file_is_touched(args: list[str], said: str,
                                                                          tmp_path: Path) -> None:
    path = tmp_path / "devices.toml"
    env = env_for(path)
    assert run_cli("devices", "add", "first", "127.0.0.1", "--kind", "xyz", env=env).returncode == 0
    before = path.read_bytes()
    refused = run_cli("devices", "add", *args, env=env)
    assert refused.returncode == InputError.exit_code, refused.stderr
    assert said in refused.stderr
    assert ", line " not in refused.stderr  # the file has no such line: the entry was never written
    assert path.read_bytes() == before


@pytest.mark.parametrize(("first", "second"), [
    ("printer.local", "tcp://printer.local"), ("printer.local", "PRINTER.LOCAL:9100"),
    ("printer.local", "printer.local."), ("127.0.0.7", "127.0.0.7:9100"), ("127.0.0.7", " 127.0.0.7 "),
])
def test_a_machine_already_named_is_not_named_again(tmp_path: Path, first: str, second: str) -> None:
    """`fabwire serve` monitors each machine once: `devices add` refuses the second name before the file changes."""
    path = tmp_path / "devices.toml"
    env = env_for(path)
    assert run_cli("devices", "add", "office", first, "--kind", "xyz", env=env).returncode == 0
    before = path.read_text()
    again = run_cli("devices", "add", "desk", second, "--kind", "xyz", env=env)
    assert again.returncode == InputError.exit_code, again.stdout
    assert "'office' names already" in again.stderr
    assert path.read_text() == before
    assert run_cli("devices", "add", "arm", second, "--kind", "lineus", env=env).returncode == 0  # another kind


@pytest.mark.parametrize(("kind", "address", "stored"), [("xyz", " 127.0.0.7\t", "127.0.0.7"),
                                                         ("xyz", "127.0.0.7:9100\r\n", "127.0.0.7:9100"),
                                                         ("mmu", "COM3", "COM3")])
def test_an_address_is_kept_as_it_is_read_and_serve_takes_it(tmp_path: Path, kind: str, address: str,
                                                             stored: str) -> None:
    path = tmp_path / "devices.toml"
    env = env_for(path)
    added = run_cli("devices", "add", "bench", address, "--kind", kind, env=env)
    assert added.returncode == 0, added.stderr
    assert f'url = "{stored}"' in path.read_text()
    from fabwire.config import load_devices
    from fabwire.transport.urls import parse_url

    device = load_devices(path)["bench"]
    assert parse_url(device.endpoint.url, device.kind) == device.endpoint  # what serve reads back


def test_the_default_moves_to_another_device_of_its_kind_and_comments_stay(tmp_path: Path) -> None:
    path = tmp_path / "devices.toml"
    path.write_text('# printers\n[devices.office]  # upstairs\nkind = "xyz"\nurl = "10.0.0.5"\ndefault = true  # old\n'
                    '\n[devices.garage]\nkind = "xyz"\nurl = "10.0.0.6"\n\n'
                    '[devices.arm]\nkind = "lineus"\nurl = "10.0.0.7"\ndefault = true\n')
    env = env_for(path)
    moved = run_cli("devices", "default", "garage", env=env)
    assert moved.returncode == 0, moved.stderr
    assert moved.stdout.strip() == "garage is now the default XYZprinting da Vinci (was office)"
    rows = {r["name"]: r["default"] for r in json.loads(run_cli("devices", "list", "--json", env=env).stdout)}
    assert rows == {"office": False, "garage": True, "arm": True}  # the Line-us keeps its own default
    text = path.read_text()
    assert text.startswith("# printers\n[devices.office]  # upstairs\n")
    assert '[devices.garage]\ndefault = true\nkind = "xyz"' in text
    again = run_cli("devices", "default", "garage", "--json", env=env)
    assert json.loads(again.stdout)["changed"] is False
    assert path.read_text() == text
    unknown = run_cli("devices", "default", "garag", env=env)
    assert unknown.returncode == ConfigError.exit_code
    assert "(did you mean 'garage'?)" in unknown.stderr
    assert path.read_text() == text
