"""Run every benchmark (benchmarks/bench_*.py) and print one table; a JSON copy goes to benchmarks/results.json.

Usage: python benchmarks/run.py [NAME ...]   (names filter by module, e.g. `mmu` or `threew`)
"""

from __future__ import annotations

import importlib
import json
import platform
import sys
import time
import traceback
from datetime import UTC, datetime
from pathlib import Path

from rich.console import Console
from rich.table import Table

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from common import Figure  # noqa: E402


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
    for name in discover(argv):
        console.print(f"[dim]running {name} …[/dim]")
        started = time.perf_counter()
        try:
            figures: list[Figure] = importlib.import_module(name).run()
        except Exception:
            failed = True
            console.print(f"[red]{name} failed:[/red]\n{traceback.format_exc()}")
            continue
        console.print(f"[dim]{name} took {time.perf_counter() - started:.1f} s[/dim]")
        for fig in figures:
            met = "" if fig.meets_target is None else ("yes" if fig.meets_target else "NO")
            baseline = f"{fmt(fig.baseline)} ({fig.baseline_name})" if fig.baseline is not None else ""
            table.add_row(name.removeprefix("bench_"), fig.name, fmt(fig.value), fig.unit, fig.target, met,
                          baseline, fmt(fig.ratio))
            results.append({"benchmark": name, "figure": fig.name, "value": fig.value, "unit": fig.unit,
                            "target": fig.target, "meets_target": fig.meets_target, "baseline": fig.baseline,
                            "baseline_name": fig.baseline_name, "ratio": fig.ratio})
    console.print(table)
    record = {"when": datetime.now(UTC).isoformat(timespec="seconds"), "python": platform.python_version(),
              "machine": platform.machine(), "results": results}
    (HERE / "results.json").write_text(json.dumps(record, indent=2) + "\n")
    console.print(f"JSON copy: {HERE / 'results.json'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
