"""What every benchmark returns: named figures with a unit, a target and, where there is one, a baseline."""

from __future__ import annotations

import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class Figure:
    name: str
    value: float
    unit: str
    target: str = ""
    """Human-readable target, e.g. '>= 1,000,000' or '< 5'."""
    meets_target: bool | None = None
    baseline: float | None = None
    """The side-by-side reference figure measured in the same run, if any (ratio = value / baseline)."""
    baseline_name: str = ""

    @property
    def ratio(self) -> float | None:
        return self.value / self.baseline if self.baseline else None


def cpu_seconds(func: Callable[[], object]) -> float:
    """Process CPU time (user + system) spent in `func`: unlike wall time, not skewed by other load."""
    before = resource.getrusage(resource.RUSAGE_SELF)
    func()
    after = resource.getrusage(resource.RUSAGE_SELF)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def wall_seconds(func: Callable[[], object]) -> float:
    start = time.perf_counter()
    func()
    return time.perf_counter() - start


@dataclass(frozen=True)
class Run:
    """One run of a whole command as a user starts it: wall seconds, CPU seconds (user + system), peak RSS (MiB)."""

    wall: float
    cpu: float
    rss_mib: float


_MEASURE = """
import os, sys, time
start = time.perf_counter()
pid = os.posix_spawn(sys.argv[1], sys.argv[1:], os.environ, file_actions=[(os.POSIX_SPAWN_OPEN, 1, os.devnull,
                                                                          os.O_WRONLY, 0)])
_, status, usage = os.wait4(pid, 0)
wall = time.perf_counter() - start
print(os.waitstatus_to_exitcode(status), wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss, file=sys.stderr)
"""
"""Runs a command from a small process and reports that command's own figures: a child's peak RSS as the
kernel counts it starts from its parent's, so the benchmark process (large) must not be the parent."""


def run_command(args: Sequence[str], env: Mapping[str, str] | None = None) -> Run:
    """Run `args` as a fresh process to its end (it must succeed) and measure that process alone."""
    program = args[0] if os.sep in args[0] else shutil.which(args[0]) or args[0]
    with tempfile.TemporaryFile() as err:
        subprocess.run([sys.executable, "-S", "-c", _MEASURE, program, *args[1:]], stdout=subprocess.DEVNULL,
                       stderr=err, env=env, check=False)
        err.seek(0)
        said = err.read().decode(errors="replace")
    *output, figures = said.rstrip("\n").rsplit("\n", 1) if "\n" in said.rstrip("\n") else ("", said.strip())
    code, wall, cpu, rss_kib = figures.split()
    if int(code) != 0:
        raise RuntimeError(f"{' '.join(args)} exited {code}: {''.join(output)[-500:]}")
    return Run(float(wall), float(cpu), int(rss_kib) / 1024)


def interleaved(commands: Mapping[str, tuple[Sequence[str], Mapping[str, str] | None]], runs: int) -> dict[str, Run]:
    """The median run of each command, run side by side: one of each in turn, `runs` rounds after a warm-up round,
    so load that comes and goes weighs on all of them alike."""
    samples: dict[str, list[Run]] = {name: [] for name in commands}
    for round_ in range(runs + 1):
        for name, (args, env) in commands.items():
            run = run_command(args, env)
            if round_:
                samples[name].append(run)
    return {name: Run(statistics.median(r.wall for r in got), statistics.median(r.cpu for r in got),
                      statistics.median(r.rss_mib for r in got)) for name, got in samples.items()}


def ratio_figure(name: str, value: float, unit: str, baseline: float, baseline_name: str, at_most: float) -> Figure:
    """A figure whose target is a ratio to a baseline measured beside it: `value <= at_most × baseline`."""
    return Figure(name, value, unit, f"<= {at_most:g}x {baseline_name}", value <= at_most * baseline, baseline,
                  baseline_name)
