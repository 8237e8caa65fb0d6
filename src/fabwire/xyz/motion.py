"""How long the moves of a G-code take on a printer: a trapezoid per move under the firmware's acceleration, jerk
and feed rate limits, with look-ahead between moves, as Marlin-style firmware plans them (and as PrusaSlicer's
G-code processor estimates them: the same junction rule, the same reverse and forward passes).

Moves arrive as arrays; they are planned in windows of `WINDOW` moves counted from the file's start (so the result
does not depend on how the file was cut into pieces). Both passes are min-plus recurrences on squared speeds
(v_i^2 = min(limit_i, v_{i-1}^2 + 2 a d)), which a cumulative minimum solves for a whole window at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

Floats = NDArray[np.float64]

WINDOW = 16384
"""Moves planned together; the speed at a window's end is the last move's safe speed."""


@dataclass(frozen=True, slots=True)
class Limits:
    """A firmware's motion limits, axes X, Y, Z, E; speeds in mm/s, accelerations in mm/s^2."""

    max_feedrate: tuple[float, float, float, float]
    """M203 X Y Z E."""
    max_acceleration: tuple[float, float, float, float]
    """M201 X Y Z E."""
    acceleration: float
    """M204 P (Marlin 2) or S (legacy): moves that extrude."""
    retract_acceleration: float
    """M204 R (Marlin 2) or T with S (legacy): moves of the extruder alone."""
    travel_acceleration: float
    """M204 T (Marlin 2) or S (legacy): moves that do not extrude."""
    max_jerk: tuple[float, float, float, float]
    """M205 X Y Z E: the speed change an axis makes at once."""
    min_feedrate: float = 0.0
    """M205 S."""
    min_travel_feedrate: float = 0.0
    """M205 T."""


DEFAULT_LIMITS = Limits(
    max_feedrate=(500.0, 500.0, 12.0, 120.0), max_acceleration=(9000.0, 9000.0, 500.0, 10000.0), acceleration=1500.0,
    retract_acceleration=1500.0, travel_acceleration=1500.0, max_jerk=(10.0, 10.0, 0.2, 2.5),
)
"""Used when a file states no limits: PrusaSlicer's default machine limits (PrintConfig.cpp, machine_max_*; the
values it estimates with when the printer profile gives none). No public source gives the da Vinci firmware's own
limits, so a file's M201-M205 always win."""

_AXES = "XYZE"


