"""Steps that cannot be undone ask first on a terminal and need --yes elsewhere; negative numbers are arguments."""

from __future__ import annotations

import os
import select
import subprocess
import sys
import time
from pathlib import Path

import click
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import SimulatorStarter, cli_env, run_cli
from fabwire.cli_support import NumberCommand


def _on_a_terminal(args: list[str], answer: bytes) -> tuple[int, str, str]:
    """Run `fabwire ARGS` with stdin and stderr on a pty; type `answer` once it asks. Returns code, stdout, tty."""
    master, slave = os.openpty()
    try:
        proc = subprocess.Popen([sys.executable, "-m", "fabwire", *args], env=cli_env(), stdin=slave,
                                stdout=subprocess.PIPE, stderr=slave, start_new_session=True)
        seen = b""
        deadline = time.monotonic() + 30
        while b"[y/N]" not in seen and proc.poll() is None and time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 0.5)
            if ready:
                seen += os.read(master, 4096)
        os.write(master, answer)
        out, _ = proc.communicate(timeout=30)
        while select.select([master], [], [], 0.2)[0]:
            try:
                chunk = os.read(master, 4096)
            except OSError:
                break
            if not chunk:
                break
            seen += chunk
    finally:
        os.close(slave)
        os.close(master)
    return proc.returncode, out.decode(), seen.decode(errors="replace")


@pytest.mark.parametrize(("args", "asked", "yes_code", "yes_says"), [
    (["mmu", "-d", "sim://mmu?speed=100", "--speed", "100", "reset"], "Reboot the MMU?", 0, ""),
])
def test_a_terminal_is_asked_and_no_means_nothing_is_done(args: list[str], asked: str, yes_code: int,
                                                          yes_says: str) -> None:
    code, out, tty = _on_a_terminal(args, b"n\n")
    assert asked in tty
    assert (code, out) == (4, ""), tty
    assert "not confirmed" in tty
    code, out, tty = _on_a_terminal(args, b"y\n")
    assert code == yes_code, tty
    assert yes_says in tty
    if yes_code == 0:
        assert out.strip() == "MMU reset; firmware 3.0.4+936 answering"


@pytest.mark.parametrize(("args", "words"), [
    (["xyz", "-d", "sim://xyz", "restore-defaults"], "reset every setting"),
    (["mmu", "-d", "sim://mmu", "reset"], "reboot the MMU"),
    (["mmu", "-d", "sim://mmu", "reset", "--erase"], "erase the MMU's EEPROM"),
])
def test_without_a_terminal_yes_is_needed(args: list[str], words: str) -> None:
    done = run_cli(*args, input_text="y\n")
    assert (done.returncode, done.stdout) == (4, "")
    assert len(done.stderr.strip().splitlines()) == 1
    assert words in done.stderr
    assert "add --yes" in done.stderr


@pytest.mark.parametrize(("args", "given"), [
    (["xyz", "energy", "-5"], "-5"), (["xyz", "-d", "sim://xyz", "energy", "-5"], "-5"),
    (["xyz", "energy", "-5", "-d", "sim://xyz"], "-5"), (["xyz", "energy", "-d", "sim://xyz", "-12"], "-12"),
    (["--json", "xyz", "energy", "-1", "--json"], "-1"), (["xyz", "energy", "10"], "10"),
])
def test_an_energy_time_out_of_range_is_bad_input_even_when_negative(args: list[str], given: str) -> None:
    done = run_cli(*args)
    assert (done.returncode, done.stdout) == (4, "")
    assert done.stderr.strip().splitlines() == [f"fabwire: error: energy saving takes 0-9 minutes, not {given}"]


@pytest.mark.parametrize("args", [
    ["xyz", "zoffset", "-12", "-d", "sim://xyz"], ["xyz", "-d", "sim://xyz", "zoffset", "-12"],
    ["xyz", "zoffset", "-d", "sim://xyz", "-12"], ["xyz", "zoffset", "-v", "-12", "-d", "sim://xyz"],
])
def test_a_negative_z_offset_is_taken_in_every_position(args: list[str]) -> None:
    done = run_cli(*args)
    assert (done.returncode, done.stdout) == (0, "z offset -0.12 mm\n"), done.stderr


