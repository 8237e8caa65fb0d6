"""The agent's memory under attack: `fabwire serve` (a real process; the printers' simulators in another) while
clients send parallel 60 MB uploads, 200 MB action bodies (declared and chunked) and thousands of half-sent
requests. The figure is the growth of its resident memory over its idle size, sampled every 20 ms, a fresh agent
for each attack; the target is what the boundary promises: at most `--max-upload` plus a constant per machine
that takes a job, whatever is sent. (An upload itself costs a few MB in write batches; the rest of a job's
share is checking the file as the CLI does and printing it.)
"""

from __future__ import annotations

import os
import socket
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx

try:
    from bench_agent import _agent, _stop, start_printers
    from common import Figure
except ImportError:  # imported as benchmarks.bench_agent_attack
    from benchmarks.bench_agent import _agent, _stop, start_printers
    from benchmarks.common import Figure

MAX_UPLOAD_MB = 64
CONSTANT_MB = 32
"""What the agent may hold besides one upload's worth: write batches, buffers of the connections."""
UPLOAD_MB = 60
PARALLEL = 4
BODY_MB = 200
HALF_SENT = 2000


def _rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _peak_growth(pid: int, attack: Callable[[], None]) -> float:
    """How far the resident size rose above where it was before `attack`, in MB."""
    base = _rss_mb(pid)
    peak = [base]
    running = True

    def watch() -> None:
        while running:
            peak[0] = max(peak[0], _rss_mb(pid))
            time.sleep(0.02)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        attack()
    finally:
        running = False
        watcher.join()
    return peak[0] - base


def _gcode(megabytes: int) -> Iterator[bytes]:
    line = b"G1 X10.5 Y20.25 E0.5 F1200\n"
    block = b"G28\n" + line * (2**20 // len(line))
    for _ in range(megabytes):
        yield block


def _parallel(jobs: list[Callable[[], object]]) -> None:
    threads = [threading.Thread(target=job) for job in jobs]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()


def _attacked(ports: list[int], attack: Callable[[str, list[str], str], None]) -> float:
    """A fresh agent (the simulators in their own process), online; the growth of its memory under `attack`."""
    with tempfile.TemporaryDirectory(prefix="fabwire-bench-attack-") as tmp:
        proc, url = _agent(ports, Path(tmp), "--max-upload", str(MAX_UPLOAD_MB),
                           "--device", "arm:lineus=sim://lineus?speed=inf")
        try:
            with httpx.Client(base_url=url, timeout=30) as client:
                for _ in range(300):
                    devices = client.get("/api/v1/devices").json()
                    if len(devices) == PARALLEL + 1 and all(d["state"]["online"] for d in devices):
                        break
                    time.sleep(0.2)
            printers = [d["id"] for d in devices if d["kind"] == "xyz"]
            arm = next(d["id"] for d in devices if d["kind"] == "lineus")
            time.sleep(2)
            return _peak_growth(proc.pid, lambda: attack(url, printers, arm))
        finally:
            proc.terminate()
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()


def _upload(url: str, device: str) -> Callable[[], object]:
    return lambda: httpx.post(f"{url}/api/v1/devices/{device}/jobs", params={"filename": "big.gcode"},
                              content=_gcode(UPLOAD_MB), timeout=600,
                              headers={"content-type": "application/octet-stream"})


def _uploads_to_one(url: str, printers: list[str], arm: str) -> None:
    _parallel([_upload(url, printers[0]) for _ in printers])


def _uploads_to_each(url: str, printers: list[str], arm: str) -> None:
    _parallel([_upload(url, p) for p in printers])


def _bodies(url: str, printers: list[str], arm: str) -> None:
    def body(declared: bool) -> Callable[[], object]:
        def send() -> object:
            data = b'{"text": "' + b"a" * (BODY_MB * 2**20) + b'"}'
            content = data if declared else iter([data[i:i + 2**20] for i in range(0, len(data), 2**20)])
            try:
                return httpx.post(f"{url}/api/v1/devices/{arm}/actions/text", content=content,
                                  headers={"content-type": "application/json"}, timeout=120)
            except httpx.HTTPError as exc:  # the agent answered 413 and stopped reading
                return exc
        return send

    _parallel([body(n % 2 == 0) for n in range(PARALLEL)])


def _half_sent(url: str, printers: list[str], arm: str) -> None:
    host, port = url.removeprefix("http://").rsplit(":", 1)
    held = []
    for n in range(HALF_SENT):
        try:
            sock = socket.create_connection((host, int(port)), timeout=5)
            sock.sendall(b"POST /api/v1/devices/x/jobs?filename=a.gcode HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                         + (b"Content-Length: 1000000\r\n\r\n" if n % 2 else b""))
            held.append(sock)
        except OSError:
            break
    time.sleep(2)
    for sock in held:
        sock.close()


def run() -> list[Figure]:
    sims, ports = start_printers(PARALLEL)
    try:
        one = _attacked(ports, _uploads_to_one)
        each = _attacked(ports, _uploads_to_each)
        bodies = _attacked(ports, _bodies)
        slow = _attacked(ports, _half_sent)
    finally:
        _stop(sims)
    bound = MAX_UPLOAD_MB + CONSTANT_MB
    return [
        Figure(f"RSS growth, {PARALLEL} parallel {UPLOAD_MB} MB uploads to one printer", one, "MB", f"< {bound}",
               one < bound),
        Figure(f"RSS growth, {PARALLEL} parallel {UPLOAD_MB} MB uploads, one per printer", each, "MB",
               f"< {PARALLEL * bound}", each < PARALLEL * bound),
        Figure(f"RSS growth, {PARALLEL} parallel {BODY_MB} MB action bodies", bodies, "MB", f"< {CONSTANT_MB}",
               bodies < CONSTANT_MB),
        Figure(f"RSS growth, {HALF_SENT:,} half-sent requests", slow, "MB", f"< {bound}", slow < bound),
    ]


if __name__ == "__main__":
    for figure in run():
        print(figure)
