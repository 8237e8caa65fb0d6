"""`fabwire sim KIND` serving options: -v logs what clients send, --trace records it, limits bound the clients."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from pathlib import Path

import pytest

from clitools import run_cli, start_simulator
from fabwire.mmu.protocol import Query, encode_request
from fabwire.transport.tap import read_trace


def endpoint(url: str) -> tuple[str, int]:
    host, port = url.removeprefix("tcp://").rsplit(":", 1)
    return host, int(port)


def test_verbose_and_trace_show_every_command_received(tmp_path: Path) -> None:
    trace = tmp_path / "sim.jsonl"
    sim = start_simulator("xyz", "--listen", "127.0.0.1:0", "-v", "--trace", str(trace), "--speed", "100")
    try:
        with socket.create_connection(endpoint(sim.url), timeout=10) as client:
            client.sendall(b"XYZv3/query=j\r\n")
            assert client.recv(100)
    finally:
        stderr = sim.stop()
    assert "> XYZv3/query=j\\r\\n" in stderr  # as written on the wire, escaped
    assert "connected" in stderr
    records = list(read_trace(trace))
    assert records[0].event == "connect"
    assert [r.data for r in records if r.direction == ">"] == [b"XYZv3/query=j\r\n"]
    assert any(r.direction == "<" for r in records)


def test_options_go_before_or_after_the_kind_and_limits_apply(tmp_path: Path) -> None:
    sim = start_simulator("--max-connections", "1", "lineus", "--listen", "127.0.0.1:0", "--idle-timeout", "60")
    try:
        with socket.create_connection(endpoint(sim.url), timeout=10) as first:
            assert first.recv(100).startswith(b"hello")
            with socket.create_connection(endpoint(sim.url), timeout=10) as second:
                reply = b""
                while chunk := second.recv(200):
                    reply += chunk
            assert b"busy: all 1 connections are in use" in reply
    finally:
        stderr = sim.stop()
    assert "refused" in stderr
    assert stderr.count("\n") < 5


KEEP_BUSY = {"xyz": b"XYZv3/query=j\r\n", "lineus": b"M114\x00", "mmu": encode_request(Query())}
ASK = {"xyz": "status", "lineus": "position", "mmu": "status"}


@pytest.mark.parametrize("kind", sorted(KEEP_BUSY))
def test_a_client_turned_away_hears_that_the_simulator_is_busy(kind: str) -> None:
    sim = start_simulator(kind, "--listen", "127.0.0.1:0", "--max-connections", "1", "--speed", "50")
    host, _, port = sim.url.removeprefix("tcp://").rpartition(":")
    stop = threading.Event()

    def keep_busy() -> None:  # the one place stays taken by a client that keeps talking
        with socket.create_connection((host, int(port)), timeout=10) as held:
            held.settimeout(0.1)
            while not stop.is_set():
                with contextlib.suppress(OSError):
                    held.sendall(KEEP_BUSY[kind])
                    held.recv(65536)

    holder = threading.Thread(target=keep_busy, daemon=True)
    holder.start()
    try:
        time.sleep(0.5)
        refused = run_cli("--timeout", "5", kind, "-d", sim.url, *(["--speed", "50"] if kind == "mmu" else []),
                          ASK[kind])
    finally:
        stop.set()
        holder.join(10)
        sim.stop()
    assert refused.returncode == 8, refused.stderr
    assert refused.stderr == (f"fabwire: error: {host}:{port}: the {kind} simulator turned the connection away: "
                              "all 1 of its connections are in use (its --max-connections); try again later\n")


FAREWELL = {"xyz": b"xyz simulator replaced this quiet connection: all 1 connections were in use\r\n",
            "mmu": b"mmu simulator replaced this quiet connection: all 1 connections were in use\r\n",
            "lineus": b'error INFO:"lineus simulator replaced this quiet connection: all 1 connections were in use"'
                      b"\r\n\x00"}
"""What each simulator tells a quiet client it closes to make room: a Line-us error reply; for the XYZv3 and MMU
protocols, which have no error a client would show for it, the plain line their refusals use."""


@pytest.mark.parametrize("kind", sorted(KEEP_BUSY))
def test_the_quiet_client_replaced_is_told_why(kind: str) -> None:
    sim = start_simulator(kind, "--listen", "127.0.0.1:0", "--max-connections", "1", "--speed", "50")
    where = endpoint(sim.url)
    try:
        with socket.create_connection(where, timeout=10) as quiet:
            if kind == "lineus":
                assert quiet.recv(200).startswith(b"hello")
            deadline = time.monotonic() + 60
            while True:  # until the quiet one has been quiet long enough to give up its place
                assert time.monotonic() < deadline, "the newcomer was never served"
                with socket.create_connection(where, timeout=10) as newcomer:
                    newcomer.sendall(KEEP_BUSY[kind])
                    if b"busy: all 1 connections" not in newcomer.recv(4096):
                        break
                time.sleep(0.1)
            said = b""
            while chunk := quiet.recv(4096):
                said += chunk
    finally:
        stderr = sim.stop()
    assert said == FAREWELL[kind]
    assert "closed the quietest connection" in stderr