def apply_command(limits: Limits, command: bytes, words: dict[bytes, float]) -> Limits:
    """`limits` after an M201, M203, M204 or M205 with these words (Marlin's units, as PrusaSlicer reads them)."""

    def axes(current: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
        values = [words.get(axis.encode(), current[k]) for k, axis in enumerate(_AXES)]
        return (values[0], values[1], values[2], values[3])

    if command == b"M201":
        return replace(limits, max_acceleration=axes(limits.max_acceleration))
    if command == b"M203":
        return replace(limits, max_feedrate=axes(limits.max_feedrate))
    if command == b"M204":
        if b"S" in words:  # the legacy form: S for printing and travel, T for retraction
            return replace(limits, acceleration=words[b"S"], travel_acceleration=words[b"S"],
                           retract_acceleration=words.get(b"T", limits.retract_acceleration))
        return replace(limits, acceleration=words.get(b"P", limits.acceleration),
                       retract_acceleration=words.get(b"R", limits.retract_acceleration),
                       travel_acceleration=words.get(b"T", limits.travel_acceleration))
    if command == b"M205":
        return replace(limits, max_jerk=axes(limits.max_jerk), min_feedrate=words.get(b"S", limits.min_feedrate),
                       min_travel_feedrate=words.get(b"T", limits.min_travel_feedrate))
    return limits


LIMIT_COMMANDS = (b"M201", b"M203", b"M204", b"M205")


def _sane(limits: Limits) -> Limits:
    """Zero, negative or absurd limits (a typo, `M204 S0`) would stop or never slow the machine: the defaults
    stand in for them."""
    def positive(value: float, default: float) -> float:
        return value if math.isfinite(value) and value > 0 else default

    def each(values: tuple[float, ...], defaults: tuple[float, ...]) -> tuple[float, float, float, float]:
        out = [positive(v, d) for v, d in zip(values, defaults, strict=True)]
        return (out[0], out[1], out[2], out[3])

    d = DEFAULT_LIMITS
    return Limits(each(limits.max_feedrate, d.max_feedrate), each(limits.max_acceleration, d.max_acceleration),
                  positive(limits.acceleration, d.acceleration),
                  positive(limits.retract_acceleration, d.retract_acceleration),
                  positive(limits.travel_acceleration, d.travel_acceleration), each(limits.max_jerk, d.max_jerk),
                  max(0.0, limits.min_feedrate) if math.isfinite(limits.min_feedrate) else 0.0,
                  max(0.0, limits.min_travel_feedrate) if math.isfinite(limits.min_travel_feedrate) else 0.0)


def radius_centre(x0: Floats, y0: Floats, x1: Floats, y1: Floats, r: Floats,
                  clockwise: NDArray[np.bool_]) -> tuple[Floats, Floats]:
    """Centres (X, Y in mm) of G2 (clockwise) / G3 arcs from (x0, y0) to (x1, y1) with radius R (negative: the
    longer way round), as Marlin's G2_G3.cpp finds them: h from the chord's middle along the chord's unit normal,
    h² = (|R| - chord / 2)(|R| + chord / 2), h = 0 (mid-chord) when R is shorter than half the chord. The unit
    normal is taken first, so a chord of 1e-308 mm neither overflows nor underflows; NaN where start and end meet."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        dx, dy = x1 - x0, y1 - y0
        chord = np.hypot(dx, dy)
        h = np.sqrt(np.maximum(0.0, (np.abs(r) - chord / 2) * (np.abs(r) + chord / 2)))
        side = np.where(clockwise ^ (r < 0), -h, h)
        return (x0 + x1) / 2 - side * (dy / chord), (y0 + y1) / 2 + side * (dx / chord)


ARC_TOLERANCE_MM = 0.01
"""Largest distance between a straight segment and the arc it stands for (`arc_segment_counts`)."""
ARC_MOST_SEGMENTS = 4096
"""Segments of a full circle at most, whatever its radius (within the tolerance up to a radius of 30 m)."""


def arc_paths(x0: Floats, y0: Floats, x1: Floats, y1: Floats, i: Floats, j: Floats, r: Floats,
              clockwise: NDArray[np.bool_], turns: Floats) -> tuple[Floats, Floats, Floats, Floats, Floats]:
    """(centre X, centre Y, radius in mm, start angle, sweep in radians) of G2 (clockwise) / G3 arcs from (x0, y0)
    to (x1, y1) with centre offsets I, J from the start or radius R (NaN when not given; I or J wins over R), after
    `turns` full turns (P), as Marlin's plan_arc runs them: the sweep is from the start's angle to the end's around
    the centre, a whole turn where the end comes back to the start. NaN where the arc has no centre (none of I, J
    and R, or an R arc that ends where it starts: `radius_centre`)."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        by_offsets = ~(np.isnan(i) & np.isnan(j))
        rx, ry = radius_centre(x0, y0, x1, y1, r, clockwise)
        cx = np.where(by_offsets, x0 + np.where(np.isnan(i), 0.0, i), rx)
        cy = np.where(by_offsets, y0 + np.where(np.isnan(j), 0.0, j), ry)
        radius = np.hypot(x0 - cx, y0 - cy)
        begin, end = np.arctan2(y0 - cy, x0 - cx), np.arctan2(y1 - cy, x1 - cx)
        sweep = np.where(clockwise, begin - end, end - begin) % (2 * math.pi)
        sweep = np.where(sweep < 1e-9, 2 * math.pi, sweep) + turns * (2 * math.pi)
    return cx, cy, radius, begin, sweep


def arc_segment_counts(radius: Floats, sweep: Floats) -> NDArray[np.int64]:
    """How many equal chords cover arcs of `radius` (mm) and `sweep` (radians) with none further than
    ARC_TOLERANCE_MM from its arc (the chord of angle 2 acos(1 - tolerance / radius); a half turn each for a
    radius within the tolerance), at most ARC_MOST_SEGMENTS per full turn and at least one; 0 where the radius
    or sweep is not a finite number (an arc without a centre)."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        step = np.where(radius > ARC_TOLERANCE_MM,
                        2 * np.arccos(np.maximum(-1.0, 1 - ARC_TOLERANCE_MM / radius)), math.pi)
        step = np.maximum(step, 2 * math.pi / ARC_MOST_SEGMENTS)
        count = np.maximum(1.0, np.ceil(sweep / step))
        finite = np.isfinite(radius) & np.isfinite(sweep)
    counts: NDArray[np.int64] = np.where(finite, count, 0.0).astype(np.int64)
    return counts


def arc_lengths(x0: Floats, y0: Floats, x1: Floats, y1: Floats, i: Floats, j: Floats, r: Floats,
                clockwise: NDArray[np.bool_]) -> Floats:
    """Lengths in the XY plane of G2 (clockwise) / G3 arcs from (x0, y0) to (x1, y1), centre at offset (I, J) from
    the start, or radius R when I and J are NaN (negative R: the longer way), as Marlin's plan_arc reads them; an
    arc that ends where it starts is a full circle. An R arc whose chord exceeds its diameter is the half circle
    over its chord (Marlin's G2_G3.cpp puts the centre mid-chord, `radius_centre`)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        chord = np.hypot(x1 - x0, y1 - y0)
        centred = ~(np.isnan(i) & np.isnan(j))
        ii, jj = np.nan_to_num(i), np.nan_to_num(j)
        radius = np.where(centred, np.hypot(ii, jj), np.maximum(np.abs(r), chord / 2))
        start = np.arctan2(-jj, -ii)
        end = np.arctan2(y1 - (y0 + jj), x1 - (x0 + ii))
        sweep = np.where(clockwise, start - end, end - start) % (2 * math.pi)
        sweep = np.where(sweep < 1e-9, 2 * math.pi, sweep)
        half = np.arcsin(np.clip(chord / (2 * radius), 0.0, 1.0))
        by_radius = np.where(r < 0, 2 * math.pi - 2 * half, 2 * half)
        sweep = np.where(centred, sweep, by_radius)
        length = radius * sweep
        invalid = ~np.isfinite(length) | (radius == 0)
    result: Floats = np.where(invalid, chord, length)
    return result


@dataclass(slots=True)
class _Carry:
    """The last planned move, for the junction into the next window."""

    cruise: float
    velocity: Floats
    safe: float
    reach: float
    """The squared speed the next move may enter at (the last move's planned exit)."""


@dataclass(slots=True)
class Planner:
    """Collects moves (axis deltas in mm, path length in mm, feed rate in mm/min) and adds up their time."""

    limits: Limits = DEFAULT_LIMITS
    seconds: float = 0.0
    _table: list[Limits] = field(default_factory=lambda: [DEFAULT_LIMITS])
    _pending: list[tuple[Floats, ...]] = field(default_factory=list)
    _count: int = 0
    _carry: _Carry | None = None

    def set_limits(self, limits: Limits) -> None:
        self.limits = limits
        sane = _sane(limits)
        if sane != self._table[-1]:
            self._table.append(sane)

    def add(self, delta: tuple[Floats, Floats, Floats, Floats], length: Floats, feed: Floats) -> None:
        """Moves: X, Y, Z, E deltas, the path length (the arc's for arcs; 0 for extruder-only moves) and F."""
        dx, dy, dz, de = delta
        real = (length > 0) | (de != 0)
        if not real.all():
            dx, dy, dz, de, length, feed = (a[real] for a in (dx, dy, dz, de, length, feed))
        if not len(length):
            return
        which = np.full(len(length), float(len(self._table) - 1))
        self._pending.append((dx, dy, dz, de, length, feed, which))
        self._count += len(length)
        if self._count >= WINDOW + 1:  # a window is planned once the move after it is known
            self._plan()

    def total(self) -> float:
        """The seconds of every move so far, the ones still waiting for their window planned as if the file ended
        there (the planner itself is left as it was)."""
        if not self._count:
            return self.seconds
        columns = [np.concatenate(parts) for parts in zip(*self._pending, strict=True)]
        seconds, carry = self.seconds, self._carry
        with np.errstate(over="ignore", invalid="ignore"):  # moves no printer makes (1e305 mm) plan to inf or NaN
            for start in range(0, self._count, WINDOW):
                part, carry = _plan_window([c[start:start + WINDOW] for c in columns], self._table, carry)
                seconds += part
        return seconds

    def _plan(self) -> None:
        """Plan every window whose next move is known; the moves after the last one wait for more."""
        columns = [np.concatenate(parts) for parts in zip(*self._pending, strict=True)]
        start = 0
        while self._count - start >= WINDOW + 1:
            seconds, self._carry = _plan_window([c[start:start + WINDOW] for c in columns], self._table, self._carry)
            self.seconds += seconds
            start += WINDOW
        self._pending = [tuple(c[start:] for c in columns)]
        self._count -= start


def _limit_columns(table: list[Limits], which: Floats) -> dict[str, Floats]:
    """Each limit per move: one row when the window has one set of limits (the usual case), else a row per move."""
    rows = np.array([[*t.max_feedrate, *t.max_acceleration, t.acceleration, t.retract_acceleration,
                      t.travel_acceleration, *t.max_jerk, t.min_feedrate, t.min_travel_feedrate] for t in table])
    picked = rows[int(which[0]):int(which[0]) + 1] if which[0] == which[-1] else rows[which.astype(np.intp)]
    return {"max_feedrate": picked[:, 0:4], "max_acceleration": picked[:, 4:8], "acceleration": picked[:, 8],
            "retract": picked[:, 9], "travel": picked[:, 10], "jerk": picked[:, 11:15], "min_feed": picked[:, 15],
            "min_travel": picked[:, 16]}


def _smallest(values: list[Floats]) -> Floats:
    """The elementwise minimum of a few arrays (faster than a reduction along a short axis)."""
    out = values[0]
    for value in values[1:]:
        out = np.minimum(out, value)
    return out


SPARSE = 1 / 8
"""An axis that moves in fewer than this share of a window's moves (Z between layers, mostly) is planned at those
moves and the ones after them only: elsewhere it sets no limit."""


def _at(column: Floats, rows: NDArray[np.intp]) -> Floats:
    """A limit column (one value for the window, or one per move) at `rows`."""
    return column if len(column) == 1 else column[rows]


def _jerk(v_exit: Floats, v_entry: Floats, entry_speed: Floats | None = None) -> Floats:
    """An axis's speed change at junctions: the larger of the two speeds where it reverses (`entry_speed`: the
    magnitude of `v_entry`, when known)."""
    jerk: Floats = np.where(v_exit * v_entry < 0, np.maximum(np.abs(v_exit), np.abs(v_entry) if entry_speed is None
                                                             else entry_speed), np.abs(v_exit - v_entry))
    return jerk


def _with_next(rows: NDArray[np.intp], count: int) -> NDArray[np.intp]:
    """The sorted rows `rows` (ascending) of `count`, the rows just after them and row 0."""
    marked = np.zeros(count, dtype=bool)
    marked[0] = True
    marked[rows] = True
    marked[rows[rows + 1 < count] + 1] = True
    return np.flatnonzero(marked)


def _plan_window(columns: list[Floats], table: list[Limits], carry: _Carry | None) -> tuple[float, _Carry]:
    dx, dy, dz, de, length, feed, which = columns
    count = len(length)
    lim = _limit_columns(table, which)
    moving = length > 0
    dist = np.where(moving, length, np.abs(de))
    deltas = (dx, dy, dz, de)
    nonzero = [delta != 0 for delta in deltas]
    moves = [np.count_nonzero(moved) for moved in nonzero]
    ones, zeros = np.ones(count), np.zeros(count + 1)  # minimum/maximum with an array: faster than with a number
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse_dist = 1.0 / dist
        # still moves of an axis set no limit, unless a distance too small for its inverse makes them NaN
        few = SPARSE * count if np.isfinite(inverse_dist).all() else 0.0
        axes = [a for a in range(4) if moves[a] > few or (moves[a] and not few)]  # planned on every move
        others = [a for a in range(4) if a not in axes and (moves[a] or carry is not None)]
        sparse, still = (others, []) if few else ([], others)
        moved = {a: np.flatnonzero(nonzero[a]) for a in sparse}
        unit = [deltas[a] * inverse_dist for a in axes]
        inverse = [1.0 / np.abs(u) for u in unit]  # inf for an axis that does not move
        few_unit = [deltas[a][moved[a]] * inverse_dist[moved[a]] for a in sparse]
        few_inverse = [1.0 / np.abs(u) for u in few_unit]
        uniform = len(lim["min_feed"]) == 1  # one set of limits for the window
        speed = np.maximum(feed / 60.0, ones * lim["min_feed"] if uniform and lim["min_feed"] == lim["min_travel"]
                           else np.where(de == 0, lim["min_travel"], lim["min_feed"]))
        cruise = _smallest([speed] + [lim["max_feedrate"][:, a] * inverse[k] for k, a in enumerate(axes)])
        if uniform and lim["retract"] == lim["acceleration"] == lim["travel"]:
            accel = np.full(count, float(lim["acceleration"][0]))
        else:
            accel = np.where(~moving, lim["retract"], np.where(de > 0, lim["acceleration"], lim["travel"]))
        accel = _smallest([accel] + [lim["max_acceleration"][:, a] * inverse[k] for k, a in enumerate(axes)])
        for k, a in enumerate(sparse):
            rows = moved[a]
            cruise[rows] = np.minimum(cruise[rows], _at(lim["max_feedrate"][:, a], rows) * few_inverse[k])
            accel[rows] = np.minimum(accel[rows], _at(lim["max_acceleration"][:, a], rows) * few_inverse[k])
        velocity = [cruise * u for u in unit]
        speeds = [np.abs(v) for v in velocity]
        # the jerk limit where an axis's speed exceeds it, else inf (limits are positive: see `_sane`)
        safe = _smallest([cruise] + [np.divide(lim["jerk"][:, a], s > lim["jerk"][:, a]) for s, a in zip(
            speeds, axes, strict=True)])
    if safe is cruise:
        safe = cruise.copy()
    few_velocity = []
    for k, a in enumerate(sparse):
        rows = moved[a]
        v = np.zeros(count)
        v[rows] = cruise[rows] * few_unit[k]
        few_velocity.append(v)
        limit = _at(lim["jerk"][:, a], rows)
        safe[rows] = np.minimum(safe[rows], np.where(np.abs(v[rows]) > limit, limit, np.inf))

    # The junction speed into each move (PrusaSlicer's GCodeProcessor, Marlin's classic jerk): the per-axis speed
    # change, the larger of the two speeds where an axis reverses; scaled down by the tightest axis.
    first = carry is None
    prev_cruise = np.concatenate(([cruise[0] if carry is None else carry.cruise], cruise[:-1]))
    prev_safe = np.concatenate(([safe[0] if carry is None else carry.safe], safe[:-1]))
    factor = ones
    with np.errstate(divide="ignore", invalid="ignore"):
        slower = np.minimum(ones, cruise / prev_cruise)  # the previous move's speeds as it slows to this one's
        for k, a in enumerate(axes + still):
            v_entry, s_entry = (velocity[k], speeds[k]) if k < len(axes) else (zeros[:count], zeros[:count])
            before = v_entry[0] if carry is None else carry.velocity[a]
            v_exit = np.concatenate(([before], v_entry[:-1])) * slower
            factor = np.minimum(factor, lim["jerk"][:, a] / _jerk(v_exit, v_entry, s_entry))
        for k, a in enumerate(sparse):  # the moves of the axis and the ones after them (and the window's first)
            rows = _with_next(moved[a], count)
            v_entry = few_velocity[k][rows]
            v_before = few_velocity[k][rows - 1]
            v_before[rows == 0] = v_entry[0] if carry is None else carry.velocity[a]
            factor[rows] = np.minimum(factor[rows], _at(lim["jerk"][:, a], rows) / _jerk(v_before * slower[rows],
                                                                                          v_entry))
    junction = np.minimum(prev_cruise, cruise) * factor
    threshold = junction * 0.99
    junction = np.where((prev_safe > threshold) & (safe > threshold), safe, junction)
    if first:
        junction[0] = safe[0]
    limit_sq = np.concatenate((junction * junction, [safe[-1] * safe[-1]]))

    # Reverse then forward pass: squared entry speeds, each within reach of the next and of the previous move.
    twice_accel = 2.0 * accel
    prefix = np.empty(count + 1)
    prefix[0] = 0.0
    np.cumsum(twice_accel * dist, out=prefix[1:])
    reverse = np.minimum.accumulate((limit_sq + prefix)[::-1])[::-1] - prefix
    reach = math.inf if carry is None else carry.reach
    forward = np.minimum.accumulate(np.concatenate(([reach], reverse - prefix)))[1:] + prefix
    forward = np.maximum(forward, zeros)
    root = np.sqrt(forward)
    v0 = np.minimum(root[:-1], cruise)
    v1 = np.minimum(root[1:], cruise)

    # Each move's trapezoid: up to its peak speed (the cruise speed, or less when the move is too short to reach
    # it), any cruise, down to the exit speed.
    v0_sq, v1_sq = v0 * v0, v1 * v1
    peak = np.minimum(cruise, np.sqrt(accel * dist + (v0_sq + v1_sq) * 0.5))
    peak = np.maximum(peak, np.maximum(v0, v1))
    ramps = (2 * cruise * cruise - v0_sq - v1_sq) / twice_accel
    times = (2 * peak - v0 - v1) / accel + np.maximum(dist - ramps, zeros[:count]) / cruise
    last = np.zeros(4)
    last[axes] = [v[-1] for v in velocity]
    last[sparse] = [v[-1] for v in few_velocity]
    carried = _Carry(float(cruise[-1]), last, float(safe[-1]), float(forward[-1]))
    return float(np.sum(times)), carried
