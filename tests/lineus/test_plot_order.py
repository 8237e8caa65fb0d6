"""The ordering is a work budget, not a clock: the same drawing and options give the same plan in any process, on
a busy machine or an idle one; and whatever it returns draws every stroke once and never travels more than the
drawing's own order."""

from __future__ import annotations

import gc
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from fabwire.errors import InputError
from fabwire.lineus.plot import PlanOptions, plan_lines
from fabwire.lineus.plot.geometry import extent, flatten, split_at
from fabwire.lineus.plot.optimize import (
    WORK_PER_LINE,
    WORK_PER_SECOND,
    drop_fine_points,
    join_touching,
    optimise,
    travel_length,
    work_budget,
)

coords = st.floats(min_value=600.0, max_value=1800.0, allow_nan=False, allow_infinity=False)
point = st.tuples(coords, st.floats(min_value=-900.0, max_value=900.0, allow_nan=False, allow_infinity=False))
drawings = st.lists(st.lists(point, min_size=1, max_size=6).map(lambda pts: np.array(pts, dtype=float)),
                    min_size=0, max_size=40)
"""Random drawings: up to 40 polylines of 1 to 6 points (dots included), in machine units."""


def stroke_key(line: np.ndarray) -> bytes:
    """A stroke the same whichever way round it is drawn."""
    return min(line.tobytes(), line[::-1].copy().tobytes())


@settings(max_examples=150, deadline=None)
@given(drawings, st.sampled_from([None, 0.0, 0.002, 0.05]))
@example([np.array([[606.0, 0.0], [600.0, 0.0]]), np.array([[600.0, 1.0], [606.0, 0.0]])], None)  # joined into
# one stroke that starts farther from home than the given first line
def test_the_order_draws_each_stroke_once_and_never_travels_more_than_the_input(lines: list[np.ndarray],
                                                                               budget: float | None) -> None:
    out = optimise(lines, time_budget=budget)
    thinned = drop_fine_points(lines)
    joined = join_touching(thinned)
    # A permutation of the cleaned strokes, each drawn one way or the other (or of the thinned ones, when their
    # own order travels less).
    got = sorted(map(stroke_key, out))
    assert got in (sorted(map(stroke_key, joined)), sorted(map(stroke_key, thinned)))
    assert travel_length(out) <= travel_length(thinned) + 1e-9
    assert travel_length(out) <= travel_length(lines) + 1e-9  # thinning keeps every line's first and last point
    again = optimise(lines, time_budget=budget)
    assert len(again) == len(out)
    assert all(np.array_equal(a, b) for a, b in zip(again, out, strict=True))


def sequential_thinning(line: np.ndarray, resolution: float) -> np.ndarray:
    """The definition of dropping fine points, vertex by vertex."""
    if len(line) < 2:
        return line
    kept = [0]
    for k in range(1, len(line)):
        if math.dist(line[k], line[kept[-1]]) >= resolution:
            kept.append(k)
    last = len(line) - 1
    if kept[-1] != last:
        if len(kept) > 1:
            kept[-1] = last
        elif math.dist(line[last], line[0]) > 0:
            kept.append(last)
    return line[kept]


steps = st.floats(min_value=-2.0, max_value=2.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.lists(st.tuples(steps, steps), min_size=1, max_size=12), min_size=1, max_size=12))
def test_fine_points_are_dropped_as_defined_vertex_by_vertex(walks: list[list[tuple[float, float]]]) -> None:
    lines = [1000.0 + np.cumsum(np.array(walk, dtype=float), axis=0) for walk in walks]
    got = drop_fine_points(lines)
    assert len(got) == len(lines)
    for line, thinned in zip(lines, got, strict=True):
        np.testing.assert_array_equal(thinned, sequential_thinning(line, 1.0))


