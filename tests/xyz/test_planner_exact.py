"""The planner's window arithmetic against the straightforward form it was written from: the same seconds and the
same state carried into the next window, to the last bit (a zero's sign aside, which no sum shows)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from fabwire.xyz import motion

Floats = NDArray[np.float64]


def _jerk(v_exit: Floats, v_entry: Floats) -> Floats:
    jerk: Floats = np.where(v_exit * v_entry < 0, np.maximum(np.abs(v_exit), np.abs(v_entry)),
                            np.abs(v_exit - v_entry))
    return jerk


def reference_plan(columns: list[Floats], table: list[motion.Limits],
                   carry: motion._Carry | None) -> tuple[float, motion._Carry]:
    dx, dy, dz, de, length, feed, which = columns
    count = len(length)
    lim = motion._limit_columns(table, which)
    moving = length > 0
    dist = np.where(moving, length, np.abs(de))
    deltas = (dx, dy, dz, de)
    moves = [np.count_nonzero(delta) for delta in deltas]
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse_dist = 1.0 / dist
        # still moves of an axis set no limit, unless a distance too small for its inverse makes them NaN
        few = motion.SPARSE * count if np.isfinite(inverse_dist).all() else 0.0
        axes = [a for a in range(4) if moves[a] > few or (moves[a] and not few)]  # planned on every move
        others = [a for a in range(4) if a not in axes and (moves[a] or carry is not None)]
        sparse, still = (others, []) if few else ([], others)
        moved = {a: np.flatnonzero(deltas[a]) for a in sparse}
        unit = [deltas[a] * inverse_dist for a in axes]
        inverse = [1.0 / np.abs(u) for u in unit]  # inf for an axis that does not move
        few_unit = [deltas[a][moved[a]] * inverse_dist[moved[a]] for a in sparse]
        few_inverse = [1.0 / np.abs(u) for u in few_unit]
        uniform = len(lim["min_feed"]) == 1  # one set of limits for the window
        speed = np.maximum(feed / 60.0, lim["min_feed"] if uniform and lim["min_feed"] == lim["min_travel"] else
                           np.where(de == 0, lim["min_travel"], lim["min_feed"]))
        cruise = motion._smallest([speed] + [lim["max_feedrate"][:, a] * inverse[k] for k, a in enumerate(axes)])
        if uniform and lim["retract"] == lim["acceleration"] == lim["travel"]:
            accel = np.full(count, float(lim["acceleration"][0]))
        else:
            accel = np.where(~moving, lim["retract"], np.where(de > 0, lim["acceleration"], lim["travel"]))
        accel = motion._smallest([accel] + [lim["max_acceleration"][:, a] * inverse[k] for k, a in enumerate(axes)])
        for k, a in enumerate(sparse):
            rows = moved[a]
            cruise[rows] = np.minimum(cruise[rows], motion._at(lim["max_feedrate"][:, a], rows) * few_inverse[k])
            accel[rows] = np.minimum(accel[rows], motion._at(lim["max_acceleration"][:, a], rows) * few_inverse[k])
    velocity = [cruise * u for u in unit]
    jerk_limit = [lim["jerk"][:, a] for a in axes]
    safe = motion._smallest([cruise] + [np.where(np.abs(v) > limit, limit, np.inf)
                                        for v, limit in zip(velocity, jerk_limit, strict=True)])
    if safe is cruise:
        safe = cruise.copy()
    few_velocity = []
    for k, a in enumerate(sparse):
        rows = moved[a]
        v = np.zeros(count)
        v[rows] = cruise[rows] * few_unit[k]
        few_velocity.append(v)
        limit = motion._at(lim["jerk"][:, a], rows)
        safe[rows] = np.minimum(safe[rows], np.where(np.abs(v[rows]) > limit, limit, np.inf))

    # The junction speed into each move (PrusaSlicer's GCodeProcessor, Marlin's classic jerk): the per-axis speed
    # change, the larger of the two speeds where an axis reverses; scaled down by the tightest axis.
    first = carry is None
    prev_cruise = np.concatenate(([cruise[0] if carry is None else carry.cruise], cruise[:-1]))
    prev_safe = np.concatenate(([safe[0] if carry is None else carry.safe], safe[:-1]))
    factor = np.ones(len(cruise))
    with np.errstate(divide="ignore", invalid="ignore"):
        slower = np.minimum(1.0, cruise / prev_cruise)  # the previous move's speeds as it slows to this one's
        for k, a in enumerate(axes + still):
            v_entry = velocity[k] if k < len(axes) else np.zeros(count)
            before = v_entry[0] if carry is None else carry.velocity[a]
            v_exit = np.concatenate(([before], v_entry[:-1])) * slower
            factor = np.minimum(factor, lim["jerk"][:, a] / _jerk(v_exit, v_entry))
        for k, a in enumerate(sparse):  # the moves of the axis and the ones after them (and the window's first)
            rows = np.union1d(np.append(moved[a], 0), (moved[a] + 1)[moved[a] + 1 < count])
            v_entry = few_velocity[k][rows]
            v_before = few_velocity[k][rows - 1]
            v_before[rows == 0] = v_entry[0] if carry is None else carry.velocity[a]
            factor[rows] = np.minimum(factor[rows], motion._at(lim["jerk"][:, a], rows) / _jerk(v_before * slower[rows],
                                                                                          v_entry))
    junction = np.minimum(prev_cruise, cruise) * factor
    threshold = junction * 0.99
    junction = np.where((prev_safe > threshold) & (safe > threshold), safe, junction)
    if first:
        junction[0] = safe[0]
    limit_sq = np.concatenate((junction * junction, [safe[-1] * safe[-1]]))

    # Reverse then forward pass: squared entry speeds, each within reach of the next and of the previous move.
    gain = 2.0 * accel * dist
    prefix = np.concatenate(([0.0], np.cumsum(gain)))
    reverse = np.minimum.accumulate((limit_sq + prefix)[::-1])[::-1] - prefix
    reach = math.inf if carry is None else carry.reach
    forward = np.minimum.accumulate(np.concatenate(([reach], reverse - prefix)))[1:] + prefix
    forward = np.maximum(forward, 0.0)
    v0 = np.minimum(np.sqrt(forward[:-1]), cruise)
    v1 = np.minimum(np.sqrt(forward[1:]), cruise)

    # Each move's trapezoid: up to its peak speed (the cruise speed, or less when the move is too short to reach
    # it), any cruise, down to the exit speed.
    v0_sq, v1_sq = v0 * v0, v1 * v1
    peak = np.minimum(cruise, np.sqrt(accel * dist + (v0_sq + v1_sq) / 2))
    peak = np.maximum(peak, np.maximum(v0, v1))
    ramps = (2 * cruise * cruise - v0_sq - v1_sq) / (2 * accel)
    times = (2 * peak - v0 - v1) / accel + np.maximum(dist - ramps, 0.0) / cruise
    last = np.zeros(4)
    last[axes] = [v[-1] for v in velocity]
    last[sparse] = [v[-1] for v in few_velocity]
    carried = motion._Carry(float(cruise[-1]), last, float(safe[-1]), float(forward[-1]))
    return float(np.sum(times)), carried


_DELTA = st.one_of(st.just(0.0), st.just(0.0), st.floats(-300, 300, allow_nan=False),
                   st.sampled_from([1e-9, -3.5, 5e-324, -5e-324, 1e-300, 2.5]))
_LIMITS = st.builds(
    motion.Limits,
    st.tuples(*[st.floats(0.01, 1000)] * 4), st.tuples(*[st.floats(0.01, 20_000)] * 4), st.floats(0.01, 5000),
    st.floats(0.01, 5000), st.floats(0.01, 5000), st.tuples(*[st.floats(0.01, 30)] * 4), st.floats(0, 50),
    st.floats(0, 50))


def _same(a: float, b: float) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b))


@settings(max_examples=300, deadline=None)
@given(moves=st.lists(st.tuples(_DELTA, _DELTA, _DELTA, _DELTA, st.floats(1, 20_000)), min_size=2, max_size=90),
       table=st.lists(_LIMITS, min_size=0, max_size=2), switch=st.integers(0, 89), cut=st.integers(1, 89),
       arcs=st.booleans(), z_every=st.integers(1, 40))
def test_window_arithmetic_is_the_straightforward_one(moves: list[tuple[float, ...]], table: list[motion.Limits],
                                                     switch: int, cut: int, arcs: bool, z_every: int) -> None:
    """Two windows in a row (the second gets the first's carried state), with zero, tiny and subnormal deltas,
    one or more sets of limits (changing at `switch`), moves of the extruder alone, arcs longer than chords, and Z
    moving at every `z_every`-th move only (the planner's sparse form), the last move before the cut included."""
    limits = [motion.DEFAULT_LIMITS, *(motion._sane(t) for t in table)]
    dx, dy, dz, de, feed = (np.array(c) for c in zip(*moves, strict=True))
    rows = np.arange(len(moves))
    dz[(rows % z_every != 0) & (rows != cut - 1)] = 0.0
    with np.errstate(all="ignore"):
        length = np.sqrt(dx * dx + dy * dy + dz * dz) * (1.5 if arcs else 1.0)
    keep = (length > 0) | (de != 0)
    which = np.where(np.arange(len(moves)) < switch, 0.0, float(len(limits) - 1))
    columns = [c[keep] for c in (dx, dy, dz, de, length, feed, which)]
    if not len(columns[0]):
        return
    cut = min(cut, len(columns[0]))
    ours: motion._Carry | None = None
    theirs: motion._Carry | None = None
    with np.errstate(all="ignore"):
        for window in ([c[:cut] for c in columns], [c[cut:] for c in columns]):
            if not len(window[0]):
                continue
            seconds, ours = motion._plan_window(window, limits, ours)
            expected, theirs = reference_plan(window, limits, theirs)
            assert _same(seconds, expected)
            assert _same(ours.cruise, theirs.cruise)
            assert _same(ours.safe, theirs.safe)
            assert _same(ours.reach, theirs.reach)
            assert all(_same(a, b) for a, b in zip(ours.velocity.tolist(), theirs.velocity.tolist(), strict=True))
