"""Less pen-up travel and fewer pen lifts: drop sub-resolution points, join touching lines, then order and
orient the lines (greedy nearest neighbour over a grid index, improved by 2-opt and or-opt moves on
neighbour lists, then iterated local search with small double-bridge kicks, within a budget of CPU seconds).

The tour is open: it starts at the pen's position (home) and ends wherever the last line ends. Lines may be
drawn in either direction; every line is drawn exactly once.
"""

from __future__ import annotations

import math
import random
from collections import deque
from collections.abc import Sequence

import numpy as np

from fabwire.errors import InputError
from fabwire.importing import collection_paused
from fabwire.lineus.kinematics import HOME
from fabwire.lineus.plot.geometry import (
    BoolArray,
    FloatArray,
    IntArray,
    Polylines,
    extent,
    flatten,
    inner_segments,
    split_at,
)

RESOLUTION = 1.0
"""Smallest step worth sending, in machine units (0.05 mm): finer points are dropped."""
NEIGHBOURS = 8
"""Nearest line ends tried per line by the moves (8 gave the shortest stipple tours per CPU second in `make bench`)."""
MAX_REVERSAL = 1000
"""Longest run a 2-opt move may reverse: long reversals cost more time than they usually save."""

KICK_SPAN = 15
"""Longest block a kick of the iterated local search moves: short blocks keep the re-optimisation after a kick
local, so many more kicks fit in the budget (measured on stipples and scribbles, `make bench`)."""
WORK_PER_SECOND = 80_000
"""Lines the improvement examines per nominal second of budget: under one CPU second on a shared 2-core machine
under load, for every drawing `make bench` plans (stipples, scribbles, circles, hatching, text)."""
WORK_PER_LINE = 1
"""Lines examined per line of the drawing when no budget is given: one pass of the local search, about what
vpype's greedy `linesort` costs, whatever the drawing's size."""


def drop_fine_points(lines: Polylines, resolution: float = RESOLUTION) -> Polylines:
    """Remove vertices closer than `resolution` to the last kept one (the last vertex always stays)."""
    if not lines:
        return []
    points, offsets = flatten(lines)
    steps = np.hypot(*np.diff(points, axis=0).T)
    fine = np.flatnonzero(~(steps >= resolution) & inner_segments(offsets))
    if not len(fine):
        return list(lines)
    # Vertices stay up to the first fine step; from there, scan for the next vertex far enough from the last
    # kept one, and so on: only the fine steps cost a Python loop, not every vertex.
    line_of = np.searchsorted(offsets, fine, side="right") - 1
    firsts, lasts = offsets[:-1][line_of].tolist(), (offsets[1:] - 1)[line_of].tolist()
    keep = np.ones(len(points), dtype=bool)
    # Most scans stop two vertices on: that distance measured for every fine step at once.
    after = np.minimum(fine + 2, len(points) - 1)
    skip = (np.hypot(*(points[after] - points[fine]).T) >= resolution).tolist()
    hyp = math.hypot
    resume = 0
    for a, first, last, two in zip(fine.tolist(), firsts, lasts, skip, strict=True):
        if a < resume:
            continue  # decided by an earlier scan
        keep[a + 1] = False  # the fine step's own end
        k = a + 2
        if not (two and k <= last):
            ax, ay = points[a].tolist()
            while k <= last and hyp(*(points[k] - (ax, ay))) < resolution:
                keep[k] = False
                k += 1
        if k > last:  # the last vertex always stays: in place of the last kept one, or after a lone first one
            if a != first:
                keep[a] = False
                keep[last] = True
            else:
                keep[last] = bool((points[last] != points[a]).any())
        resume = k
    # One selection over all points, then every line as a view of it.
    return split_at(points[keep], np.concatenate([[0], np.cumsum(keep)])[offsets])


def line_ends(lines: Sequence[FloatArray]) -> tuple[FloatArray, FloatArray]:
    """The first and the last point of every line, as two (n, 2) arrays."""
    points, offsets = flatten(lines)
    return points[offsets[:-1]], points[offsets[1:] - 1]