def scattered_dashes(seed: int, count: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    starts = rng.uniform(700, 1700, (count, 2)) * [1.0, 0.8] - [0.0, 500.0]
    angles = rng.uniform(0, math.pi, count)
    return [np.array([s, s + 12 * np.array([math.cos(a), math.sin(a)])]) for s, a in zip(starts, angles, strict=True)]


def test_the_budget_is_counted_work_in_proportion_to_the_drawing_by_default() -> None:
    assert work_budget(None, 2000) == 2000 * WORK_PER_LINE
    assert work_budget(0.5, 2000) == work_budget(0.5, 10) == WORK_PER_SECOND // 2
    assert work_budget(0.0, 2000) == 0
    lines = scattered_dashes(5, 400)
    cheap = optimise(lines, time_budget=None)
    thorough = optimise(lines, time_budget=0.2)
    assert travel_length(thorough) <= travel_length(cheap) <= travel_length(lines)


def test_the_same_drawing_plans_the_same_twice_in_one_process() -> None:
    lines = scattered_dashes(9, 600)
    first = plan_lines(lines, PlanOptions(fit=False, time_budget=0.1), fit_default=False)
    second = plan_lines(lines, PlanOptions(fit=False, time_budget=0.1), fit_default=False)
    assert len(first.strokes) == len(second.strokes)
    assert all(np.array_equal(a, b) for a, b in zip(first.strokes, second.strokes, strict=True))
    assert first.figures() == second.figures()


PLAN_IN_A_PROCESS = """
import sys, hashlib
import numpy as np
sys.path.insert(0, sys.argv[1])
from test_plot_order import scattered_dashes
from fabwire.errors import InputError
from fabwire.lineus.plot import PlanOptions, plan_lines
plan = plan_lines(scattered_dashes(9, 600), PlanOptions(fit=False, time_budget=0.1), fit_default=False)
digest = hashlib.sha256()
for stroke in plan.strokes:
    digest.update(np.ascontiguousarray(stroke).tobytes() + b"|")
print(digest.hexdigest(), plan.figures().as_dict())
"""

SPIN = "import time\nend = time.monotonic() + 60\nwhile time.monotonic() < end:\n    pass\n"


def test_the_same_drawing_plans_the_same_in_separate_processes_busy_or_idle() -> None:
    """One process plans alone; two more plan while processes spinning on every core compete with them: all
    three print the same plan, byte for byte."""
    here = str(Path(__file__).parent)
    command = [sys.executable, "-c", PLAN_IN_A_PROCESS, here]
    idle = subprocess.run(command, capture_output=True, text=True, timeout=300, check=True).stdout
    spinners = [subprocess.Popen([sys.executable, "-c", SPIN]) for _ in range(2 * len(os.sched_getaffinity(0)))]
    try:
        busy = [subprocess.Popen(command, stdout=subprocess.PIPE, text=True) for _ in range(2)]
        outputs = [proc.communicate(timeout=300)[0] for proc in busy]
    finally:
        for spinner in spinners:
            spinner.kill()
            spinner.wait()
    assert idle.strip()
    assert outputs == [idle, idle]



@pytest.mark.parametrize("budget", [math.nan, math.inf, -1.0, 1e20, 600.5])
def test_a_plan_refuses_an_ordering_budget_out_of_range(budget: float) -> None:
    with pytest.raises(InputError, match="0 to 600 s"):
        PlanOptions(time_budget=budget)


@settings(max_examples=60, deadline=None)
@given(drawings, st.sampled_from([0.05, 0.2]))
def test_stopping_once_every_kick_failed_plans_exactly_as_spending_the_whole_budget(
        lines: list[np.ndarray], budget: float) -> None:
    import fabwire.lineus.plot.optimize as optimize

    early = optimise(lines, time_budget=budget)
    limit = optimize.KICK_ENUMERATION_LIMIT
    optimize.KICK_ENUMERATION_LIMIT = 0  # no counting: every kick the budget allows is drawn
    try:
        whole = optimise(lines, time_budget=budget)
    finally:
        optimize.KICK_ENUMERATION_LIMIT = limit
    assert len(early) == len(whole)
    assert all(np.array_equal(a, b) for a, b in zip(early, whole, strict=True))



@pytest.mark.parametrize("enabled", [True, False])
def test_the_ordering_collects_no_garbage_and_leaves_the_collector_as_it_found_it(enabled: bool) -> None:
    """Thousands of lines make thousands of small tables: no collection runs meanwhile (inside vpype one walks the
    whole document; at most the youngest objects are collected once, as the collector resumes), and the collector
    is on or off afterwards as it was before."""
    rng = np.random.default_rng(5)
    lines = [rng.random((4, 2)) * 900 + (700.0, -450.0) for _ in range(3000)]
    collections: list[int] = []

    def seen(phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            collections.append(info["generation"])

    was = gc.isenabled()
    (gc.enable if enabled else gc.disable)()
    gc.collect()  # nothing pending: a collection from here on would be the ordering's
    gc.callbacks.append(seen)
    try:
        ordered = optimise(lines, time_budget=None)
        assert gc.isenabled() == enabled
    finally:
        gc.callbacks.remove(seen)
        (gc.enable if was else gc.disable)()
    assert collections in ([], [0])
    assert len(ordered) == len(join_touching(drop_fine_points(lines)))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(min_value=1, max_value=5), min_size=1, max_size=30))
def test_lines_split_back_as_numpy_splits_them_and_their_extent_is_the_columns_bounds(sizes: list[int]) -> None:
    rng = np.random.default_rng(len(sizes))
    lines = [rng.normal(size=(size, 2)) * 1000 for size in sizes]
    points, offsets = flatten(lines)
    parts = split_at(points, offsets)
    assert [part.tobytes() for part in parts] == [part.tobytes() for part in np.split(points, offsets[1:-1])]
    assert all(np.shares_memory(part, points) for part in parts)  # views, not copies
    assert extent(points) == (points[:, 0].min(), points[:, 1].min(), points[:, 0].max(), points[:, 1].max())
