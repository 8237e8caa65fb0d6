"""The agent under load: `fabwire serve` monitoring 1,000 simulated printers at 1 Hz on one core (poll punctuality
and its CPU), the API's p99 latency meanwhile, and the dashboard's first meaningful paint with 50 machines.

The simulators run in their own process, the agent in another, the load generator here. On a shared machine the
agent gets only its share of a core, so its CPU cost per poll is reported beside the punctuality it achieved.

The CPU per poll is compared with a bare asyncio poller under the same conditions: the agent only polling (no
burner, no API traffic), in turns with the bare poller against the same simulators. The figure with the burner and
the API's requests, whose CPU counts per poll too, is a row of its own.
"""

from __future__ import annotations

import os
import random
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import httpx

try:
    from bench_xyz import _start as start_printers
    from bench_xyz import _stop
    from common import Figure, ratio_figure
except ImportError:  # imported as benchmarks.bench_agent
    from benchmarks.bench_xyz import _start as start_printers
    from benchmarks.bench_xyz import _stop
    from benchmarks.common import Figure, ratio_figure

PRINTERS = 1000
SMALL_BENCH = 250
"""The same measurements on a quarter of the bench: the API's latency must not grow with the number of machines."""
MEASURE_S = 10.0
SETTLE_S = 4.0
DASHBOARD_PRINTERS = 50
POLL_ROUNDS = 1
"""Turns of the agent that only polls and the bare poller, one after the other against the same printers."""
SRC = Path(__file__).resolve().parents[1] / "src"
BURNER = "while True: pass"
"""A CPU burner beside the agent, as on a machine busy with other work."""

BARE_POLLER = """
import asyncio, math, resource, sys, time

async def printer(port, offset, seconds, counts, grid):
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    loop = asyncio.get_running_loop()
    slot = loop.time() + offset
    if grid:
        slot = math.ceil(slot / grid) * grid
    end = loop.time() + seconds
    while True:
        await asyncio.sleep(max(0.0, slot - loop.time()))
        if loop.time() >= end:
            break
        writer.write(b"XYZv3/query=a\\r\\n")
        await reader.readuntil(b"$\\n")
        counts[0] += 1
        slot += 1.0
        if grid:
            slot = round(slot / grid) * grid
    writer.close()

async def main(ports, seconds, grid):
    counts = [0]
    tasks = [printer(p, i / len(ports), seconds + 2.0, counts, grid) for i, p in enumerate(ports)]
    runs = asyncio.gather(*tasks)
    await asyncio.sleep(2.0)  # connected and settled
    before, polls = resource.getrusage(resource.RUSAGE_SELF), counts[0]
    await asyncio.sleep(seconds)
    after, done = resource.getrusage(resource.RUSAGE_SELF), counts[0] - polls
    await runs
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    print(cpu / max(done, 1))

asyncio.run(main([int(p) for p in sys.argv[3:]], float(sys.argv[1]), float(sys.argv[2])))
"""
"""The floor for a poll's cost: a bare asyncio loop sending each printer the same status query at 1 Hz and
reading the reply, nothing else (no parsing, no state, no history, no API). Its polls are spread evenly over the
second; given a grid step (argv[2], 0 for none) they start on it, as the agent's do."""


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("FABWIRE_")}
    env["PYTHONPATH"] = str(SRC)
    return env


def _agent(ports: list[int], where: Path, *extra: str) -> tuple[subprocess.Popen[str], str]:
    config = where / "devices.toml"
    config.write_text("".join(f'[devices.p{i}]\nkind = "xyz"\nurl = "tcp://127.0.0.1:{port}"\n\n'
                              for i, port in enumerate(ports)), encoding="utf-8")
    command = [sys.executable, "-m", "fabwire", "serve", "--listen", "127.0.0.1:0", "--config", str(config),
               "--state-dir", str(where / "state"), *extra]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=_env())
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if "listening on " not in line:
        proc.kill()
        raise RuntimeError(f"the agent did not start: {line!r}")
    return proc, line.split("listening on ", 1)[1].strip().rstrip("/")


def _cpu_seconds(pid: int) -> float:
    """CPU seconds of the agent's process and its children (its links' process), from /proc."""
    parents: dict[int, int] = {}
    ticks: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:  # ended meanwhile
            continue
        parents[int(entry.name)] = int(fields[1])
        ticks[int(entry.name)] = int(fields[11]) + int(fields[12])
    tree = {pid}
    grew = True  # a child's pid may be lower than its parent's: go round until none joins
    while grew:
        grew = False
        for candidate, parent in parents.items():
            if parent in tree and candidate not in tree:
                tree.add(candidate)
                grew = True
    return sum(ticks.get(p, 0) for p in tree) / os.sysconf("SC_CLK_TCK")


