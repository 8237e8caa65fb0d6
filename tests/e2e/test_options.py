"""Shared options work before or after the subcommand, and configured devices are honoured by every command."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from clitools import cli_env, run_cli
from fabwire.errors import ConfigError

XYZ_SIM = "sim://xyz?speed=1000"
MMU_SIM = "sim://mmu?speed=50"


@pytest.mark.parametrize("args", [
    ["xyz", "status", "-d", XYZ_SIM, "--json"],
    ["--json", "xyz", "-d", XYZ_SIM, "status"],
    ["-d", XYZ_SIM, "xyz", "status", "--json"],
    ["xyz", "--json", "status", "--device", XYZ_SIM],
], ids=["after", "before", "root", "mixed"])
def test_device_and_json_anywhere(args: list[str], tmp_path: Path) -> None:
    result = run_cli(*args, env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    status = json.loads(result.stdout)
    assert "state" in status or "state_code" in status


@pytest.mark.parametrize("args", [
    ["mmu", "--speed", "50", "-d", MMU_SIM, "version", "--json"],
    ["mmu", "version", "--speed", "50", "-d", MMU_SIM, "--json"],
    ["--json", "mmu", "-d", MMU_SIM, "version", "--speed", "50"],
    ["--speed", "50", "mmu", "-d", MMU_SIM, "version", "--json"],
    ["--accept", "3.0.4", "--json", "mmu", "--speed", "50", "-d", MMU_SIM, "version"],
], ids=["group", "command", "split", "root", "root-and-group"])
def test_a_device_link_option_anywhere(args: list[str], tmp_path: Path) -> None:
    result = run_cli(*args, env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["major"] == 3


@pytest.mark.parametrize("where", [0, 1, 4], ids=["root", "group", "command"])
def test_a_link_option_before_the_device_group_reaches_the_link(where: int, tmp_path: Path) -> None:
    command = ["mmu", "-d", MMU_SIM, "version"]
    result = run_cli(*command[:where], "--accept", "3.0.2", *command[where:], env=cli_env(tmp_path))
    assert result.returncode == 7  # the simulator's 3.0.4 is refused: the option was used
    assert "MMU firmware 3.0.4" in result.stderr
    assert "is not one of 3.0.2" in result.stderr


@pytest.mark.parametrize(("accept", "words"), [
    ("9.9.9", "MMU firmware 3.x.x is not one of 9.9.9"),  # the major part already differs: the rest is not read
    ("3.1.0", "MMU firmware 3.0.x is not one of 3.1.0"),
    ("banana", "'accept[0]': expected text of the right form (such as '3.0.3')"),
])
def test_a_refused_firmware_or_a_malformed_version_is_said_plainly(accept: str, words: str, tmp_path: Path) -> None:
    result = run_cli("mmu", "-d", MMU_SIM, "--accept", accept, "version", env=cli_env(tmp_path))
    assert result.returncode in (4, 7)
    assert words in result.stderr
    assert "regex" not in result.stderr


@pytest.mark.parametrize(("args", "message"), [
    (["--speed", "50", "xyz", "-d", XYZ_SIM, "status"], "--speed is a link option of `fabwire mmu`; it does not "
                                                         "apply to `fabwire xyz`"),
    (["--accept", "3.0.4", "lineus", "-d", "sim://lineus?speed=inf", "position"], "--accept is a link option of "
                                                                                  "`fabwire mmu`"),
    (["--speed", "50", "sim", "mmu", "--listen", "127.0.0.1:0"], "a simulator's own options go after its name"),
])
def test_a_link_option_before_another_command_says_where_it_belongs(args: list[str], message: str,
                                                                    tmp_path: Path) -> None:
    result = run_cli(*args, env=cli_env(tmp_path), timeout=30)
    assert result.returncode == 2
    assert message in result.stderr
    assert "Traceback" not in result.stderr
    assert result.stdout == ""


def test_the_mmu_speed_from_the_environment_leaves_other_devices_alone(tmp_path: Path) -> None:
    env = cli_env(tmp_path)
    env["FABWIRE_MMU_SPEED"] = "50"
    result = run_cli("xyz", "status", "-d", XYZ_SIM, "--json", env=env)
    assert result.returncode == 0, result.stderr
    assert "state" in json.loads(result.stdout) or "state_code" in json.loads(result.stdout)


def test_the_last_occurrence_wins_and_verbose_adds_up(tmp_path: Path) -> None:
    result = run_cli("-d", "sim://nothing", "lineus", "-v", "position", "-d", "sim://lineus?speed=inf", "--json",
                     env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["pen"] == "up"
    assert "connecting to sim://lineus" in result.stderr  # -v logs the connect


def test_trace_and_timeout_after_the_subcommand(tmp_path: Path) -> None:
    trace = tmp_path / "wire.jsonl"
    result = run_cli("lineus", "position", "-d", "sim://lineus?speed=inf", "--trace", str(trace), "--timeout", "3",
                     env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    assert "M114" in trace.read_text()


def config_env(tmp_path: Path, text: str) -> dict[str, str]:
    path = tmp_path / "devices.toml"
    path.write_text(text)
    env = cli_env()
    env["FABWIRE_CONFIG"] = str(path)
    return env


def test_a_misspelt_device_name_suggests_the_configured_one(tmp_path: Path) -> None:
    env = config_env(tmp_path, '[devices.office]\nkind = "xyz"\nurl = "sim://xyz"\n')
    result = run_cli("xyz", "status", "-d", "offfice", env=env)
    assert result.returncode == ConfigError.exit_code
    assert result.stderr.strip() == "fabwire: error: no device named 'offfice' (did you mean 'office'?)"


def test_configured_settings_reach_the_command(tmp_path: Path) -> None:
    """The file's speed 50 shrinks the host's timeouts 50-fold, too short for a simulator at real speed;
    the command line's --speed 1 overrides it."""
    env = config_env(tmp_path, '[devices.bench]\nkind = "mmu"\nurl = "sim://mmu"\nspeed = 50\ndefault = true\n')
    hurried = run_cli("mmu", "version", env=env)
    assert hurried.returncode != 0
    assert "within 0.04 s" in hurried.stderr
    result = run_cli("mmu", "version", "--json", "--speed", "1", env=env)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["minor"] == 0


