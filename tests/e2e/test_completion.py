"""`fabwire completion SHELL` prints a working script; completion offers commands and configured device names."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from clitools import cli_env, run_cli


@pytest.mark.parametrize(("shell", "marker"), [("bash", "complete -o nosort -F"), ("zsh", "#compdef fabwire"),
                                               ("fish", "complete --no-files --command fabwire")])
def test_scripts_for_each_shell(shell: str, marker: str) -> None:
    result = run_cli("completion", shell)
    assert result.returncode == 0, result.stderr
    assert marker in result.stdout
    assert "_FABWIRE_COMPLETE" in result.stdout


def complete(words: str, tmp_path: Path) -> list[str]:
    config = tmp_path / "devices.toml"
    config.write_text('[devices.office]\nkind = "xyz"\nurl = "10.0.0.5"\n[devices.basement]\nkind = "xyz"\n'
                      'url = "10.0.0.6"\n[devices.bench]\nkind = "mmu"\nurl = "/dev/ttyACM0"\n')
    env = cli_env()
    env.update(FABWIRE_CONFIG=str(config), _FABWIRE_COMPLETE="bash_complete", COMP_WORDS=words,
               COMP_CWORD=str(len(words.split()) - (0 if words.endswith(" ") else 1)))
    result = run_cli(env=env)
    assert result.returncode == 0, result.stderr
    return [line.split(",", 1)[1] for line in result.stdout.splitlines()]


def test_device_names_complete_for_their_kind(tmp_path: Path) -> None:
    assert complete("fabwire xyz status -d b", tmp_path) == ["basement"]
    assert complete("fabwire mmu -d b", tmp_path) == ["bench"]
    assert complete("fabwire xyz st", tmp_path) == ["status"]


@pytest.mark.parametrize("command", ["show", "remove"])
def test_the_devices_commands_complete_every_configured_name(tmp_path: Path, command: str) -> None:
    assert complete(f"fabwire devices {command} b", tmp_path) == ["basement", "bench"]
    assert complete(f"fabwire devices {command} ", tmp_path) == ["basement", "bench", "office"]


def test_a_name_written_by_hand_with_a_space_completes_as_one_quoted_word(tmp_path: Path) -> None:
    config = tmp_path / "devices.toml"
    config.write_text('[devices."my printer"]\nkind = "xyz"\nurl = "10.0.0.5"\n')
    env = cli_env()
    env.update(FABWIRE_CONFIG=str(config), _FABWIRE_COMPLETE="bash_complete", COMP_WORDS="fabwire devices show m",
               COMP_CWORD="3")
    offered = [line.split(",", 1)[1] for line in run_cli(env=env).stdout.splitlines()]
    assert offered == ["'my printer'"]
    env = cli_env()
    env["FABWIRE_CONFIG"] = str(config)
    shown = subprocess.run(["bash", "-c", f"{sys.executable} -m fabwire devices show {offered[0]}"],
                           capture_output=True, text=True, timeout=60, env=env)
    assert shown.returncode == 0, shown.stderr
    assert shown.stdout.startswith('[devices."my printer"]')


def test_the_readme_installs_bash_completion_as_typed_on_a_fresh_home(tmp_path: Path) -> None:
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text(encoding="utf-8")
    block, = (b for b in re.findall(r"```sh\n(.*?)```", readme, flags=re.DOTALL) if "completion bash" in b)
    env = cli_env(tmp_path)
    env["HOME"] = str(tmp_path)  # nothing under it yet: the folders the commands write to do not exist
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"  # `fabwire` as installed
    ran = subprocess.run(["bash", "-e", "-c", block], capture_output=True, text=True, timeout=60, env=env)
    assert ran.returncode == 0, ran.stderr
    script = tmp_path / ".local/share/bash-completion/completions/fabwire"
    assert "complete -o nosort -F" in script.read_text()
