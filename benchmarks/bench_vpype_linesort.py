"""Line-us plans side by side with vpype's own ordering: the same samples, read and placed by a vpype pipeline
(`read … lineus-fit`), then ordered by fabwire's optimiser (a budget of 1 nominal second of work, and the plugin's
default budget, in proportion to the lines) or by vpype's `linesort` (greedy, and
`--two-opt`, also after `linemerge`) and costed by the same Line-us plan figures: pen-up travel from home and the
estimated drawing time (fabwire also drops points closer than 0.05 mm, which the Line-us cannot draw apart:
that, more than the order, is where its time estimate gains on dense curves). Stipples, the case where a tour
matters most, come in several densities: each must travel at most `STIPPLE_TARGET` times `linesort --two-opt`.
Last, the CPU time of the whole command a user runs to plan the 100,000-segment file with the plugin
(`vpype read … lineus-fit lineus-stat`) against vpype's own `vpype read … linesort`, run side by side, with
`vpype read …` alone beside them (what both share), and the planning alone, after one read, in one process."""

from __future__ import annotations

import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import vpype_cli

from bench_lineus_plot import SEGMENTS, circles, hatching, sketch, stipple, text_page
from common import Figure, cpu_seconds, interleaved, ratio_figure
from fabwire.lineus.kinematics import UNITS_PER_MM
from fabwire.lineus.plot import PlanFigures, PlanOptions
from fabwire.vpype.passes import document_passes, plan_passes, total_figures

BUDGET = 1.0
STIPPLE_TARGET = 0.95
PLUGIN_RUNS = 4
"""Rounds of the whole-command comparison: one command's CPU time varies by about 10 % from run to run on a
busy machine: more rounds, a steadier median."""
T = TypeVar("T")
SAMPLES: tuple[tuple[str, Callable[[np.random.Generator], str]], ...] = (
    ("scribbles", lambda rng: sketch(rng, 800, 6)), ("stipple", stipple), ("circles", circles),
    ("hatching", hatching), ("text page", lambda rng: text_page()),
    ("stipple 600", lambda rng: stipple(rng, 600)), ("stipple 3000", lambda rng: stipple(rng, 3000)),
)
"""The planner benchmark's travel samples."""
VPYPE_ORDERINGS = {
    "linesort": "linesort",
    "linesort --two-opt": "linesort --two-opt",
    "linemerge linesort --two-opt": "linemerge linesort --two-opt",
}


def _figures(document: Any, options: PlanOptions) -> PlanFigures:
    return total_figures(plan_passes(document_passes(document), options))


def _measured(func: Callable[[], T]) -> tuple[T, float]:
    """`func()` and the CPU seconds it took."""
    out: list[T] = []
    cpu = cpu_seconds(lambda: out.append(func()))
    return out[0], cpu


def run() -> list[Figure]:
    figures: list[Figure] = []
    rng = np.random.default_rng(2024)
    samples = {name: make(rng) for name, make in SAMPLES}
    as_placed = PlanOptions(fit=False, optimize=False)
    with tempfile.TemporaryDirectory() as tmp:
        for name, text in samples.items():
            path = Path(tmp) / f"{name.replace(' ', '_')}.svg"
            path.write_text(text)
            placed = vpype_cli.execute(f"read {path} lineus-fit")
            fab, our_cpu = _measured(lambda doc=placed: _figures(doc, PlanOptions(fit=False, time_budget=BUDGET)))
            default = _figures(placed, PlanOptions(fit=False, time_budget=None))
            for label, pipeline in VPYPE_ORDERINGS.items():
                ordered, cpu = _measured(lambda pipe=pipeline, doc=placed: vpype_cli.execute(pipe, doc))
                other = _figures(ordered, as_placed)
                strict = name.startswith("stipple") and label == "linesort --two-opt"
                limit = STIPPLE_TARGET if strict else 1.0
                figures.append(Figure(f"{name}: pen-up travel, fabwire vs {label}", fab.pen_up_travel / UNITS_PER_MM,
                                      "mm", f"<= {limit:g} x {label}" if strict else f"<= {label}",
                                      fab.pen_up_travel <= limit * other.pen_up_travel,
                                      other.pen_up_travel / UNITS_PER_MM, label))
                figures.append(Figure(f"{name}: est. time, fabwire vs {label}", fab.estimated_seconds, "s",
                                      baseline=other.estimated_seconds, baseline_name=label))
                if label == "linesort":
                    figures.append(Figure(f"{name}: pen-up travel, plugin default vs {label}",
                                          default.pen_up_travel / UNITS_PER_MM, "mm", f"<= {label}",
                                          default.pen_up_travel <= other.pen_up_travel,
                                          other.pen_up_travel / UNITS_PER_MM, label))
                if label == "linesort --two-opt":
                    figures.append(Figure(f"{name}: ordering CPU, fabwire vs {label}", our_cpu, "s",
                                          f"<= {BUDGET:g} s budget + 0.5", our_cpu <= BUDGET + 0.5, cpu, label))
        figures.extend(_plugin_planning(Path(tmp), rng))
    return figures


