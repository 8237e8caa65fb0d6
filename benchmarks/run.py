"""Run every benchmark (benchmarks/bench_*.py) and print one table; a JSON copy goes to benchmarks/results.json.

Usage: python benchmarks/run.py [NAME ...]   (names filter by module, e.g. `mmu` or `threew`)
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import platform
import sys
import tempfile
import time
import traceback
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path

from rich.console import Console
from rich.table import Table

HERE = Path(__file__).resolve().parent
BUDGET_S = 300
"""`make bench` is meant to finish within five minutes."""
sys.path.insert(0, str(HERE))

from common import Figure  # noqa: E402


@contextlib.contextmanager
def stderr_kept() -> Iterator[list[str]]:
    """What is written to standard error meanwhile (by this process and its children, at the descriptor),
    handed over at the end: a benchmark that prints a traceback has failed, even when it returned figures."""
    said: list[str] = []
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as kept:
        os.dup2(kept.fileno(), 2)
        try:
            yield said
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            kept.seek(0)
            said.append(kept.read().decode(errors="replace"))


def discover(filters: list[str]) -> list[str]:
    names = sorted(p.stem for p in HERE.glob("bench_*.py"))
    return [n for n in names if not filters or any(f in n for f in filters)]


def fmt(value: float | None) -> str:
    if value is None:
        return ""
    if value == 0 or 0.01 <= abs(value) < 1e6:
        return f"{value:,.3f}".rstrip("0").rstrip(".")
    return f"{value:,.3g}"


def main(argv: list[str]) -> int:
    console = Console(width=150)
    results: list[dict[str, object]] = []
    table = Table(title="fabwire benchmarks")
    for column in ("benchmark", "figure", "value", "unit", "target", "met", "baseline", "ratio"):
        table.add_column(column, justify="right" if column in ("value", "ratio", "baseline") else "left")
    failed = False
    began = time.perf_counter()
    for name in discover(argv):
        console.print(f"[dim]running {name} …[/dim]")
        started = time.perf_counter()
        with stderr_kept() as said:
            try:
                figures: list[Figure] = importlib.import_module(name).run()
            except Exception:
                figures = []
                print(traceback.format_exc(), file=sys.stderr)
        took = time.perf_counter() - started
        if said:
            sys.stderr.write(said[0])
        if not figures or "Traceback" in said[0]:
            failed = True
            console.print(f"[red]{name} failed: a traceback above[/red]")
            continue
        console.print(f"[dim]{name} took {took:.1f} s[/dim]")
        for fig in figures:
            met = "—" if fig.meets_target is None else ("yes" if fig.meets_target else "NO")
            baseline = f"{fmt(fig.baseline)} ({fig.baseline_name})" if fig.baseline is not None else ""
            table.add_row(name.removeprefix("bench_"), fig.name, fmt(fig.value), fig.unit,
                          fig.target or "(reference)", met, baseline, fmt(fig.ratio))
            results.append({"benchmark": name, "figure": fig.name, "value": fig.value, "unit": fig.unit,
                            "target": fig.target, "meets_target": fig.meets_target, "baseline": fig.baseline,
                            "baseline_name": fig.baseline_name, "ratio": fig.ratio})
    console.print(table)
    total = time.perf_counter() - began
    over = "" if total <= BUDGET_S else f" (over the {BUDGET_S} s budget)"
    console.print(f"all benchmarks took {total:.0f} s{over}")
    record = {"when": datetime.now(UTC).isoformat(timespec="seconds"), "python": platform.python_version(),
              "machine": platform.machine(), "results": results}
    (HERE / "results.json").write_text(json.dumps(record, indent=2) + "\n")
    console.print(f"JSON copy: {HERE / 'results.json'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
