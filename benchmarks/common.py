"""What every benchmark returns: named figures with a unit, a target and, where there is one, a baseline."""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
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


def run_command(args: Sequence[str], env: Mapping[str, str] | None = None) -> Run:
    """Run `args` as a fresh process to its end (it must succeed) and measure that process alone."""
    with tempfile.TemporaryFile() as err:
        start = time.perf_counter()
        process = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=err, env=env)
        _, status, usage = os.wait4(process.pid, 0)
        wall = time.perf_counter() - start
        process.returncode = os.waitstatus_to_exitcode(status)
        if process.returncode != 0:
            err.seek(0)
            raise RuntimeError(f"{' '.join(args)} exited {process.returncode}: {err.read().decode()[-500:]}")
    return Run(wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024)


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
