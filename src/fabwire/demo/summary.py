"""What the showcase did, timed: the closing table for people and the JSON document for scripts."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rich.table import Table
from rich.text import Text

from fabwire import units


@dataclass
class Step:
    device: str
    name: str
    seconds: float = 0.0
    ok: bool = False
    detail: str = ""
    files: list[Path] = field(default_factory=list)


@dataclass
class Summary:
    speed: float
    out_dir: Path
    steps: list[Step] = field(default_factory=list)
    simulators: list[dict[str, Any]] = field(default_factory=list)
    error: str | None = None
    started: float = field(default_factory=time.monotonic)
    total_seconds: float = 0.0

    @contextmanager
    def step(self, device: str, name: str) -> Iterator[Step]:
        """Time one step; it counts as done only if the block ends without an exception."""
        step = Step(device, name)
        self.steps.append(step)
        began = time.monotonic()
        try:
            yield step
            step.ok = True
        finally:
            step.seconds = time.monotonic() - began

    def record(self, device: str, name: str, seconds: float, detail: str = "", files: list[Path] | None = None) -> Step:
        """A step timed by the caller (e.g. one phase of a longer call)."""
        step = Step(device, name, seconds, True, detail, list(files or []))
        self.steps.append(step)
        return step

    @property
    def files(self) -> list[Path]:
        return [f for step in self.steps for f in step.files]

    @property
    def ok(self) -> bool:
        return self.error is None and all(step.ok for step in self.steps)

    def finish(self) -> None:
        self.total_seconds = time.monotonic() - self.started

    def to_dict(self) -> dict[str, Any]:
        return {
            "ok": self.ok,
            "error": self.error,
            "speed": self.speed,
            "out": str(self.out_dir),
            "seconds": round(self.total_seconds, 2),
            "steps": [{"device": s.device, "step": s.name, "seconds": round(s.seconds, 2), "ok": s.ok,
                       "detail": s.detail, "files": [str(f) for f in s.files]} for s in self.steps],
            "files": [{"path": str(f), "size_bytes": f.stat().st_size if f.exists() else None} for f in self.files],
            "simulators": self.simulators,
        }

    def table(self) -> Table:
        table = Table(title=f"fabwire demo — {units.elapsed(self.total_seconds)} at speed ×{self.speed:g}",
                      title_justify="left")
        table.add_column("device", style="bold")
        table.add_column("step")
        table.add_column("time", justify="right")
        table.add_column("result", overflow="fold")
        table.add_column("output", overflow="fold")  # a path too long for its cell goes on, never cut with "…"
        for step in self.steps:
            result = Text("ok") if step.ok else Text("failed", style="red")
            if step.detail:
                result.append(f" — {step.detail}")
            table.add_row(step.device, step.name, units.elapsed(step.seconds), result,
                          "\n".join(_shown(f) for f in step.files))
        return table


def _shown(path: Path) -> str:
    try:
        return f"{path} ({path.stat().st_size:,} bytes)"
    except OSError:
        return f"{path} (missing)"
