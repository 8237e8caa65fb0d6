"""Where people wait on the command line: help, shell completion and a status query, each timed as the whole
command a user runs (a fresh process, start-up included), against the floor beside it in the same run.

Every command runs as a fresh process, interleaved with its floor (one of each in turn, median of several rounds),
so load that comes and goes weighs on both; the figure is the process's own CPU time (user + system) and its peak
RSS. The package is byte-compiled first, as `pip install` and `make bytecode` do. The floors: what Python needs to
load the two libraries every command stands on (asyncio for the links, click for the command line), and a
ten-line raw-socket client that sends the same status query to the same simulator.
"""

from __future__ import annotations

import compileall
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from common import Figure, interleaved, ratio_figure
from fabwire.lifeline import spawn

RUNS = 5
STATUS_OVER_FLOOR = 1.25
"""What a status query may cost on top of the libraries every command loads: the raw client needs neither asyncio
nor click, so where those two alone cost over twice the raw client, this is the part fabwire can act on."""
RAW_CLIENT = """
import socket, sys
host, port = sys.argv[1].removeprefix("tcp://").rsplit(":", 1)
with socket.create_connection((host, int(port))) as s:
    s.sendall(b"XYZv3/query=a\\r\\n")
    reply = b""
    while not reply.endswith(b"$\\n"):
        reply += s.recv(65536)
print(len(reply))
"""
DEVICES = '[devices.office]\nkind = "xyz"\nurl = "10.0.0.5"\n[devices.basement]\nkind = "xyz"\nurl = "10.0.0.6"\n'


def fabwire_command() -> list[str]:
    script = Path(sys.executable).with_name("fabwire")
    return [str(script)] if script.exists() else [sys.executable, "-m", "fabwire"]


def completing(words: str, config: Path) -> dict[str, str]:
    """The environment bash gives `fabwire` when Tab is pressed after `words`."""
    return {**os.environ, "FABWIRE_CONFIG": str(config), "_FABWIRE_COMPLETE": "bash_complete", "COMP_WORDS": words,
            "COMP_CWORD": str(len(words.split()) - (0 if words.endswith(" ") else 1))}


def run() -> list[Figure]:
    import fabwire

    compileall.compile_dir(Path(fabwire.__file__).parent, quiet=1)
    fabwire_cmd = fabwire_command()
    sim = spawn([*fabwire_cmd, "sim", "xyz", "--listen", "127.0.0.1:0"], stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL, text=True)
    try:
        assert sim.stdout is not None
        address = sim.stdout.readline().rsplit(" ", 1)[1].strip()
        with tempfile.TemporaryDirectory() as tmp:
            config = Path(tmp, "devices.toml")
            config.write_text(DEVICES)
            quiet = {**os.environ, "FABWIRE_CONFIG": str(config)}
            runs = interleaved({
                "floor": ([sys.executable, "-c", "import asyncio, click"], None),
                "help": ([*fabwire_cmd, "--help"], quiet),
                "complete device": (fabwire_cmd, completing("fabwire xyz status -d b", config)),
                "complete command": (fabwire_cmd, completing("fabwire x", config)),
                "version": ([*fabwire_cmd, "--version"], quiet),
                "raw": ([sys.executable, "-c", RAW_CLIENT, address], None),
                "json": ([*fabwire_cmd, "xyz", "-d", address, "status", "--json"], quiet),
                "panel": ([*fabwire_cmd, "xyz", "-d", address, "status"], quiet),
            }, RUNS)
    finally:
        sim.terminate()
        sim.wait(10)
    floor, raw = runs["floor"], runs["raw"]
    ms = 1000.0
    return [
        Figure("floor: python -c 'import asyncio, click', CPU", floor.cpu * ms, "ms", "(floor)"),
        ratio_figure("fabwire --help, CPU", runs["help"].cpu * ms, "ms", floor.cpu * ms, "floor", 1.5),
        ratio_figure("fabwire --help, peak RSS", runs["help"].rss_mib, "MiB", floor.rss_mib, "floor", 1.5),
        ratio_figure("completion of a device name (fabwire xyz status -d b<Tab>), CPU",
                     runs["complete device"].cpu * ms, "ms", floor.cpu * ms, "floor", 1.5),
        ratio_figure("completion of a command (fabwire x<Tab>), CPU", runs["complete command"].cpu * ms, "ms",
                     floor.cpu * ms, "floor", 1.5),
        Figure("fabwire --version, wall", runs["version"].wall, "s", "<= 0.10", runs["version"].wall <= 0.10),
        Figure("floor: 10-line raw socket client, status query, CPU", raw.cpu * ms, "ms", "(floor)"),
        ratio_figure("xyz status --json (whole command), CPU", runs["json"].cpu * ms, "ms", raw.cpu * ms,
                     "raw socket", 2.0),
        Figure("the floor under it: python -c 'import asyncio, click' vs the raw client, CPU", floor.cpu * ms, "ms",
               "(floor" + ("; by itself over the 2x)" if floor.cpu > 2 * raw.cpu else ")"), None, raw.cpu * ms,
               "raw socket"),
        ratio_figure("xyz status --json (whole command) vs python + asyncio + click, CPU", runs["json"].cpu * ms, "ms",
                     floor.cpu * ms, "floor", STATUS_OVER_FLOOR),
        ratio_figure("xyz status --json (whole command), peak RSS", runs["json"].rss_mib, "MiB", raw.rss_mib,
                     "raw socket", 2.5),
        Figure("xyz status --json (whole command), wall", runs["json"].wall, "s", "<= 0.25",
               runs["json"].wall <= 0.25, raw.wall, "raw socket"),
        ratio_figure("xyz status (panel, whole command), CPU", runs["panel"].cpu * ms, "ms", raw.cpu * ms,
                     "raw socket", 3.0),
    ]
