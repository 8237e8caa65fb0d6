"""The README's tour runs as typed: its simulators, then every `$ command` in one shell, each output as shown.

The tour's addresses are 127.0.0.1; the test serves the simulators on another loopback address (127.0.0.N, same
ports) and rewrites the commands to it, so it never collides with anything on the usual ports. In a shown output,
`…` stands for any text within a line, and a line of just `…` for any number of lines.
"""

from __future__ import annotations

import os
import random
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from clitools import RunningSimulator, cli_env, start_simulator

README = Path(__file__).resolve().parents[2] / "README.md"
TOUR = README.read_text(encoding="utf-8").split("## A five-minute tour", 1)[1].split("\n## ", 1)[0]


@dataclass
class Step:
    command: str
    shown: list[str]


def tour_steps() -> list[Step]:
    steps: list[Step] = []
    for block in re.findall(r"```console\n(.*?)```", TOUR, flags=re.DOTALL):
        for line in block.splitlines():
            if line.startswith("$ "):
                steps.append(Step(line[2:], []))
            else:
                steps[-1].shown.append(line)
    return steps


def simulator_commands() -> list[list[str]]:
    found = []
    for block in re.findall(r"```sh\n(.*?)```", TOUR, flags=re.DOTALL):
        for line in block.splitlines():
            command = line.split("#", 1)[0].strip().removesuffix("&").strip()
            if command.startswith("fabwire sim "):
                found.append(command.split()[2:])
    return found


def matches(shown: list[str], actual: list[str]) -> bool:
    """`shown` (with … wildcards) against the lines a command printed."""
    pattern = "".join("(?:.*\n)*" if line.strip() == "…" else
                      re.escape(line.rstrip()).replace("…", ".*") + r"[ \t]*\n" for line in shown)
    return re.fullmatch(pattern, "".join(line + "\n" for line in actual)) is not None


def test_the_tour_names_its_simulators_and_commands() -> None:
    assert [args[0] for args in simulator_commands()] == ["xyz", "lineus", "mmu"]
    commands = [step.command for step in tour_steps()]
    assert commands[:2] == ["mkdir tour && cd tour", "fabwire samples"]
    assert any(c.startswith("fabwire xyz -d 127.0.0.1 print calibration-square.gcode") for c in commands)
    assert any("fabwire-logo.svg" in c for c in commands)


def test_the_tour_runs_as_typed(tmp_path: Path) -> None:
    host = f"127.0.0.{random.randint(2, 250)}"
    sims: list[RunningSimulator] = []
    env = cli_env(tmp_path)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"  # `fabwire` as installed
    try:
        for args in simulator_commands():
            sims.append(start_simulator(*(a.replace("127.0.0.1", host) for a in args), env=env))
        steps = tour_steps()
        script = "".join(f"echo '@@step {i}'\n{step.command.replace('127.0.0.1', host)}\necho \"@@rc $?\"\n"
                         for i, step in enumerate(steps))
        ran = subprocess.run(["bash", "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                             env=env)
    finally:
        for sim in sims:
            sim.stop()
    outputs = re.split(r"^@@step \d+\n", ran.stdout, flags=re.MULTILINE)[1:]
    assert len(outputs) == len(steps), ran.stderr
    for step, output in zip(steps, outputs, strict=True):
        *lines, rc_line = output.rstrip("\n").split("\n")
        expected_rc = 4 if "load 7" in step.command else 0
        assert rc_line == f"@@rc {expected_rc}", f"{step.command}\n{ran.stderr}"
        assert matches(step.shown, lines), f"$ {step.command}\nREADME shows:\n{step.shown}\nprinted:\n{lines}"
    assert "fabwire: error: filament slot must be 0 to 4, not 7" in ran.stderr
    assert (tmp_path / "tour" / "square.3w").stat().st_size == 12720
