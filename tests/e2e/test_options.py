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
], ids=["group", "command", "split"])
def test_a_device_link_option_anywhere(args: list[str], tmp_path: Path) -> None:
    result = run_cli(*args, env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["major"] == 3


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
    assert json.loads(result.stdout) == {"zoffset": -12}
    shown = run_cli("xyz", "zoffset", "2.45", "-d", XYZ_SIM, env=cli_env(tmp_path))
    assert shown.stdout.strip() == "z offset 2.45 mm"
    bad = run_cli("xyz", "zoffset", "2.45cm", "-d", XYZ_SIM, env=cli_env(tmp_path))
    assert bad.returncode == 4
    assert "z offset must be millimetres" in bad.stderr
