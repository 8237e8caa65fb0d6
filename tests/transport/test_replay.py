"""`fabwire trace replay`: the host side of a capture, sent again, with each differing reply reported."""

from __future__ import annotations

import json
import socket
import tracemalloc
from pathlib import Path

import pytest

from clitools import run_cli, start_simulator
from fabwire.transport.replay import exchanges
from fabwire.transport.tap import TraceRecord, TraceWriter, read_trace


def test_chunks_group_into_request_and_reply() -> None:
    records = [TraceRecord(0, ">", b"XYZv3/"), TraceRecord(0, ">", b"query=a\r\n"), TraceRecord(0, "<", b"b:20\n"),
               TraceRecord(0, "<", b"$\n"), TraceRecord(0, None, event="eof"), TraceRecord(0, ">", b"M114\x00")]
    found = list(exchanges(records))
    assert [(e.number, e.sent, e.expected) for e in found] == [
        (1, b"XYZv3/query=a\r\n", b"b:20\n$\n"), (2, b"M114\x00", b"")]


def test_replay_to_the_same_and_to_another_printer(tmp_path: Path) -> None:
    mini = start_simulator("xyz", "--listen", "127.0.0.1:0")  # real time: nothing changes between the runs
    nano = start_simulator("xyz", "--listen", "127.0.0.1:0", "--model", "nano", "--speed", "100")
    trace = tmp_path / "status.jsonl"
    try:
        recorded = run_cli("xyz", "-d", mini.url, "status", "--trace", str(trace))
        assert recorded.returncode == 0, recorded.stderr
        same = run_cli("trace", "replay", str(trace), "--to", mini.url)
        assert same.returncode == 0, same.stderr
        assert same.stdout.strip() == "every reply matches the recording"
        other = run_cli("--json", "trace", "replay", str(trace), "--to", nano.url, "--quiet", "0.5")
        assert other.returncode == 6  # documented: the device broke the protocol (answered otherwise)
        report = json.loads(other.stdout)
        assert report["protocol"] == "xyz"
        differences = report["differences"]
        assert differences[0]["exchange"] == 1
        assert differences[0]["sent"] == "XYZv3/query=a\r\n"
        assert "dv1NX0A000" in differences[0]["got"]
        assert "dv1NX0A000" not in differences[0]["expected"]
    finally:
        mini.stop()
        nano.stop()


def test_replay_to_a_silent_port_says_no_reply_came(tmp_path: Path) -> None:
    trace = tmp_path / "wire.jsonl"
    run = run_cli("lineus", "position", "-d", "sim://lineus?speed=inf", "--trace", str(trace))
    assert run.returncode == 0, run.stderr
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(4)
        port = silent.getsockname()[1]
        result = run_cli("trace", "replay", str(trace), "--to", f"127.0.0.1:{port}", "--quiet", "0.2")
    assert result.returncode == 6, result.stderr
    assert "got      no reply (0.2 s of silence)" in result.stdout
    assert "differs from byte" not in result.stdout


@pytest.mark.parametrize("content", ["", "\n\n", "   \n"], ids=["empty", "blank-lines", "spaces"])
@pytest.mark.parametrize("command", [["show"], ["show", "--json"], ["replay", "--to", "127.0.0.1:9"]])
def test_a_capture_without_records_is_refused(tmp_path: Path, content: str, command: list[str]) -> None:
    trace = tmp_path / "empty.jsonl"
    trace.write_text(content)
    result = run_cli("trace", command[0], str(trace), *command[1:])
    assert result.returncode == 4
    assert result.stderr.strip() == f"fabwire: error: {trace} holds no trace records"
    assert result.stdout == ""


def test_a_capture_that_never_got_a_reply_is_not_held_whole(tmp_path: Path) -> None:
    """8 MB the host sent to a device that never answered: streamed in exchanges of about 1 MB, all bytes kept."""
    trace = tmp_path / "silent.jsonl"
    writer = TraceWriter.to_file(trace, url="tcp://127.0.0.1:1", peer="silent")
    chunk = bytes(range(256)) * 16
    for _ in range(2048):
        writer.chunk(">", chunk)
    writer.close()
    tracemalloc.start()
    try:
        sizes = [len(e.sent) for e in exchanges(read_trace(trace))]
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert sum(sizes) == 2048 * len(chunk)
    assert max(sizes) <= (1 << 20) + len(chunk)
    assert peak < 4 * (1 << 20), f"peak {peak} bytes for an 8 MB capture"