def test_a_config_error_is_one_line_with_the_fix(tmp_path: Path) -> None:
    env = config_env(tmp_path, '[devices.office]\nkind = "xyz"\nurl = "sim://xyz"\ndefualt = true\n')
    result = run_cli("xyz", "status", env=env)
    assert result.returncode == ConfigError.exit_code
    assert result.stderr.count("\n") == 1
    assert "unknown key 'defualt' (did you mean 'default'?)" in result.stderr


def test_the_zoffset_is_typed_in_millimetres(tmp_path: Path) -> None:
    result = run_cli("xyz", "zoffset", "-0.12mm", "-d", XYZ_SIM, "--json", env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == {"zoffset_mm": -0.12}
    shown = run_cli("xyz", "zoffset", "2.45", "-d", XYZ_SIM, env=cli_env(tmp_path))
    assert shown.stdout.strip() == "z offset 2.45 mm"
    bad = run_cli("xyz", "zoffset", "2.45cm", "-d", XYZ_SIM, env=cli_env(tmp_path))
    assert bad.returncode == 4
    assert "z offset must be millimetres" in bad.stderr


@pytest.mark.parametrize(("typed", "meant"), [(["xzy"], "xyz"), (["sevre"], "serve"), (["lineus", "drw"], "draw"),
                                              (["xyz", "stauts"], "status"), (["devics"], "devices")])
def test_a_misspelt_command_gets_a_suggestion_at_every_level(typed: list[str], meant: str) -> None:
    result = run_cli(*typed, timeout=60)
    assert result.returncode == 2
    assert f"Did you mean '{meant}'?" in result.stderr
