"""What every device showcase gets: where to write, how fast the simulators run, where to talk, what to record."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from rich.console import Console
from rich.rule import Rule
from rich.text import Text

from fabwire.demo.summary import Summary


@dataclass
class DemoContext:
    out_dir: Path
    speed: float
    err: Console
    """People's text and progress bars (stderr)."""
    summary: Summary
    quiet_bars: bool = False
    """Hide live progress bars (JSON mode keeps stderr to plain lines)."""

    def heading(self, text: str) -> None:
        self.err.print(Rule(Text(text, style="bold"), align="left"))

    def say(self, text: str, *, markup: bool = False) -> None:
        """Print a line as it is; with `markup`, the demo's own rich markup is applied (escape what goes in it)."""
        self.err.print(text, markup=markup)
