"""Running the real `fabwire` CLI and its simulators as subprocesses, for end-to-end tests."""

from __future__ import annotations

import os
import selectors
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import click

from fabwire.lifeline import spawn

STARTUP_TIMEOUT = 20.0


def cli_env(tmp_path: Path | None = None) -> dict[str, str]:
    """A clean environment: no user config file, unbuffered output, no colour codes."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("FABWIRE_")}
    env["PYTHONUNBUFFERED"] = "1"
    env["NO_COLOR"] = "1"
    env["TERM"] = "dumb"
    env["COLUMNS"] = "120"
    if tmp_path is not None:
        env["FABWIRE_CONFIG"] = str(tmp_path / "no-such-config.toml")
    return env


def run_cli(*args: str, timeout: float = 60.0, env: dict[str, str] | None = None,
            input_text: str | None = None) -> subprocess.CompletedProcess[str]:
    """Run `fabwire ARGS` as a real subprocess and capture its output."""
    return subprocess.run(
        [sys.executable, "-m", "fabwire", *args],
        capture_output=True, text=True, timeout=timeout, env=env or cli_env(), input=input_text,
    )


@dataclass
class RunningSimulator:
    process: subprocess.Popen[str]
    where: list[str]
    """What the simulator announced: `tcp://host:port` URLs and/or pty paths, in order."""
    _stderr: str = ""

    @property
    def url(self) -> str:
        return self.where[0]

    def stop(self) -> str:
        """Stop with SIGTERM (as a user's Ctrl-C would) and return what it printed on stderr."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.process.stdin is not None and not self.process.stdin.closed:
            self.process.stdin.close()
        if self.process.stderr is None or self.process.stderr.closed:
            return self._stderr
        self._stderr = self.process.stderr.read()
        for stream in (self.process.stdout, self.process.stderr):
            if stream:
                stream.close()
        return self._stderr


def start_simulator(*args: str, announcements: int = 1, env: dict[str, str] | None = None) -> RunningSimulator:
    """Start `fabwire sim ARGS` and wait until it has announced `announcements` places it serves on."""
    process = spawn([sys.executable, "-m", "fabwire", "sim", *args],  # ends with the test run, however it ends
                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env or cli_env())
    where: list[str] = []
    assert process.stdout is not None

    with selectors.DefaultSelector() as sel:
        sel.register(process.stdout, selectors.EVENT_READ)
        while len(where) < announcements:
            if not sel.select(STARTUP_TIMEOUT):
                process.kill()
                raise RuntimeError(f"simulator {args} did not announce itself in {STARTUP_TIMEOUT} s")
            line = process.stdout.readline()
            if not line:
                err = process.stderr.read() if process.stderr else ""
                raise RuntimeError(f"simulator {args} exited early: {err}")
            if " listening on " in line:
                where.append(line.split(" listening on ", 1)[1].split(" (link")[0].strip())
    return RunningSimulator(process, where)


SimulatorStarter = Callable[..., RunningSimulator]


def leaf_commands() -> dict[tuple[str, ...], click.Command]:
    """Every command that runs something (not a group), by its path under `fabwire`."""
    from fabwire.cli import cli  # here: the simulators' harness above needs no CLI import

    found: dict[tuple[str, ...], click.Command] = {}

    def walk(command: click.Command, path: tuple[str, ...], ctx: click.Context) -> None:
        if not isinstance(command, click.Group):
            found[path] = command
            return
        for name in command.list_commands(ctx):
            sub = command.get_command(ctx, name)
            assert sub is not None, (*path, name)
            walk(sub, (*path, name), click.Context(sub, parent=ctx, info_name=name))

    walk(cli, (), click.Context(cli, info_name="fabwire"))
    return found
