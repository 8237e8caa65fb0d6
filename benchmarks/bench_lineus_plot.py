"""Line-us drawing planner: how fast a large SVG is read and planned, how much pen-up travel and drawing time the
optimised order saves against the file's own order and against plain greedy nearest-neighbour, and how close the
time estimate is to the simulator's time for the same plan."""

from __future__ import annotations

import asyncio
import math
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np

from common import Figure
from fabwire.lineus.client import LineUs
from fabwire.lineus.draw_cli import send_plan
from fabwire.lineus.kinematics import UNITS_PER_MM
from fabwire.lineus.plot import (
    PlanOptions,
    greedy_order,
    load_drawing,
    plan_drawing,
    plan_file,
    plan_lines,
    read_drawing,
    text_lines,
)
from fabwire.lineus.plot.optimize import arrange, drop_fine_points, join_touching
from fabwire.lineus.plot.plan import Plan
from fabwire.lineus.sim import LineUsSim, SimOptions
from fabwire.transport import memory_pair

SEGMENTS = 100_000
BUDGET = 1.0


def _svg(paths: list[str], size: float = 1000.0) -> str:
    body = "".join(f'<path d="{d}"/>' for d in paths)
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{size}" height="{size}" viewBox="0 0 {size} {size}">'
            f'<g stroke="black" fill="none">{body}</g></svg>')


def _poly(points: np.ndarray) -> str:
    return "M" + " L".join(f"{x:.2f} {y:.2f}" for x, y in points)


def sketch(rng: np.random.Generator, paths: int, per_path: int) -> str:
    """Random-walk scribbles scattered over the page: many short strokes, the worst case for travel. Kept on the
    page (a browser shows nothing beyond it, and neither does the plan)."""
    out = []
    for _ in range(paths):
        start = rng.uniform(20, 980, 2)
        steps = rng.normal(0, 4, (per_path, 2))
        out.append(_poly(np.clip(np.vstack([start, start + np.cumsum(steps, axis=0)]), 0.0, 1000.0)))
    return _svg(out)


def stipple(rng: np.random.Generator, count: int = 1500) -> str:
    """`count` short dashes in random order (stippling / hatching fragments)."""
    pts = rng.uniform(20, 980, (count, 2))
    ang = rng.uniform(0, math.pi, count)
    return _svg([f"M{x:.2f} {y:.2f} l{8 * math.cos(a):.2f} {8 * math.sin(a):.2f}" for (x, y), a in zip(pts, ang,
                                                                                                      strict=True)])


def circles(rng: np.random.Generator) -> str:
    """400 small circles and 200 squiggles, shuffled the way an editor's layer order often leaves them."""
    paths = []
    for x, y, r in zip(rng.uniform(40, 960, 400), rng.uniform(40, 960, 400), rng.uniform(3, 25, 400), strict=True):
        paths.append(f"M{x - r:.2f} {y:.2f} a{r:.2f} {r:.2f} 0 1 0 {2 * r:.2f} 0 a{r:.2f} {r:.2f} 0 1 0 {-2 * r:.2f} 0")
    for _ in range(200):
        start = rng.uniform(40, 960, 2)
        paths.append(_poly(start + np.cumsum(rng.normal(0, 6, (12, 2)), axis=0)))
    rng.shuffle(paths)
    return _svg(paths)