def _percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


@dataclass
class Measured:
    cpu: float
    """Agent CPU seconds per second."""
    polls: float
    """Polls per second."""
    late: float
    """Share of polls that started over half an interval late."""
    latencies: list[float]
    """Seconds per API request."""

    @property
    def per_poll_ms(self) -> float:
        return 1000.0 * self.cpu / max(self.polls, 1e-9)

    def p99_ms(self) -> float:
        return _percentile(self.latencies, 0.99) * 1000


def _measure(printers: int, *, traffic: bool = True, ports: list[int] | None = None) -> Measured:
    """The agent monitoring `printers` for MEASURE_S. With `traffic`, a CPU burner runs beside it and an API request
    is timed every 20 ms (their CPU is the agent's too); without, it only polls, as the bare poller does. `ports`:
    simulators already running (else its own are started and stopped)."""
    sims = None
    if ports is None:
        sims, ports = start_printers(printers)
    where = Path(tempfile.mkdtemp(prefix="fabwire-bench-agent-"))
    agent = burner = None
    try:
        agent, url = _agent(ports, where)
        with httpx.Client(base_url=url, timeout=30) as client:
            deadline = time.monotonic() + 120
            while client.get("/api/v1/agent").json()["online"] < printers:
                if time.monotonic() > deadline:
                    raise RuntimeError("the printers did not all come online")
                time.sleep(0.5)
            if traffic:
                burner = subprocess.Popen([sys.executable, "-c", BURNER])
            time.sleep(SETTLE_S)
            ids = [d["id"] for d in client.get("/api/v1/devices").json()]
            before = client.get("/api/v1/agent").json()
            cpu_before, wall_before = _cpu_seconds(agent.pid), time.monotonic()
            latencies: list[float] = []
            while traffic and time.monotonic() - wall_before < MEASURE_S:
                path = random.choice((f"/api/v1/devices/{random.choice(ids)}/state", "/api/v1/agent",
                                      f"/api/v1/devices/{random.choice(ids)}"))
                started = time.perf_counter()
                response = client.get(path)
                latencies.append(time.perf_counter() - started)
                response.raise_for_status()
                time.sleep(0.02)
            if not traffic:
                time.sleep(MEASURE_S)
            wall = time.monotonic() - wall_before
            cpu = (_cpu_seconds(agent.pid) - cpu_before) / wall
            after = client.get("/api/v1/agent").json()
    finally:
        for proc in (burner, agent):
            if proc is not None:
                _stop(proc)
        if sims is not None:
            _stop(sims)
        shutil.rmtree(where, ignore_errors=True)
    polls = after["polls"] - before["polls"]
    return Measured(cpu, polls / wall, (after["late_polls"] - before["late_polls"]) / max(polls, 1), latencies)


def _bare_per_poll_ms(ports: list[int], grid: float = 0.0) -> float:
    """CPU per poll of the bare asyncio loop polling the simulated printers at `ports` at 1 Hz for MEASURE_S (its
    polls on a grid of `grid` seconds if not 0)."""
    out = subprocess.run([sys.executable, "-c", BARE_POLLER, str(MEASURE_S), str(grid), *map(str, ports)],
                         capture_output=True, text=True, check=True, timeout=120)
    return float(out.stdout.strip()) * 1000


def polling_side_by_side(ports: list[int], rounds: int = POLL_ROUNDS) -> tuple[list[float], list[float], float]:
    """CPU per poll (ms) of the agent that only polls and of the bare poller, in turns against the same simulated
    printers (at `ports`) under the same conditions (no burner, no API traffic for either): `rounds` figures of
    each, and once the bare poller with its polls on the agent's grid."""
    from fabwire.agent.linkside import POLL_TICK_S

    agent: list[float] = []
    bare: list[float] = []
    for _ in range(rounds):
        agent.append(_measure(len(ports), traffic=False, ports=ports).per_poll_ms)
        bare.append(_bare_per_poll_ms(ports))
    on_grid = _bare_per_poll_ms(ports, POLL_TICK_S)
    return agent, bare, on_grid