def test_unknown_options_are_still_refused() -> None:
    done = run_cli("xyz", "energy", "--bogus")
    assert done.returncode == 2
    assert "No such option: --bogus" in done.stderr
    done = run_cli("mmu", "tool-change", "-x", "1")
    assert done.returncode == 2
    assert "No such option: -x" in done.stderr


@click.command(cls=NumberCommand)
@click.argument("first", type=float)
@click.argument("second", type=float)
@click.option("--name", "-n")
@click.option("--verbose", "-v", count=True)
def _probe(first: float, second: float, name: str | None, verbose: int) -> None:
    click.echo(repr((first, second, name, verbose)))


numbers = (st.floats(max_value=-1e-3, min_value=-1e6, allow_nan=False).map(repr) | st.integers(max_value=-1).map(str)
           | st.sampled_from(["-inf", "-Infinity", "-nan", "-1E3", "-.5"]))


@settings(max_examples=60, deadline=None)
@given(first=numbers, second=numbers, name=numbers, cut=st.integers(0, 2), flags=st.sampled_from(["-v", "-vv"]))
def test_negative_numbers_are_arguments_anywhere_and_option_values_stay_theirs(
        first: str, second: str, name: str, cut: int, flags: str) -> None:
    positionals = [first, second]
    line = [*positionals[:cut], "--name", name, *positionals[cut:cut + 1], flags, *positionals[cut + 1:]]
    result = CliRunner().invoke(_probe, line)
    assert result.exit_code == 0, result.output
    assert result.output.strip() == repr((float(first), float(second), name, len(flags) - 1))


@pytest.mark.parametrize("args", [
    ["mmu", "-d", "sim://mmu?speed=100", "eject", "1", "--continue-after", "inf"],
    ["mmu", "-d", "sim://mmu?speed=100", "monitor", "--duration", "nan"],
    ["mmu", "-d", "sim://mmu?speed=100", "home", "--max-time", "nan"],
    ["xyz", "-d", "sim://xyz", "status", "--watch", "--interval", "inf"],
    ["xyz", "-d", "sim://xyz", "--timeout", "nan", "status"],
    ["mmu", "-d", "sim://mmu", "--speed", "inf", "status"],
])
def test_a_time_or_speed_that_is_not_a_finite_number_is_refused_before_anything_runs(args: list[str]) -> None:
    done = run_cli(*args, timeout=60)
    assert (done.returncode, done.stdout) == (2, "")
    assert "is not a finite number" in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize("value", ["9" * 5000, "9" * 5000 + "mm", "-" + "9" * 400 + ".5mm"])
def test_a_z_offset_too_long_for_a_number_is_one_line_of_bad_input(value: str) -> None:
    done = run_cli("xyz", "-d", "sim://xyz", "zoffset", value)
    assert (done.returncode, done.stdout) == (4, "")
    assert done.stderr.count("\n") == 1
    assert done.stderr.startswith("fabwire: error: z offset ")


def test_cancel_asks_only_when_there_is_a_print_to_cancel(simulator: SimulatorStarter, tmp_path: Path) -> None:
    idle = run_cli("xyz", "-d", "sim://xyz?speed=1000", "cancel")  # no terminal, no --yes: the state comes first
    assert idle.returncode == 4
    assert "nothing to cancel: no print is running" in idle.stderr
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "50")
    job = tmp_path / "long.gcode"
    job.write_bytes(b";TIME:1000000\nG28\nG1 X10 Y10 E1 F1200\n")
    assert run_cli("xyz", "-d", sim.url, "print", "--no-wait", str(job), timeout=120).returncode == 0
    code, out, tty = _on_a_terminal(["xyz", "-d", sim.url, "cancel"], b"n\n")
    assert "Cancel the running print?" in tty
    assert (code, out) == (4, ""), tty
    assert "not confirmed" in tty
    code, out, tty = _on_a_terminal(["xyz", "-d", sim.url, "cancel"], b"y\n")
    assert code == 0, tty
