"""XYZ: upload throughput client → simulator (vs. a bare socket sender with the same block/ack framing), and the
CPU one process spends polling 500 simulated printers once a second.

The simulators run in a child process so the figures are the client's own cost.
"""

from __future__ import annotations

import asyncio
import os
import resource
import socket
import subprocess
import sys
import time
from pathlib import Path

try:
    from common import Figure
except ImportError:  # imported as benchmarks.bench_xyz
    from benchmarks.common import Figure

from fabwire.transport import open_tcp
from fabwire.xyz import protocol as p
from fabwire.xyz.client import XYZPrinter

UPLOAD_BYTES = 50 * 1024 * 1024
PRINTERS = 500
POLL_SECONDS = 6.0
BASE_PORT = 29100

_SERVE = """
import asyncio, sys
from fabwire.transport import serve_tcp
from fabwire.xyz.sim import XYZSimulator

async def main(count, base):
    servers = []
    for i in range(count):
        sim = XYZSimulator(speed=1000)
        servers.append(await serve_tcp(sim.serve, "127.0.0.1", base + i if base else 0))
    ports = [s.sockets[0].getsockname()[1] for s in servers]
    print(" ".join(map(str, ports)), flush=True)
    await asyncio.Event().wait()

asyncio.run(main(int(sys.argv[1]), int(sys.argv[2])))
"""


def _start(count: int, base: int = 0) -> tuple[subprocess.Popen[str], list[int]]:
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1] / "src"))
    proc = subprocess.Popen([sys.executable, "-c", _SERVE, str(count), str(base)], stdout=subprocess.PIPE,
                            text=True, env=env)
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if not line:
        proc.kill()
        raise RuntimeError("simulators did not start")
    return proc, [int(x) for x in line.split()]


def _stop(proc: subprocess.Popen[str]) -> None:
    proc.terminate()
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()


def _raw_upload(port: int, data: bytes) -> float:
    """The floor: a blocking socket, the same blocks and the same wait for each `ok`."""
    with socket.create_connection(("127.0.0.1", port)) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        started = time.perf_counter()
        buf = b""

        def ack() -> None:
            nonlocal buf
            while b"\n" not in buf:
                chunk = sock.recv(4096)
                if not chunk:
                    raise ConnectionError("simulator closed")
                buf += chunk
            _, _, buf = buf.partition(b"\n")

        sock.sendall(b"XYZv3/upload=raw.bin,%d\r\n" % len(data))
        ack()
        for block in p.iter_blocks(data, 8192):
            sock.sendall(block)
            ack()
        sock.sendall(b"XYZv3/uploadDidFinish")
        ack()
        return time.perf_counter() - started


async def _client_upload(port: int, data: bytes, window: int = XYZPrinter.upload_window) -> float:
    printer = XYZPrinter(await open_tcp("127.0.0.1", port))
    printer.upload_window = window
    try:
        await printer.status()
        started = time.perf_counter()
        await printer.upload(data, "client.bin")
        return time.perf_counter() - started
    finally:
        await printer.close()


def upload_figures() -> list[Figure]:
    """Alternate client and raw sender (after one warm-up each) and keep the median of three runs."""
    data = os.urandom(UPLOAD_BYTES)
    proc, ports = _start(11)
    try:
        _raw_upload(ports[0], data[: UPLOAD_BYTES // 10])
        asyncio.run(_client_upload(ports[1], data[: UPLOAD_BYTES // 10]))
        raws, clients, lockstep = [], [], []
        for i in range(3):
            clients.append(asyncio.run(_client_upload(ports[2 + 3 * i], data)))
            raws.append(_raw_upload(ports[3 + 3 * i], data))
            lockstep.append(asyncio.run(_client_upload(ports[4 + 3 * i], data, window=1)))
    finally:
        _stop(proc)
    mb = UPLOAD_BYTES / 1e6
    client_rate, raw_rate = mb / sorted(clients)[1], mb / sorted(raws)[1]
    lockstep_rate = mb / sorted(lockstep)[1]
    return [
        Figure("xyz upload 50 MB client → simulator (loopback TCP, 8 KiB blocks, Wi-Fi window 8, every ack checked)",
               client_rate, "MB/s", ">= 80 % of raw socket", client_rate >= 0.8 * raw_rate, raw_rate,
               "raw socket sender, ack per block"),
        Figure("xyz upload 50 MB client, one block in flight (serial-style lockstep)", lockstep_rate, "MB/s",
               "(reference)", None, raw_rate, "raw socket sender, ack per block"),
    ]


async def _poll_all(ports: list[int], seconds: float) -> tuple[float, float, int]:
    printers = [XYZPrinter(await open_tcp("127.0.0.1", port)) for port in ports]
    polls = 0

    async def poll(printer: XYZPrinter, offset: float) -> None:
        nonlocal polls
        await asyncio.sleep(offset)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            started = time.monotonic()
            await printer.status()
            polls += 1
            await asyncio.sleep(max(0.0, 1.0 - (time.monotonic() - started)))

    try:
        before = resource.getrusage(resource.RUSAGE_SELF)
        wall = time.perf_counter()
        await asyncio.gather(*(poll(pr, i / len(printers)) for i, pr in enumerate(printers)))
        wall = time.perf_counter() - wall
        after = resource.getrusage(resource.RUSAGE_SELF)
    finally:
        for printer in printers:
            await printer.close()
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall, polls


def polling_figures() -> list[Figure]:
    proc, ports = _start(PRINTERS)
    try:
        cpu, wall, polls = asyncio.run(_poll_all(ports, POLL_SECONDS))
    finally:
        _stop(proc)
    load = cpu / wall
    return [
        Figure(f"xyz status polling, {PRINTERS} printers at 1 Hz, one process (query=a over TCP)", load,
               "CPU s per s", "< 1 core", load < 1.0),
        Figure("xyz status polls completed", polls / wall, "polls/s", f"~{PRINTERS} (1 Hz each)",
               polls / wall > 0.85 * PRINTERS),
    ]


def run() -> list[Figure]:
    return upload_figures() + polling_figures()


if __name__ == "__main__":
    for figure in run():
        extra = f" (baseline {figure.baseline:,.2f} {figure.baseline_name})" if figure.baseline else ""
        print(f"{figure.name}: {figure.value:,.3f} {figure.unit}  target {figure.target}{extra}")
