"""`fabwire xyz print FILE.3w --no-wait` as a user runs it (the whole command: start-up, the file's checks, the
upload and the printer taking the job), against a raw lockstep sender: a short Python program that sends the same
file to the same kind of simulator in the same framed blocks and waits for every block's `ok`.

Both run as fresh processes, interleaved (one of each in turn, median of several rounds), each against a simulator
of its own that has not printed yet; beside them, what Python takes to load asyncio and click, which every fabwire
command does before anything else (the raw sender needs neither). The floor sends one block at a time, as a
serial-line host must; fabwire keeps a Wi-Fi printer's window of blocks in flight, so it can be at or under the
floor but has no reason to be above it.
"""

from __future__ import annotations

import random
import statistics
import sys
import tempfile
from pathlib import Path

from bench_startup import fabwire_command
from bench_xyz import _start, _stop
from common import Figure, Run, ratio_figure, run_command
from fabwire.xyz.threew import convert_gcode_file

SIZE = 21_000_000
"""Bytes of G-code; the .3w is about as large (the body is encrypted, not compressed)."""
MODEL = "dv1MW0A000"
"""The simulator's default model (da Vinci mini w), the file's target."""
ROUNDS = 3

RAW_SENDER = r"""
import socket, struct, sys, zlib
port, path = int(sys.argv[1]), sys.argv[2]
data = open(path, "rb").read()
with socket.create_connection(("127.0.0.1", port)) as s:
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    buf = b""
    def until(end):
        global buf
        while end not in buf:
            buf += s.recv(65536)
        reply, _, buf = buf.partition(end)
        return reply
    s.sendall(b"XYZv3/query=a\r\n"); until(b"$\n")
    s.sendall(b"XYZv3/upload=raw.3w,%d\r\n" % len(data)); until(b"\n")
    for i, at in enumerate(range(0, len(data), 8192)):
        block = data[at:at + 8192]
        s.sendall(struct.pack(">II", i, len(block)) + block + struct.pack(">I", zlib.crc32(block))); until(b"\n")
    s.sendall(b"XYZv3/uploadDidFinish"); until(b"\n")
    s.sendall(b"XYZv3/query=a\r\n"); until(b"$\n")
"""


def gcode(path: Path, size: int) -> None:
    """A slicer-like G-code file of about `size` bytes: moves with extrusion, a layer change now and then."""
    rng = random.Random(26)
    lines = [";FLAVOR:Marlin\nG21\nG90\nM82\nM104 S210\nM140 S60\nG28\n"]
    x = y = e = 0.0
    layer = 0
    written = 0
    while written < size:
        if rng.random() < 0.0005:
            layer += 1
            lines.append(f";LAYER:{layer}\nG1 Z{0.2 * layer:.2f} F600\n")
        x, y, e = (x + rng.uniform(-3, 3)) % 150, (y + rng.uniform(-3, 3)) % 150, e + rng.uniform(0.01, 0.1)
        lines.append(f"G1 X{x:.3f} Y{y:.3f} E{e:.5f} F1800\n")
        written += len(lines[-1])
    path.write_text("".join(lines))


def run() -> list[Figure]:
    fabwire_cmd = fabwire_command()
    with tempfile.TemporaryDirectory() as tmp:
        source, job = Path(tmp, "part.gcode"), Path(tmp, "part.3w")
        gcode(source, SIZE)
        convert_gcode_file(source, job, MODEL)
        proc, ports = _start(2 * (ROUNDS + 1))
        try:
            free = iter(ports)
            runs: dict[str, list[Run]] = {"fabwire": [], "raw": [], "floor": []}
            for round_ in range(ROUNDS + 1):  # the first round warms the file cache and is not counted
                ours = run_command([*fabwire_cmd, "xyz", "-d", f"127.0.0.1:{next(free)}", "print", str(job),
                                    "--no-wait"])
                raw = run_command([sys.executable, "-c", RAW_SENDER, str(next(free)), str(job)])
                floor = run_command([sys.executable, "-c", "import asyncio, click"])
                if round_:
                    runs["fabwire"].append(ours)
                    runs["raw"].append(raw)
                    runs["floor"].append(floor)
        finally:
            _stop(proc)
        size_mb = job.stat().st_size / 1e6
    ours_wall = statistics.median(r.wall for r in runs["fabwire"])
    raw_wall = statistics.median(r.wall for r in runs["raw"])
    floor_wall = statistics.median(r.wall for r in runs["floor"])
    return [
        ratio_figure(f"xyz print --no-wait of a {size_mb:.0f} MB .3w (whole command), wall", ours_wall, "s", raw_wall,
                     "raw lockstep sender", 1.0),
        Figure("the start-up under it: python -c 'import asyncio, click', wall", floor_wall, "s", "(floor)", None,
               raw_wall, "raw lockstep sender"),
        Figure("the whole command less that start-up, wall", ours_wall - floor_wall, "s", "(reference)", None,
               raw_wall, "raw lockstep sender"),
        Figure("the same, CPU (fabwire's process)", statistics.median(r.cpu for r in runs["fabwire"]), "s",
               "(reference)", None, statistics.median(r.cpu for r in runs["raw"]), "raw lockstep sender"),
        Figure("the same, peak RSS", statistics.median(r.rss_mib for r in runs["fabwire"]), "MiB", "(reference)",
               None, statistics.median(r.rss_mib for r in runs["raw"]), "raw lockstep sender"),
    ]