def join_touching(lines: Polylines, resolution: float = RESOLUTION) -> Polylines:
    """Chain lines whose ends meet (within `resolution`), reversing lines where that lets them join."""
    n = len(lines)
    if n < 2:
        return list(lines)
    # Line ends numbered e: the start of line e (e < n) or the end of line e - n; ends on one grid point of
    # `resolution` share a group, and only groups holding ends of two or more lines can join anything.
    starts, ends = line_ends(lines)
    keys = np.round(np.concatenate([starts, ends]) * (1.0 / max(resolution, 1e-9)))
    group = np.unique(keys, axis=0, return_inverse=True)[1].reshape(-1).astype(np.int64)
    pairs = np.unique(group * n + np.arange(2 * n) % n)
    joinable = (np.bincount(pairs // n, minlength=2 * n) >= 2)[group]
    if not joinable.any():
        return list(lines)
    by_line = np.stack([np.arange(n), np.arange(n) + n], axis=1).reshape(-1)
    buckets: dict[int, list[int]] = {}
    grp = group.tolist()
    for e in by_line[joinable[by_line]].tolist():
        buckets.setdefault(grp[e], []).append(e)
    used = bytearray(n)

    def take(end: int) -> tuple[int, bool] | None:
        """An unused line with an end where `end` is: (line, whether that is its last point)."""
        bucket = buckets.get(grp[end])
        while bucket:
            e = bucket.pop()
            i = e % n
            if not used[i]:
                used[i] = 1
                return (i, e >= n)
        return None

    out: Polylines = []
    for seed in range(n):
        if used[seed]:
            continue
        used[seed] = 1
        if len(lines[seed]) < 2 or not (joinable[seed] or joinable[seed + n]):
            out.append(lines[seed])
            continue
        parts: deque[FloatArray] = deque([lines[seed]])
        tail, head = seed + n, seed
        while (found := take(tail)) is not None:  # extend forward from the tail
            i, at_end = found
            nxt = lines[i][::-1] if at_end else lines[i]
            parts.append(nxt[1:] if len(nxt) > 1 else nxt[:0])
            if len(nxt) == 1:
                break
            tail = i if at_end else i + n
        while (found := take(head)) is not None:  # extend backward from the head
            i, at_end = found
            prev = lines[i] if at_end else lines[i][::-1]
            parts.appendleft(prev[:-1] if len(prev) > 1 else prev[:0])
            if len(prev) == 1:
                break
            head = i if at_end else i + n
        out.append(np.concatenate(list(parts)) if len(parts) > 1 else parts[0])
    return out


def travel_length(lines: Sequence[FloatArray], origin: tuple[float, float] = HOME) -> float:
    """Pen-up distance to draw `lines` in the given order and direction, starting at `origin`."""
    if not lines:
        return 0.0
    return _travel(*line_ends(lines), origin)


def _travel(starts: FloatArray, ends: FloatArray, origin: tuple[float, float]) -> float:
    """`travel_length` of lines with these first and last points (one or more lines)."""
    prev = np.vstack([np.asarray(origin, dtype=float), ends[:-1]])
    return float(np.hypot(*(starts - prev).T).sum())


def _arranged_ends(starts: FloatArray, ends: FloatArray, order: IntArray, flips: BoolArray
                   ) -> tuple[FloatArray, FloatArray]:
    """`line_ends(arrange(lines, order, flips))` from the lines' own ends, without touching their points."""
    turned = flips[:, None]
    return np.where(turned, ends[order], starts[order]), np.where(turned, starts[order], ends[order])


def greedy_order(
    starts: FloatArray, ends: FloatArray, origin: tuple[float, float] = HOME
) -> tuple[IntArray, BoolArray]:
    """Nearest-neighbour tour over line ends (either end may come first), using a uniform grid index.

    Returns the line order and, per position, whether that line is drawn reversed.
    """
    n = len(starts)
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool)
    pts = np.vstack([starts, ends])
    lo, span = _origin_span(pts)
    cell = max(float(math.sqrt(span[0] * span[1] / (2 * n))) * 1.5, float(span.max()) / 4096, 1e-6)
    cols = np.floor((pts - lo) / cell).astype(np.int64)
    width = int(cols[:, 1].max()) + 1
    cell_of = (cols[:, 0] * width + cols[:, 1]).tolist()
    cells: dict[int, set[int]] = {}
    for e, c in enumerate(cell_of):
        cells.setdefault(c, set()).add(e)
    xs = pts[:, 0].tolist()
    ys = pts[:, 1].tolist()
    alive = np.ones(2 * n, dtype=bool)
    max_ring = max(3, int(math.sqrt(n) / 8))
    ncx = int(cols[:, 0].max()) + 1
    order: list[int] = []
    flips: list[bool] = []
    cx, cy = float(origin[0]), float(origin[1])
    lox, loy = float(lo[0]), float(lo[1])
    # Each ring of cells around the pen's cell, as (dx, dy) steps and as steps of the cell key, in the order the
    # search visits them (the order decides between ends at equal distances).
    rings = [[(dx, dy) for dx in range(-r, r + 1) for dy in range(-r, r + 1, 1 if abs(dx) == r else max(2 * r, 1))]
             for r in range(max_ring + 1)]
    ring_keys = [[dx * width + dy for dx, dy in ring] for ring in rings]
    reach = [r * cell for r in range(max_ring + 1)]
    get, floor, sqrt = cells.get, math.floor, math.sqrt

    for _ in range(n):
        gx = floor((cx - lox) / cell)
        gy = floor((cy - loy) / cell)
        here = gx * width + gy
        best = -1
        best_d = math.inf
        for r in range(max_ring + 1):
            if r <= gx < ncx - r and r <= gy < width - r:  # the whole ring on the grid
                buckets = [get(here + key) for key in ring_keys[r]]
            else:
                buckets = [get((gx + dx) * width + gy + dy) for dx, dy in rings[r]
                           if 0 <= gx + dx < ncx and 0 <= gy + dy < width]
            for bucket in buckets:
                if bucket:
                    for e in bucket:
                        d = (xs[e] - cx) ** 2 + (ys[e] - cy) ** 2
                        if d < best_d:
                            best_d, best = d, e
            if best >= 0 and sqrt(best_d) <= reach[r]:
                break
        if best < 0 or sqrt(best_d) > reach[max_ring]:
            idx = np.flatnonzero(alive)
            dd = (pts[idx, 0] - cx) ** 2 + (pts[idx, 1] - cy) ** 2
            best = int(idx[int(np.argmin(dd))])
        node = best % n
        rev = best >= n
        order.append(node)
        flips.append(rev)
        for e in (node, node + n):
            bucket = cells[cell_of[e]]
            bucket.discard(e)
            if not bucket:
                del cells[cell_of[e]]
            alive[e] = False
        exit_e = node if rev else node + n
        cx, cy = xs[exit_e], ys[exit_e]
    return np.asarray(order, dtype=np.int64), np.asarray(flips, dtype=bool)


def _origin_span(pts: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The lower-left corner of the points' bounding box and its size (at least 1e-9 on each axis)."""
    x0, y0, x1, y1 = extent(pts)
    lo = np.array([x0, y0])
    return lo, np.maximum(np.array([x1, y1]) - lo, 1e-9)


def _neighbour_lists(starts: FloatArray, ends: FloatArray, k: int) -> list[list[int]]:
    """For each line, the lines with an end among the k nearest to either of its ends (grid-bucketed: up to
    `cap` ends from each of the 3 x 3 cells around an end are candidates)."""
    n = len(starts)
    pts = np.vstack([starts, ends])
    m = len(pts)
    lo, span = _origin_span(pts)
    cell = max(float(math.sqrt(span[0] * span[1] / m)) * 1.6, float(span.max()) / 2048, 1e-6)
    g = np.floor((pts - lo) / cell).astype(np.int64)
    w = int(g[:, 1].max()) + 3
    cid = (g[:, 0] + 1) * w + (g[:, 1] + 1)
    sort = np.argsort(cid, kind="stable")
    uniq, first, counts = np.unique(cid[sort], return_index=True, return_counts=True)
    cap = 6
    # Every end's 9 surrounding cells at once, then up to `cap` ends of each: an (m, 9 * cap) candidate table.
    offsets = np.array([dx * w + dy for dx in (-1, 0, 1) for dy in (-1, 0, 1)], dtype=np.int64)
    target = cid[:, None] + offsets[None, :]
    at = np.minimum(np.searchsorted(uniq, target), len(uniq) - 1)
    hit = uniq[at] == target
    base = np.where(hit, first[at], 0)
    count = np.where(hit, np.minimum(counts[at], cap), 0)
    slot = np.arange(cap)
    valid = (slot[None, None, :] < count[:, :, None]).reshape(m, -1)
    cand = sort[np.minimum(base[:, :, None] + slot[None, None, :], m - 1)].reshape(m, -1)
    node_of = cand % n
    # Distances to the real candidates only (other lines' ends), inf in the table's empty slots.
    real = valid & (node_of != (np.arange(m) % n)[:, None])
    flat = np.flatnonzero(real)
    other, row = cand.ravel()[flat], flat // cand.shape[1]
    xs, ys = pts[:, 0].copy(), pts[:, 1].copy()
    d = np.full(cand.shape, np.inf)
    d.ravel()[flat] = np.hypot(xs[other] - xs[row], ys[other] - ys[row])
    kk = min(k, d.shape[1])
    nearest = np.argpartition(d, kk - 1, axis=1)[:, :kk] if d.shape[1] > kk else np.argsort(d, axis=1)
    picked = np.take_along_axis(node_of, nearest, axis=1)
    picked[~np.isfinite(np.take_along_axis(d, nearest, axis=1))] = -1
    # Both ends of a line together, each other line once.
    both = np.sort(np.concatenate([picked[:n], picked[n:]], axis=1), axis=1)
    both[:, 1:][both[:, 1:] == both[:, :-1]] = -1
    both.sort(axis=1)  # the -1s (none, or repeated) first, each row's lines after them in increasing order
    return [row[skip:] for row, skip in zip(both.tolist(), (both < 0).sum(axis=1).tolist(), strict=True)]


def improve(
    starts: FloatArray,
    ends: FloatArray,
    order: IntArray,
    flips: BoolArray,
    origin: tuple[float, float] = HOME,
    *,
    work: int,
) -> tuple[IntArray, BoolArray]:
    """2-opt (segment reversal) and or-opt (move up to three lines, either way round) until no move on the
    neighbour lists helps, then kicks of an iterated local search, until `work` lines have been examined (a
    count, never a clock: the same input and budget give the same tour on any machine). Never makes the tour
    longer."""
    n = len(starts)
    if n < 3 or work <= 0:
        return order, flips
    spent = [0]
    neigh = _neighbour_lists(starts, ends, NEIGHBOURS)
    # Node n is the fixed starting point; per node: the point where drawing enters (i) and leaves (o).
    ix = [*starts[:, 0].tolist(), float(origin[0])]
    iy = [*starts[:, 1].tolist(), float(origin[1])]
    ox = [*ends[:, 0].tolist(), float(origin[0])]
    oy = [*ends[:, 1].tolist(), float(origin[1])]
    for node, rev in zip(order.tolist(), flips.tolist(), strict=True):
        if rev:
            ix[node], ox[node] = ox[node], ix[node]
            iy[node], oy[node] = oy[node], iy[node]
    tour = [n, *order.tolist()]
    pos = [0] * (n + 1)
    for p, v in enumerate(tour):
        pos[v] = p
    last = n
    hyp = math.hypot

    def link(a: int, b: int) -> float:
        """Travel from the end of the line at position a to the start of the one at position b."""
        if b > last or a < 0:
            return 0.0
        u, v = tour[a], tour[b]
        return hyp(ox[u] - ix[v], oy[u] - iy[v])

    def flip_block(a: int, b: int) -> None:
        block = tour[a : b + 1]
        block.reverse()
        tour[a : b + 1] = block
        for p, v in enumerate(block, a):
            pos[v] = p
            ix[v], ox[v] = ox[v], ix[v]
            iy[v], oy[v] = oy[v], iy[v]

    def neigh_union(first: int, other: int) -> list[int]:
        """The neighbours of either end line of a run (a run of two or three lines moves as one)."""
        if first == other:
            return neigh[first]
        return list(set(neigh[first]).union(neigh[other]))

    queue: deque[int] = deque(order.tolist())
    gained = [0.0]
    """Travel saved by the moves applied so far (what a kick is judged by, without re-measuring the tour)."""
    queued = bytearray(n + 1)
    for v in queue:
        queued[v] = 1
    eps = 1e-7

    def push(*nodes: int) -> None:
        for v in nodes:
            if v != n and not queued[v]:
                queued[v] = 1
                queue.append(v)

    def local_search() -> bool:
        """Apply improving moves until none is left (True) or time is up (False)."""
        popleft = queue.popleft
        while queue:
            spent[0] += 1
            if spent[0] > work:
                return False
            a = popleft()
            queued[a] = 0
            i = pos[a]
            improved = False
            oxa, oya, ixa, iya = ox[a], oy[a], ix[a], iy[a]
            # The hops into and out of a, measured once for all its neighbours.
            if i < last:
                w = tour[i + 1]
                wx, wy = ix[w], iy[w]
                hop_out = hyp(oxa - wx, oya - wy)
            else:
                w, wx, wy, hop_out = -1, 0.0, 0.0, 0.0
            if i > 0:
                prev = tour[i - 1]
                px, py = ox[prev], oy[prev]
                hop_in = hyp(px - ixa, py - iya)
            else:
                prev, px, py, hop_in = -1, 0.0, 0.0, 0.0
            for c in neigh[a]:
                j = pos[c]
                if i < j <= i + MAX_REVERSAL:
                    # 2-opt, new edge from the end of a to the end of c (c later): reverse i+1..j.
                    new = hyp(oxa - ox[c], oya - oy[c])
                    old = hop_out
                    if j < last:
                        z = tour[j + 1]
                        zx, zy = ix[z], iy[z]
                        old += hyp(ox[c] - zx, oy[c] - zy)
                        new += hyp(wx - zx, wy - zy)
                    if old - new > eps:
                        flip_block(i + 1, j)
                        gained[0] += old - new
                        push(a, c, tour[i + 1], *(tour[j + 1 : j + 2]))
                        improved = True
                        break
                elif 1 <= j < i and j >= i - MAX_REVERSAL:
                    # new edge between the starts of a and c (c earlier): reverse j..i-1.
                    u = tour[j - 1]
                    uxo, uyo = ox[u], oy[u]
                    new = hyp(ixa - ix[c], iya - iy[c]) + hyp(uxo - px, uyo - py)
                    old = hyp(uxo - ix[c], uyo - iy[c]) + hop_in
                    if old - new > eps:
                        flip_block(j, i - 1)
                        gained[0] += old - new
                        push(a, c, u, prev)
                        improved = True
                        break
            if improved:
                push(a)
                continue
            # or-opt: move the run of 1..3 lines starting at a to sit next to a neighbour, either way round.
            if i < 1:
                continue
            for size in (1, 2, 3):
                end = i + size - 1
                if end > last:
                    break
                last_v = tour[end]
                lox, loy = ox[last_v], oy[last_v]
                removed = hop_in
                bridge = 0.0
                if end < last:
                    w = tour[end + 1]
                    removed += hyp(lox - ix[w], loy - iy[w])
                    bridge = hyp(px - ix[w], py - iy[w])
                gain_out = removed - bridge
                if gain_out <= eps:
                    continue
                best_gain, best_q, best_rev = eps, -1, False
                for c in (neigh[a] if size == 1 else neigh_union(a, last_v)):
                    pc = pos[c]
                    for q in (pc - 1, pc):
                        if q < 0 or i - 1 <= q <= end:
                            continue
                        u = tour[q]
                        uxo, uyo = ox[u], oy[u]
                        fwd = hyp(uxo - ixa, uyo - iya)
                        rev = hyp(uxo - lox, uyo - loy)
                        if q < last:
                            w = tour[q + 1]
                            wix, wiy = ix[w], iy[w]
                            base = hyp(uxo - wix, uyo - wiy)
                            fwd += hyp(lox - wix, loy - wiy)
                            rev += hyp(ixa - wix, iya - wiy)
                        else:
                            base = 0.0
                        gain = gain_out + base - fwd
                        if gain > best_gain:
                            best_gain, best_q, best_rev = gain, q, False
                        gain = gain_out + base - rev
                        if gain > best_gain:
                            best_gain, best_q, best_rev = gain, q, True
                if best_q >= 0:
                    q = best_q
                    gained[0] += best_gain
                    block = tour[i : end + 1]
                    if best_rev:
                        block.reverse()
                        for v in block:
                            ix[v], ox[v] = ox[v], ix[v]
                            iy[v], oy[v] = oy[v], iy[v]
                    del tour[i : end + 1]
                    at = q + 1 if q < i else q + 1 - size
                    tour[at:at] = block
                    lo_p, hi_p = min(i, at), max(end, at + size - 1)
                    for p in range(lo_p, min(hi_p, last) + 1):
                        pos[tour[p]] = p
                    push(*block, tour[at - 1], *(tour[at + size : at + size + 1]), *(tour[i - 1 : i]))
                    improved = True
                    break
        return True

    def length() -> float:
        return sum(hyp(ox[tour[p]] - ix[tour[p + 1]], oy[tour[p]] - iy[tour[p + 1]]) for p in range(last))

    if not local_search():
        return _result(tour, ix, iy, starts, ends)
    settled = (tour[:], ix[:], iy[:], ox[:], oy[:], pos[:])
    settled_len = length()
    # Iterated local search: a local double-bridge kick, re-optimise around it, keep it only if shorter. A kick
    # is judged by the edges it changed and what the moves after it saved, so a rejected one costs no pass over
    # the whole tour.
    rng = random.Random(n)
    span = max(4, min(KICK_SPAN, n // 4))
    saved = settled
    # A kick is deterministic from the tour it starts on: once every possible kick has failed on the same tour,
    # every later one fails too, and a small drawing stops there instead of spending its whole budget (the plan
    # is the same either way).
    possible = _kick_count(last, span) if n * span * span <= KICK_ENUMERATION_LIMIT else None
    failed: set[tuple[int, int, int]] = set()
    while spent[0] < work and n >= 8:
        spent[0] += 1
        p1 = rng.randrange(1, last - 2)
        p2 = min(last - 1, p1 + rng.randrange(1, span))
        p3 = min(last, p2 + rng.randrange(1, span))
        if not p1 < p2 < p3:
            continue
        before = link(p1 - 1, p1) + link(p2 - 1, p2) + link(p3 - 1, p3)
        tour[p1:p3] = tour[p2:p3] + tour[p1:p2]
        for p in range(p1, p3):
            pos[tour[p]] = p
        added = link(p1 - 1, p1) + link(p1 + p3 - p2 - 1, p1 + p3 - p2) + link(p3 - 1, p3)
        push(*tour[max(1, p1 - 1) : min(last, p3 + 1) + 1])
        gained[0] = 0.0
        finished = local_search()
        if added - before - gained[0] < -eps:
            saved = (tour[:], ix[:], iy[:], ox[:], oy[:], pos[:])
            failed.clear()
        else:
            tour[:], ix[:], iy[:], ox[:], oy[:], pos[:] = saved
            queue.clear()
            queued[:] = bytes(n + 1)
            failed.add((p1, p2, p3))
        if not finished or (possible is not None and len(failed) >= possible):
            break
    if length() > settled_len:  # the kicks' sums of small gains could drift: never hand back a longer tour
        tour[:], ix[:], iy[:], ox[:], oy[:], pos[:] = settled
    return _result(tour, ix, iy, starts, ends)


KICK_ENUMERATION_LIMIT = 100_000
"""Drawings with up to this many kicks (lines x span²) count their distinct kicks, to stop once all have failed."""


def _kick_count(last: int, span: int) -> int:
    """The distinct kicks (p1, p2, p3) that `improve` can draw on a tour whose last position is `last`."""
    kicks = set()
    for p1 in range(1, last - 2):
        for r2 in range(1, span):
            p2 = min(last - 1, p1 + r2)
            for r3 in range(1, span):
                p3 = min(last, p2 + r3)
                if p1 < p2 < p3:
                    kicks.add((p1, p2, p3))
    return len(kicks)


def _result(
    tour: list[int], ix: list[float], iy: list[float], starts: FloatArray, ends: FloatArray
) -> tuple[IntArray, BoolArray]:
    new_order = np.asarray(tour[1:], dtype=np.int64)
    entered = np.asarray(ix)[new_order], np.asarray(iy)[new_order]
    new_flips = (entered[0] != starts[new_order, 0]) | (entered[1] != starts[new_order, 1])
    # A line whose two ends coincide is the same either way round; keep its original direction.
    closed = np.all(starts[new_order] == ends[new_order], axis=1)
    new_flips[closed] = False
    return new_order, new_flips


MAX_TIME_BUDGET_S = 600.0
"""The largest ordering budget taken, in nominal CPU seconds (ten minutes): beyond it the work count would outgrow
any drawing's use and a typo (1e20) would never end."""


def work_budget(seconds: float | None, lines: int) -> int:
    """The work (lines examined, see `improve`) of a budget of nominal CPU `seconds`, or with None, in
    proportion to the number of `lines` (`WORK_PER_LINE` each). A count, so a plan never depends on how busy or
    fast the machine is. Raises InputError for a budget that is not 0 to `MAX_TIME_BUDGET_S`."""
    if seconds is None:
        return WORK_PER_LINE * lines
    if not 0.0 <= seconds <= MAX_TIME_BUDGET_S:  # nan too
        raise InputError(f"an ordering budget is 0 to {MAX_TIME_BUDGET_S:g} s of work, not {seconds!r}")
    return max(0, round(seconds * WORK_PER_SECOND))


def arrange(lines: Sequence[FloatArray], order: IntArray, flips: BoolArray) -> Polylines:
    """The lines in `order`, each reversed where `flips` says."""
    return [lines[i][::-1] if f else lines[i] for i, f in zip(order.tolist(), flips.tolist(), strict=True)]


def optimise(
    lines: Polylines,
    *,
    origin: tuple[float, float] = HOME,
    resolution: float = RESOLUTION,
    time_budget: float | None = 1.0,
) -> Polylines:
    """The whole pass: fine points out, touching lines joined, then ordered for least pen-up travel, improving
    on greedy within `time_budget` (see `work_budget`). Never travels more than the lines in their given order
    (then that order is kept), and the same lines and budget always give the same result."""
    with collection_paused(freeze=False):  # many small tables, no reference cycles
        return _optimise(lines, origin, resolution, time_budget)


def _optimise(lines: Polylines, origin: tuple[float, float], resolution: float, time_budget: float | None
              ) -> Polylines:
    thinned = drop_fine_points(lines, resolution)
    cleaned = join_touching(thinned, resolution)
    if len(cleaned) < 2:  # nothing to order, but joining may still have moved where the drawing starts
        return cleaned if travel_length(cleaned, origin) <= travel_length(thinned, origin) else thinned
    starts, ends = line_ends(cleaned)
    work = work_budget(time_budget, len(cleaned))
    order, flips = greedy_order(starts, ends, origin)
    order, flips = improve(starts, ends, order, flips, origin, work=work - work // 10)
    ordered = arrange(cleaned, order, flips)
    ordered_ends = _arranged_ends(starts, ends, order, flips)
    travel = _travel(*ordered_ends, origin)
    if work // 10 > 0:
        by_runs = _reorder_runs(ordered, origin, work // 10, ordered_ends)
        if by_runs is not ordered:
            ordered, travel = by_runs, travel_length(by_runs, origin)
    return ordered if travel <= travel_length(thinned, origin) else thinned


def _reorder_runs(lines: Polylines, origin: tuple[float, float], work: int,
                  lines_ends: tuple[FloatArray, FloatArray] | None = None) -> Polylines:
    """Order again at a coarser grain: runs of lines joined by short hops (a hatched patch, a word) move as one
    piece, either way round. Moves of single lines cannot carry a patch of many lines across the page; this
    can. Kept only when it shortens the travel (else `lines` itself is returned); `work` as for `improve`;
    `lines_ends` is `line_ends(lines)` when known."""
    starts, ends = line_ends(lines) if lines_ends is None else lines_ends
    hops = np.hypot(*(starts[1:] - ends[:-1]).T)
    if len(hops) < 3:
        return lines
    short = max(10 * RESOLUTION, 2 * float(np.median(hops)))
    cuts = np.flatnonzero(hops > short) + 1
    bounds = [0, *cuts.tolist(), len(lines)]
    runs = [(bounds[k], bounds[k + 1]) for k in range(len(bounds) - 1)]
    if not 3 <= len(runs) < len(lines) or work < len(runs):
        return lines  # no runs to move, or too little work left to look at each once
    run_starts = np.array([starts[a] for a, _ in runs])
    run_ends = np.array([ends[b - 1] for _, b in runs])
    order, flips = greedy_order(run_starts, run_ends, origin)
    order, flips = improve(run_starts, run_ends, order, flips, origin, work=work)
    out: Polylines = []
    for index, flip in zip(order.tolist(), flips.tolist(), strict=True):
        a, b = runs[index]
        if flip:
            out.extend(line[::-1] for line in reversed(lines[a:b]))
        else:
            out.extend(lines[a:b])
    sizes = [runs[index][1] - runs[index][0] for index in order.tolist()]
    candidates = [lines, out, orient_runs(lines, [b - a for a, b in runs], origin), orient_runs(out, sizes, origin)]
    return min(candidates, key=lambda c: _travel(starts, ends, origin) if c is lines else travel_length(c, origin))


def orient_runs(lines: Polylines, sizes: Sequence[int], origin: tuple[float, float] = HOME) -> Polylines:
    """The best way round for each run of consecutive lines (`sizes` long each), the runs' order kept: a run
    may be drawn as it is, backwards, mirrored (every line reversed, same order) or both. Mirroring lets a
    zig-zag hatch start at either corner of its side, which reversing alone cannot. Exact for the given order
    (dynamic programming over the four ways of each run), counting the hops inside each run as well."""
    if not lines:
        return lines
    starts, ends = line_ends(lines)
    # Hops inside a run: end of k to start of k+1 as drawn, start of k to end of k+1 when mirrored.
    as_drawn = np.concatenate([[0.0], np.cumsum(np.hypot(*(starts[1:] - ends[:-1]).T))])
    mirrored = np.concatenate([[0.0], np.cumsum(np.hypot(*(ends[1:] - starts[:-1]).T))])
    bounds = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    first, last = bounds[:-1], bounds[1:] - 1
    inner = np.stack([as_drawn[last] - as_drawn[first]] * 2 + [mirrored[last] - mirrored[first]] * 2, axis=1)
    # The four ways: as drawn, backwards, mirrored, mirrored backwards: where each enters and leaves.
    entry = np.stack([starts[first], ends[last], ends[first], starts[last]], axis=1)
    leave = np.stack([ends[last], starts[first], starts[last], ends[first]], axis=1)
    cost = np.hypot(*(entry[0] - np.asarray(origin, dtype=float)).T) + inner[0]
    choice = np.zeros((len(sizes), 4), dtype=np.int64)
    for r in range(1, len(sizes)):
        hop = np.hypot(entry[r][None, :, 0] - leave[r - 1][:, None, 0], entry[r][None, :, 1] - leave[r - 1][:, None, 1])
        total = cost[:, None] + hop
        choice[r] = np.argmin(total, axis=0)
        cost = total[choice[r], np.arange(4)] + inner[r]
    way = int(np.argmin(cost))
    ways = [0] * len(sizes)
    for r in range(len(sizes) - 1, -1, -1):
        ways[r] = way
        way = int(choice[r, way])
    out: Polylines = []
    for (a, b), way in zip(zip(first.tolist(), (last + 1).tolist(), strict=True), ways, strict=True):
        run = lines[a:b]
        if way in (1, 3):
            run = run[::-1]
        out.extend(line[::-1] for line in run) if way in (1, 2) else out.extend(run)
    return out