def _plugin_planning(folder: Path, rng: np.random.Generator) -> list[Figure]:
    """CPU seconds of the whole command a user runs, `vpype read big.svg lineus-fit lineus-stat` (the plugin's
    default planning), against `vpype read big.svg linesort`, on the planner benchmark's 100,000-segment
    scribbles: fresh processes side by side, one of each in turn, the median of `PLUGIN_RUNS` rounds. Beside
    them `vpype read big.svg` alone, what both commands share (start-up, plugins, reading): no ordering can take
    the ratio below that share."""
    big = folder / "big.svg"
    big.write_text(sketch(rng, SEGMENTS // 50, 50))
    vpype = str(Path(sys.executable).with_name("vpype"))
    runs = interleaved({"ours": ([vpype, "read", str(big), "lineus-fit", "lineus-stat", "--json"], None),
                        "linesort": ([vpype, "read", str(big), "linesort"], None),
                        "read": ([vpype, "read", str(big)], None)}, PLUGIN_RUNS)
    ours, theirs = _planning_after_read(big)
    return [ratio_figure("100k segments: vpype read + lineus-fit + lineus-stat, CPU", runs["ours"].cpu, "s",
                         runs["linesort"].cpu, "vpype read + linesort", 1.0),
            Figure("100k segments: vpype read alone (shared by both), CPU", runs["read"].cpu, "s",
                   baseline=runs["linesort"].cpu, baseline_name="vpype read + linesort"),
            ratio_figure(f"100k segments: the planning after read, lineus-fit + lineus-stat, CPU (one vpype process, "
                         f"median of {PLANNING_ROUNDS} turns each)", ours, "s", theirs, "linesort", 1.0)]


PLANNING_ROUNDS = 9
_PLANNING = r"""
import contextlib, copy, io, statistics, sys, time
import vpype_cli
read = vpype_cli.execute(f"read {sys.argv[1]}")
took = {"ours": [], "linesort": []}
for turn in range(int(sys.argv[2]) + 1):  # a first turn of each warms up
    for name, pipeline in (("ours", "lineus-fit lineus-stat --json"), ("linesort", "linesort")):
        doc = copy.deepcopy(read)
        began = time.process_time()
        with contextlib.redirect_stdout(io.StringIO()):
            vpype_cli.execute(pipeline, doc)
        if turn:
            took[name].append(time.process_time() - began)
print(statistics.median(took["ours"]), statistics.median(took["linesort"]))
"""


def _planning_after_read(big: Path) -> tuple[float, float]:
    """CPU seconds of the plugin's planning and of `linesort`, each on a copy of one document read once, in turn
    in one vpype process: the part the two commands do not share, without the start-up and read that make
    whole-command times vary by more than it."""
    done = subprocess.run([sys.executable, "-c", _PLANNING, str(big), str(PLANNING_ROUNDS)], capture_output=True,
                          text=True, check=True, timeout=600)
    ours, theirs = (float(x) for x in done.stdout.split())
    return ours, theirs


if __name__ == "__main__":
    for figure in run():
        ratio = f"  ({figure.ratio:.3f} × {figure.baseline_name})" if figure.ratio else ""
        print(f"{figure.name:60s} {figure.value:10.2f} {figure.unit:3s} {figure.meets_target}{ratio}")
