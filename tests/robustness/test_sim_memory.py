"""Long-running simulators keep their memory bounded: rounds of hostile traffic (floods of commands, abandoned
uploads, connections opened and dropped) leave the resident set where the first round left it.

The quick profile runs a few rounds of each simulator in the normal suite; the soak profile (`make soak`, or
`FABWIRE_SOAK_MINUTES=60 pytest tests/robustness/test_sim_memory.py --soak -s`) keeps it up for minutes and
prints the figures."""

from __future__ import annotations

import collections
import contextlib
import os
import socket
import struct
import threading
import time
import zlib
from collections.abc import Callable
from pathlib import Path

import pytest

from clitools import RunningSimulator, SimulatorStarter
from fabwire.mmu.protocol import FindaQuery, Query, ToolChange, Version, encode_request

PAGE = os.sysconf("SC_PAGE_SIZE")
GROWTH_LIMIT_MB = 16.0
"""What the last round may add over the second: history caps are reached during the first rounds."""
TOTAL_LIMIT_MB = 150.0
SOAK_MINUTES = float(os.environ.get("FABWIRE_SOAK_MINUTES", "5"))


def rss_mb(pid: int) -> float:
    resident = int(Path(f"/proc/{pid}/statm").read_text().split()[1])
    return resident * PAGE / 2**20


def _endpoint(sim: RunningSimulator) -> tuple[str, int]:
    host, _, port = sim.url.removeprefix("tcp://").rpartition(":")
    return host, int(port)


def _drained(address: tuple[str, int]) -> socket.socket:
    """A connection whose replies are read and thrown away, so the simulator never blocks on a full socket."""
    sock = socket.create_connection(address, timeout=10)

    def drain() -> None:
        try:
            while sock.recv(1 << 16):
                pass
        except OSError:
            pass

    threading.Thread(target=drain, daemon=True).start()
    return sock


def _abandoned_connections(address: tuple[str, int], count: int = 24) -> None:
    """Connections that say nothing, or half a line, and vanish (a burst within the connection limit: this
    measures memory; admission has its own tests)."""
    for n in range(count):
        with socket.create_connection(address, timeout=10) as sock:
            if n % 2:
                sock.sendall(b"G01 X")


def _xyz_round(address: tuple[str, int]) -> None:
    sock = _drained(address)
    junk = (b"XYZv3/" + b"n" * 4000 + b"\r\n") * 250
    for _ in range(8):  # 8 MB of unknown commands
        sock.sendall(junk)
    sock.sendall(b"XYZv3/query=a\r\n" * 2000)
    sock.close()
    size, block = 4 << 20, b"\0" * 65536
    trailer = struct.pack(">I", zlib.crc32(block))
    for n in range(2):  # uploads abandoned half way
        upload = _drained(address)
        upload.sendall(f"XYZv3/upload=junk{n}.3w,{size}\r\n".encode())
        time.sleep(0.05)
        for index in range(size // len(block) // 2):
            upload.sendall(struct.pack(">II", index, len(block)) + block + trailer)
        upload.close()
    _abandoned_connections(address)


def _lineus_round(address: tuple[str, int]) -> None:
    sock = _drained(address)
    moves = b"".join(f"G01 X{1000 + i % 500} Y{i % 400} Z0\r\n".encode() for i in range(2000))
    sock.sendall(moves)
    sock.sendall(b"M28\r\n" + b"G01 X1000 Y0\r\n" * 20000 + b"M29\r\n")  # a stored drawing, capped by flash
    sock.close()
    _abandoned_connections(address)


def _mmu_round(address: tuple[str, int]) -> None:
    sock = _drained(address)
    frames = b"".join(encode_request(r) for r in (Query(), FindaQuery(), Version(0), Version(1)))
    sock.sendall(frames * 2000 + b"garbage*ff\n" * 2000 + encode_request(ToolChange(1)))
    sock.close()
    _abandoned_connections(address)


ROUNDS: dict[str, tuple[tuple[str, ...], Callable[[tuple[str, int]], None]]] = {
    "xyz": (("xyz", "--speed", "100"), _xyz_round),
    "lineus": (("lineus", "--speed", "100"), _lineus_round),
    "mmu": (("mmu", "--speed", "100"), _mmu_round),
}


def _last_words(sim: RunningSimulator) -> collections.deque[str]:
    """Keep reading the simulator's stderr (its last lines are kept for a failure message): a pipe nobody reads
    fills after 64 kB of log lines and then blocks the simulator, which would measure the pipe, not the simulator."""
    lines: collections.deque[str] = collections.deque(maxlen=20)
    stream = sim.process.stderr
    assert stream is not None

    def read() -> None:
        with contextlib.suppress(OSError, ValueError):
            for line in stream:
                lines.append(line.rstrip())

    threading.Thread(target=read, daemon=True).start()
    return lines


def _run(simulator: SimulatorStarter, kind: str, *, rounds: int = 0, minutes: float = 0.0) -> list[float]:
    args, one_round = ROUNDS[kind]
    sim = simulator(*args, "--listen", "127.0.0.1:0", "--max-connections", "64")
    said = _last_words(sim)
    address = _endpoint(sim)
    readings = [rss_mb(sim.process.pid)]
    ends = time.monotonic() + minutes * 60
    done = 0
    while done < rounds or time.monotonic() < ends:
        try:
            one_round(address)
        except OSError as exc:
            raise AssertionError(f"the {kind} simulator stopped serving in round {done + 1} ({exc!r}); it last said: "
                                 + " | ".join(said)) from exc
        time.sleep(1.5)  # past the connection limit's busy window: this measures memory, not admission
        readings.append(rss_mb(sim.process.pid))
        done += 1
    assert sim.process.poll() is None, f"the {kind} simulator died: " + " | ".join(said)
    return readings


def _check(kind: str, readings: list[float]) -> None:
    base, second, last, peak = readings[0], readings[2], readings[-1], max(readings)
    print(f"{kind}: RSS {base:.0f} MB at start, {second:.0f} after round 2, {last:.0f} after round "
          f"{len(readings) - 1}, peak {peak:.0f} MB")
    assert last - second < GROWTH_LIMIT_MB, f"{kind} simulator keeps growing: {readings}"
    assert peak - base < TOTAL_LIMIT_MB, f"{kind} simulator grew by {peak - base:.0f} MB: {readings}"


@pytest.mark.parametrize("kind", sorted(ROUNDS))
def test_a_simulator_under_repeated_hostile_traffic_stays_the_same_size(simulator: SimulatorStarter,
                                                                        kind: str) -> None:
    _check(kind, _run(simulator, kind, rounds=6))


@pytest.mark.soak
@pytest.mark.timeout(SOAK_MINUTES * 60 + 300)  # the rounds run for the minutes asked, then a last round and the checks
@pytest.mark.parametrize("kind", sorted(ROUNDS))
def test_soak_a_simulator_stays_the_same_size_for_minutes(simulator: SimulatorStarter, kind: str) -> None:
    _check(kind, _run(simulator, kind, rounds=3, minutes=SOAK_MINUTES))
