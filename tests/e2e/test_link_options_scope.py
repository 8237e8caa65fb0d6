"""Link options (-d, --trace, --timeout) reach only commands that open a device: every other command of the tree,
present or future, refuses them in one line with exit 2, wherever on the line they were typed."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path

import click
import pytest

from clitools import cli_env, leaf_commands, run_cli
from fabwire.cli import main

LINK_FLAGS = {"-d": "sim://xyz", "--trace": "wire.jsonl", "--timeout": "3"}
KNOWN_WITHOUT_DEVICE = {("xyz", "convert"), ("xyz", "info"), ("xyz", "discover"), ("lineus", "preview"),
                        ("lineus", "discover"), ("devices", "list"), ("samples",), ("trace", "show"),
                        ("sim", "xyz"), ("completion",)}
KNOWN_WITH_DEVICE = {("xyz", "status"), ("xyz", "wifi", "scan"), ("lineus", "draw"), ("lineus", "files", "list"),
                     ("mmu", "version")}


def shown_options(command: click.Command) -> set[str]:
    """The option names `--help` lists for `command`."""
    return {opt for p in command.params if isinstance(p, click.Option) and not p.hidden
            for opt in (*p.opts, *p.secondary_opts)}


def positions(path: tuple[str, ...], flag: str) -> list[list[str]]:
    """The option typed before the whole line, after each group on the way, and after the command."""
    value = LINK_FLAGS[flag]
    return [[*path[:i], flag, value, *path[i:]] for i in range(len(path) + 1)]


@pytest.fixture
def cli_logging_restored() -> Iterator[None]:
    """`main` in-process sets up fabwire's logging as the command line does: undone for the tests after this one."""
    logger = logging.getLogger("fabwire")
    level, handlers = logger.level, list(logger.handlers)
    yield
    logger.setLevel(level)
    logger.handlers[:] = handlers


@pytest.mark.usefixtures("cli_logging_restored")
def test_every_command_that_opens_no_device_refuses_link_options_wherever_typed(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # nothing a wrongly accepted command writes lands in the worktree
    monkeypatch.setenv("FABWIRE_CONFIG", str(tmp_path / "no-such-config.toml"))
    commands = leaf_commands()
    without = {path for path, command in commands.items() if "-d" not in shown_options(command)}
    assert without >= KNOWN_WITHOUT_DEVICE
    assert not KNOWN_WITH_DEVICE & without
    reasons = ("opens no device", "does not use it", "does not reach", "does not take it")
    wrong: list[str] = []
    for path, command in sorted(commands.items()):
        for flag in sorted(set(LINK_FLAGS) - shown_options(command)):
            for line in positions(path, flag):
                code = main(line)
                out, err = capsys.readouterr()
                said = err.strip()
                if (code != 2 or out or "\n" in said or not said.startswith("fabwire: error: ")
                        or flag not in said or f"`fabwire {' '.join(path)}`" not in said
                        or not any(reason in said for reason in reasons)
                        or (path in KNOWN_WITHOUT_DEVICE and line[-2] == "-d" and "opens no device" not in said)):
                    wrong.append(f"fabwire {' '.join(line)} -> exit {code}, stdout {out!r}, stderr {err!r}")
    assert not wrong, "\n".join(wrong)
    assert not list(tmp_path.iterdir())


def test_a_command_that_opens_a_device_lists_and_takes_the_link_options() -> None:
    commands = leaf_commands()
    for path in KNOWN_WITH_DEVICE:
        assert set(LINK_FLAGS) <= shown_options(commands[path]), path
    assert "--timeout" in shown_options(commands["trace", "replay"])  # its address is --to; it waits --timeout
    assert "-d" not in shown_options(commands["trace", "replay"])


@pytest.mark.parametrize("line", [
    ["xyz", "convert", "IN", "OUT", "-d", "office"],
    ["xyz", "-d", "office", "convert", "IN", "OUT"],
    ["-d", "office", "xyz", "convert", "IN", "OUT"],
], ids=["after", "group", "root"])
def test_convert_with_a_device_is_refused_before_any_file_is_written(line: list[str], tmp_path: Path) -> None:
    (tmp_path / "in.gcode").write_text("G28\nG1 X10 Y10 Z0.3 E1 F1200\n")
    files = {"IN": str(tmp_path / "in.gcode"), "OUT": str(tmp_path / "out.3w")}
    result = run_cli(*(files.get(word, word) for word in line), env=cli_env(tmp_path))
    assert result.returncode == 2
    assert result.stderr == ("fabwire: error: -d/--device: `fabwire xyz convert` opens no device, "
                             "so the option would do nothing\n")
    assert result.stdout == ""
    assert not (tmp_path / "out.3w").exists()


def test_a_device_option_before_a_command_with_its_own_says_where_that_goes(tmp_path: Path) -> None:
    result = run_cli("--trace", "wire.jsonl", "sim", "mmu", "--listen", "127.0.0.1:0", env=cli_env(tmp_path),
                     timeout=30)
    assert result.returncode == 2
    assert result.stderr == ("fabwire: error: --trace given to `fabwire` does not reach `fabwire sim mmu`: "
                             "its own --trace goes after `fabwire sim mmu`\n")


def test_trace_replay_takes_a_timeout_but_no_device(tmp_path: Path) -> None:
    capture = tmp_path / "empty.jsonl"
    capture.write_text("")
    waited = run_cli("trace", "replay", str(capture), "--to", "sim://xyz", "--timeout", "2", env=cli_env(tmp_path))
    assert waited.returncode == 4  # the option was taken: the empty capture is what is refused
    assert "holds no trace records" in waited.stderr
    refused = run_cli("trace", "replay", str(capture), "--to", "sim://xyz", "-d", "sim://xyz",
                      env=cli_env(tmp_path))
    assert refused.returncode == 2
    assert refused.stderr == ("fabwire: error: -d/--device: `fabwire trace replay` does not use it (of the link "
                              "options it takes --timeout)\n")
