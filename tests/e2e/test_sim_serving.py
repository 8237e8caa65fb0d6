"""`fabwire sim KIND` serving options: -v logs what clients send, --trace records it, limits bound the clients."""

from __future__ import annotations

import socket
from pathlib import Path

from clitools import start_simulator
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
