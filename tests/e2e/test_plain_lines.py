"""Where a view's lines go on stderr: off a terminal, plain lines that read as rich's would and need no rich; on a
terminal, or where rich is told to treat the stream as one, rich's console."""

from __future__ import annotations

import io
import os
import pty
import subprocess
import sys

import pytest
from rich.console import Console

from clitools import cli_env
from fabwire.console import RICH_TERMINAL_VARIABLES, Output, PlainLines
from fabwire.xyz.live import JobView
from fabwire.xyz.status import Status

STATUSES = [
    # (a status reply's fields, as a printer sends them)
    ["j:9511", "t:1,22,0", "b:20"],
    ["j:9520", "t:1,36,210", "b:20"],
    ["j:9505,1", "t:1,120,210"],
    ["j:9505,2", "t:1,205,210", "b:55", 'O:{"nozzle":"210","bed":"60"}', "d:42,10,14"],
    ["j:9506", "t:1,205,210", "b:55", "d:42,10,14"],
    ["j:9509", "t:1,150,0", "b:40", "d:100,24,0"],
]


def show(console: Console | PlainLines) -> None:
    """What a non-terminal job view prints through `console`: the upload, then every status in turn."""
    with JobView(Output(), console, "part.3w") as view:  # type: ignore[arg-type]
        view.upload(4096, 8192)
        view.upload(8192, 8192)
        for fields in STATUSES:
            view.show(Status.parse(fields))


def test_plain_lines_read_as_richs_off_a_terminal() -> None:
    rich_buffer, plain_buffer = io.StringIO(), io.StringIO()
    show(Console(file=rich_buffer, force_terminal=False, highlight=False, markup=False, emoji=False))
    show(PlainLines(plain_buffer))
    assert plain_buffer.getvalue() == rich_buffer.getvalue()
    assert len(plain_buffer.getvalue().splitlines()) == 1 + len(STATUSES)


PROBE = ("import sys\nfrom fabwire.console import Output\nlines = Output().lines_err()\nlines.print('a line')\n"
         "print(type(lines).__name__, 'rich' in sys.modules)\n")

ENVIRONMENTS = [
    # (what stderr is, a variable rich reads, the console expected, whether rich is loaded)
    ("pipe", None, "PlainLines", False),
    *[("pipe", name, "Console", True) for name in RICH_TERMINAL_VARIABLES],
    ("terminal", None, "Console", True),
]


@pytest.mark.parametrize(("stderr", "variable", "expected", "rich_loaded"), ENVIRONMENTS,
                         ids=[f"{s} {v or ''}".strip() for s, v, *_ in ENVIRONMENTS])
def test_stderr_gets_rich_only_where_rich_could_draw(stderr: str, variable: str | None, expected: str,
                                                     rich_loaded: bool) -> None:
    env = {k: v for k, v in cli_env().items() if k not in RICH_TERMINAL_VARIABLES}
    if variable is not None:
        env[variable] = "1"
    if stderr == "terminal":
        leader, follower = pty.openpty()
        try:
            result = subprocess.run([sys.executable, "-c", PROBE], stdout=subprocess.PIPE, stderr=follower, env=env,
                                    timeout=60, text=True)
        finally:
            os.close(follower)
            said = os.read(leader, 4096).decode()
            os.close(leader)
    else:
        result = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, env=env, timeout=60, text=True)
        said = result.stderr
    assert result.returncode == 0
    assert result.stdout.split() == [expected, str(rich_loaded)]
    assert "a line" in said
