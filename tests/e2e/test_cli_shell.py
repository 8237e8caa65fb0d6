"""The `fabwire` command itself: version, help, exit codes, one-line errors, --debug tracebacks."""

from __future__ import annotations

from pathlib import Path

from clitools import run_cli
from fabwire import __version__
from fabwire.errors import InputError


def test_version() -> None:
    result = run_cli("--version")
    assert result.returncode == 0
    assert result.stdout.strip() == f"fabwire, version {__version__}"


def test_help_lists_the_shared_commands() -> None:
    result = run_cli("--help")
    assert result.returncode == 0
    for word in ("sim", "trace", "--json", "--verbose", "--debug"):
        assert word in result.stdout


def test_unknown_command_is_a_usage_error() -> None:
    result = run_cli("toaster")
    assert result.returncode == 2
    assert "No such command 'toaster'" in result.stderr


def test_errors_are_one_line_without_traceback_unless_debug(tmp_path: Path) -> None:
    missing = tmp_path / "missing.jsonl"
    plain = run_cli("trace", "show", str(missing))
    assert plain.returncode == InputError.exit_code
    assert plain.stderr.strip().splitlines() == [
        f"fabwire: error: cannot read trace file {missing}: No such file or directory"
    ]
    debug = run_cli("--debug", "trace", "show", str(missing))
    assert debug.returncode == InputError.exit_code
    assert "Traceback (most recent call last)" in debug.stderr