def hatching(rng: np.random.Generator) -> str:
    """Hatched rectangles whose lines were written as separate paths, all in one direction."""
    paths = []
    for _ in range(30):
        x0, y0 = rng.uniform(20, 800, 2)
        w, h = rng.uniform(40, 180, 2)
        for k in range(int(h // 6)):
            y = y0 + 6 * k
            paths.append(f"M{x0:.2f} {y:.2f} H{x0 + w:.2f}")
    return _svg(paths)


def text_page() -> str:
    """A page of single-stroke text, stroke by stroke in reading order."""
    words = ("the quick brown fox jumps over the lazy dog " * 3).split()
    rows = [" ".join(words[i : i + 6]) for i in range(0, len(words), 6)]
    lines = text_lines("\n".join(rows), cap_height=20.0)
    flipped = [np.column_stack([line[:, 0] + 20, 60 - line[:, 1]]) for line in lines]
    return _svg([_poly(line) for line in flipped], size=1000.0)


def _greedy_plan(path: Path, reference: Plan) -> Plan:
    """The same placement, but ordered by plain greedy nearest-neighbour (after the same clean-up)."""
    placed = plan_file(path, PlanOptions(optimize=False))
    lines = join_touching(drop_fine_points(list(placed.strokes)))
    starts = np.array([line[0] for line in lines])
    ends = np.array([line[-1] for line in lines])
    order, flips = greedy_order(starts, ends, reference.origin)
    return Plan(tuple(arrange(lines, order, flips)))


async def _simulated_seconds(plan: Plan) -> float:
    """Model time the simulator (the arm at speed 1, without waiting for it) takes to draw `plan`."""
    sim = LineUsSim(SimOptions(speed=0))
    host, device = memory_pair("lineus")
    server = asyncio.create_task(sim.serve(device))
    arm = await LineUs.connect(host)
    began = sim.clock.now()
    try:
        await send_plan(arm, plan)
        return sim.clock.now() - began
    finally:
        await arm.close()
        await server


def _timed(func: Callable[[], Plan]) -> tuple[Plan, float]:
    start = time.perf_counter()
    plan = func()
    return plan, time.perf_counter() - start


def run() -> list[Figure]:
    figures: list[Figure] = []
    rng = np.random.default_rng(2024)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        # -- planning speed on 100,000 segments ------------------------------------------------------------------
        big = root / "big.svg"
        big.write_text(sketch(rng, SEGMENTS // 50, 50))
        lines, _, _ = load_drawing(big)
        assert sum(len(line) - 1 for line in lines) == SEGMENTS
        parse_s = min(_timed(lambda: Plan(tuple(load_drawing(big)[0])))[1] for _ in range(2))
        options = PlanOptions(time_budget=0.5)
        _, plan_s = _timed(lambda: plan_lines(lines, options))
        figures.append(Figure("plan 100k segments (fit + optimise, 0.5 s budget)", plan_s, "s", "< 2",
                              plan_s < 2.0))
        figures.append(Figure("read + plan 100k-segment SVG", parse_s + plan_s, "s", "< 2",
                              parse_s + plan_s < 2.0))
        # -- memory: one long generated path, read and planned ----------------------------------------------------
        long_path = root / "long.svg"
        count = 50_000
        steps = " ".join(f"L{i % 100} {(i * 7) % 100}" for i in range(count))
        long_path.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">'
                             f'<path d="M0 0 {steps}" stroke="black" fill="none"/></svg>')
        del steps
        tracemalloc.start()
        drawing = read_drawing(long_path)
        read_peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.reset_peak()
        plan_drawing(drawing, PlanOptions(time_budget=0.2))
        plan_peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        del drawing
        per_segment = max(read_peak, plan_peak) / count
        figures.append(Figure("memory per SVG path segment (peak of read, plan)", per_segment, "B", "<= 200",
                              per_segment <= 200))
        # -- travel: optimised vs file order vs greedy -----------------------------------------------------------
        samples = {
            "scribbles": sketch(rng, 800, 6),
            "stipple": stipple(rng),
            "circles": circles(rng),
            "hatching": hatching(rng),
            "text page": text_page(),
        }
        for name, text in samples.items():
            path = root / f"{name.replace(' ', '_')}.svg"
            path.write_text(text)
            best = plan_file(path, PlanOptions(time_budget=BUDGET))
            as_is = plan_file(path, PlanOptions(optimize=False))
            greedy = _greedy_plan(path, best)
            fb, fa, fg = best.figures(), as_is.figures(), greedy.figures()
            # Only sub-resolution points (< 0.05 mm apart) are dropped: the drawn length stays.
            assert abs(fb.pen_down_length - fa.pen_down_length) < 0.01 * fa.pen_down_length
            ratio = fb.pen_up_travel / fg.pen_up_travel
            figures.append(Figure(f"{name}: pen-up travel, optimised", fb.pen_up_travel / UNITS_PER_MM, "mm",
                                  "<= 0.85 x greedy NN", ratio <= 0.85, fg.pen_up_travel / UNITS_PER_MM,
                                  "greedy NN"))
            simulated = asyncio.run(_simulated_seconds(best))
            off = abs(fb.estimated_seconds - simulated) / simulated
            figures.append(Figure(f"{name}: est. drawing time, optimised", fb.estimated_seconds, "s",
                                  "within 5 % of the simulator", off <= 0.05, simulated, "simulator"))
            figures.append(Figure(f"{name}: pen-up travel, file order", fa.pen_up_travel / UNITS_PER_MM, "mm",
                                  baseline=fb.pen_up_travel / UNITS_PER_MM, baseline_name="optimised"))
            figures.append(Figure(f"{name}: est. drawing time, greedy NN", fg.estimated_seconds, "s",
                                  baseline=fb.estimated_seconds, baseline_name="optimised"))
            figures.append(Figure(f"{name}: est. drawing time, file order", fa.estimated_seconds, "s",
                                  baseline=fb.estimated_seconds, baseline_name="optimised"))
    return figures


if __name__ == "__main__":
    for figure in run():
        ratio = f"  ({figure.ratio:.3f} × {figure.baseline_name})" if figure.ratio else ""
        print(f"{figure.name:55s} {figure.value:12.3f} {figure.unit:3s} {figure.target:28s} {figure.meets_target}"
              f"{ratio}")
