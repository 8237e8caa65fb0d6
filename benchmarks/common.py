"""What every benchmark returns: named figures with a unit, a target and, where there is one, a baseline."""

from __future__ import annotations

import resource
import time
from collections.abc import Callable
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