def bench_figures() -> list[Figure]:
    # One set of simulated printers for every row: the smaller benches poll the first of them, so each row runs
    # against the same simulator process (the ones not polled wait idle, costing no CPU).
    sims, ports = start_printers(PRINTERS)
    try:
        large = _measure(PRINTERS, ports=ports)
        load = os.getloadavg()[0]
        small = _measure(SMALL_BENCH, ports=ports[:SMALL_BENCH])
        agent, bare, on_grid = polling_side_by_side(ports[:SMALL_BENCH])
    finally:
        _stop(sims)
    polling, floor = statistics.median(agent), statistics.median(bare)
    turns = ", ".join(f"{a:.3f}/{b:.3f}" for a, b in zip(agent, bare, strict=True))
    return [
        Figure(f"agent API latency p99, {PRINTERS} printers polled at 1 Hz, a CPU burner beside it "
               f"({len(large.latencies)} requests; load average {load:.1f})", large.p99_ms(), "ms", "<= 50",
               large.p99_ms() <= 50),
        Figure(f"the same with {SMALL_BENCH} printers ({len(small.latencies)} requests)", small.p99_ms(), "ms",
               "<= 50", small.p99_ms() <= 50),
        ratio_figure(f"API p99 at {PRINTERS} printers vs at {SMALL_BENCH} (independent of the bench's size)",
                     large.p99_ms(), "ms", small.p99_ms(), f"p99 at {SMALL_BENCH}", 1.5),
        Figure("API latency median at 1,000 printers", _percentile(large.latencies, 0.5) * 1000, "ms",
               "(reference)"),
        ratio_figure(f"agent CPU per poll, {SMALL_BENCH} printers, polling only (poll, state, history; median of "
                     f"{len(agent)} turns with the bare poller, agent/bare ms: {turns})", polling, "ms CPU", floor,
                     "bare asyncio poller", 1.5),
        Figure(f"bare asyncio poller CPU per poll, {SMALL_BENCH} printers, its polls on the agent's grid as the "
               f"agent's are (reference: the floor for that schedule; the agent is {polling / on_grid:.2f}x it)",
               on_grid, "ms CPU", "(reference)"),
        Figure(f"agent CPU per poll, {SMALL_BENCH} printers, a burner beside it and 50 API requests/s (their CPU "
               f"counted per poll; vs the bare poller: {small.per_poll_ms / floor:.2f}x)", small.per_poll_ms,
               "ms CPU", "(reference)"),
        Figure(f"agent CPU per poll, {PRINTERS} printers", large.per_poll_ms, "ms CPU", "< 1 (1,000 at 1 Hz on a core)",
               large.per_poll_ms < 1.0),
        Figure(f"agent polls done, {PRINTERS} printers at 1 Hz (agent CPU {large.cpu:.2f} core)", large.polls,
               "polls/s", f">= {PRINTERS * 0.98:,.0f}", large.polls >= PRINTERS * 0.98),
        Figure(f"late polls (over half an interval), {PRINTERS} printers", 100.0 * large.late, "%", "0",
               large.late == 0),
        Figure(f"late polls, {SMALL_BENCH} printers (agent CPU {small.cpu:.2f} core)", 100.0 * small.late, "%", "0",
               small.late == 0),
    ]


def dashboard_figures() -> list[Figure]:
    from playwright.sync_api import sync_playwright

    chromium = shutil.which("chromium") or "/usr/bin/chromium"
    sims, ports = start_printers(DASHBOARD_PRINTERS)
    where = Path(tempfile.mkdtemp(prefix="fabwire-bench-dashboard-"))
    agent = None
    paints: list[float] = []
    try:
        agent, url = _agent(ports, where)
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=chromium, args=["--no-sandbox"])
            for _ in range(3):
                page = browser.new_page()
                page.goto(url + "/")
                page.wait_for_function(f"document.querySelectorAll('article.card').length >= {DASHBOARD_PRINTERS}")
                paints.append(page.evaluate("performance.getEntriesByName('fabwire-cards')[0].startTime"))
                page.close()
            browser.close()
    finally:
        if agent is not None:
            _stop(agent)
        _stop(sims)
        shutil.rmtree(where, ignore_errors=True)
    median = sorted(paints)[len(paints) // 2]
    return [Figure(f"dashboard first meaningful paint, {DASHBOARD_PRINTERS} machines (all cards drawn; median of 3)",
                   median, "ms", "< 1000", median < 1000)]


def run() -> list[Figure]:
    return bench_figures() + dashboard_figures()


if __name__ == "__main__":
    for figure in run():
        print(f"{figure.name}: {figure.value:,.3f} {figure.unit}  target {figure.target}  met {figure.meets_target}")
