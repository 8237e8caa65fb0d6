"""How fast the command starts: `fabwire --version` and a status query, against a minimal raw-socket client.

Each command runs as a fresh process (as from a script or a shell prompt) against one XYZ simulator on loopback;
the figure is the median of several runs, wall time and the child's CPU time (user + system). The package is
byte-compiled first, as `pip install` does, so a development checkout run without bytecode caching
(PYTHONDONTWRITEBYTECODE) is measured like an installed copy. The floor is what Python needs to load the two
libraries every command stands on (asyncio for the links, click for the command line) and nothing else.
"""

from __future__ import annotations

import compileall
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

from common import Figure
from fabwire.lifeline import spawn

RUNS = 9
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


def fabwire_command() -> list[str]:
    script = Path(sys.executable).with_name("fabwire")
    return [str(script)] if script.exists() else [sys.executable, "-m", "fabwire"]


def timed(args: list[str]) -> tuple[float, float]:
    """Wall and CPU seconds of one run of `args` (which must succeed)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def median_of(args: list[str]) -> tuple[float, float]:
    timed(args)  # warm the file cache
    runs = [timed(args) for _ in range(RUNS)]
    return statistics.median(w for w, _ in runs), statistics.median(c for _, c in runs)


def run() -> list[Figure]:
    import fabwire

    compileall.compile_dir(Path(fabwire.__file__).parent, quiet=1)
    fabwire_cmd = fabwire_command()
    sim = spawn([*fabwire_cmd, "sim", "xyz", "--listen", "127.0.0.1:0"], stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL, text=True)
    try:
        assert sim.stdout is not None
        address = sim.stdout.readline().rsplit(" ", 1)[1].strip()
        version_wall, version_cpu = median_of([*fabwire_cmd, "--version"])
        _, floor_cpu = median_of([sys.executable, "-c", "import asyncio, click"])
        raw_wall, raw_cpu = median_of([sys.executable, "-c", RAW_CLIENT, address])
        json_wall, json_cpu = median_of([*fabwire_cmd, "xyz", "-d", address, "status", "--json"])
        panel_wall, panel_cpu = median_of([*fabwire_cmd, "xyz", "-d", address, "status"])
    finally:
        sim.terminate()
        sim.wait(10)
    return [
        Figure("fabwire --version, wall", version_wall, "s", "<= 0.10", version_wall <= 0.10),
        Figure("fabwire --version, CPU", version_cpu, "s"),
        Figure("floor: python + asyncio + click, CPU", floor_cpu, "s"),
        Figure("xyz status --json, wall", json_wall, "s", "<= 0.25", json_wall <= 0.25, raw_wall, "raw socket"),
        Figure("xyz status --json, CPU", json_cpu, "s", "<= 0.15", json_cpu <= 0.15, raw_cpu, "raw socket"),
        Figure("xyz status (panel), wall", panel_wall, "s", "<= 0.25", panel_wall <= 0.25, raw_wall, "raw socket"),
        Figure("xyz status (panel), CPU", panel_cpu, "s", "<= 0.15", panel_cpu <= 0.15, raw_cpu, "raw socket"),
    ]
