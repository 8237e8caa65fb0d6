"""Where output goes: results on stdout (JSON with --json), people's text and progress on stderr."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from rich.console import Console


def _default(value: object) -> object:
    if isinstance(value, bytes):
        return value.decode("latin-1")
    if hasattr(value, "__dict__"):
        return vars(value)
    return str(value)


@dataclass
class Output:
    json_mode: bool = False
    err: Console = field(default_factory=lambda: Console(stderr=True, highlight=False))
    out: Console = field(default_factory=lambda: Console(highlight=False, soft_wrap=True))

    def result(self, data: Any, human: Callable[[], None] | str | None = None) -> None:
        """Print a command's result: `data` as one JSON document, or `human` for people."""
        if self.json_mode:
            sys.stdout.write(json.dumps(data, default=_default, ensure_ascii=False) + "\n")
            sys.stdout.flush()
        elif callable(human):
            human()
        elif human is not None:
            self.out.print(human, markup=False)  # device names and replies may contain [brackets]
        else:
            self.out.print(data)

    def event(self, data: dict[str, Any], human: str) -> None:
        """One item of a stream (monitor, progress): a JSON line per event, or a line of text."""
        if self.json_mode:
            sys.stdout.write(json.dumps(data, default=_default, ensure_ascii=False) + "\n")
            sys.stdout.flush()
        else:
            self.out.print(human, markup=False)

    def note(self, text: str) -> None:
        """Text for people only, never on stdout."""
        self.err.print(text, markup=False)
