"""`trace replay` ignores reply values that vary by nature (uptime, clocks, temperatures, progress), says which it
ignored, and still reports every other difference; `--strict` compares every byte."""

from __future__ import annotations

import json
import re
import socket
import subprocess
import threading
import time
from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st

from clitools import RunningSimulator, run_cli, start_simulator
from fabwire.transport.replay import Exchange, compare
from fabwire.transport.tap import TraceWriter, trace_device
from fabwire.transport.volatile import LINEUS, MMU, XYZ, mask, sniff

STATUS = (b"b:20\nc:{336,374,377,355,373,371,364,377,356}\nd:0,0,0\nw:1,PMP6QTH64R1093\ne:0\nf:1,200000\n"
          b"i:3FM1WPUS5CA6750022\nj:9511,0\nL:1,301080,28581,66\nm:0,0,0\no:p8,t1,c1,a+\np:dv1MW0A000\n"
          b"t:1,22,0\nv:1.2.3\nX:2,GB-0002-0000-TH-68T-0250-28727\nz:245\n"
          b'4:{"wlan":{"ip":"192.168.1.118","ssid":"HOME","channel":"0","rssiValue":"39","MAC":"54:8c:a0:06:7e:48"}}\n'
          b"$\n")
"""A mini w's `query=a` reply (xyzv3.md 2.1, SEED), shortened."""

POLL_TIMEOUT = 60.0


def xyz_status(sim: RunningSimulator) -> bytes:
    host, port = sim.url.removeprefix("tcp://").rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=10) as sock:
        sock.sendall(b"XYZv3/query=a\r\n")
        reply = b""
        while not reply.endswith(b"$\n"):
            reply += sock.recv(4096)
    return reply


def letter(reply: bytes, name: bytes) -> bytes:
    found = re.search(rb"(?m)^" + name + rb":([^\n]*)$", reply)
    assert found is not None, reply
    return found[1]


def record(trace: Path, kind: str, *command: str) -> None:
    """Capture `fabwire KIND -d SIM COMMAND…` against a simulator of its own, stopped afterwards."""
    sim = start_simulator(kind, "--listen", "127.0.0.1:0", "--speed", "0" if kind == "lineus" else "1")
    try:
        recorded = run_cli(kind, "-d", sim.url, *command, "--trace", str(trace))
        assert recorded.returncode == 0, recorded.stderr
    finally:
        sim.stop()


def recorded_reply(trace: Path) -> bytes:
    lines = [json.loads(line) for line in trace.read_text().splitlines()[1:]]
    return b"".join(r["data"].encode("latin-1") for r in lines if r.get("dir") == "<")


def test_a_status_replayed_to_a_simulator_started_later_matches(tmp_path: Path) -> None:
    trace = tmp_path / "status.jsonl"
    record(trace, "xyz", "status")
    assert trace_device(trace) == "xyz"
    uptime = letter(recorded_reply(trace), b"L")
    later = start_simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000")
    try:
        deadline = time.monotonic() + POLL_TIMEOUT  # the later printer has been on for other minutes
        while letter(xyz_status(later), b"L") == uptime:
            assert time.monotonic() < deadline, "the later simulator's power-on minutes never moved"
            time.sleep(0.05)
        tolerant = run_cli("trace", "replay", str(trace), "--to", later.url, "--quiet", "1")
        strict = run_cli("trace", "replay", str(trace), "--to", later.url, "--quiet", "1", "--strict")
        as_json = run_cli("--json", "trace", "replay", str(trace), "--to", later.url, "--quiet", "1")
    finally:
        later.stop()
    assert tolerant.returncode == 0, tolerant.stdout + tolerant.stderr
    lines = tolerant.stdout.splitlines()
    assert lines[0] == "every reply matches the recording"
    assert lines[1].startswith("ignored: L (machine, extruder and last power-on minutes) in exchange 1")
    assert "--strict compares them" in lines[1]
    assert strict.returncode == 6
    assert "exchange 1: sent XYZv3/query=a" in strict.stdout
    report = json.loads(as_json.stdout)
    assert report["protocol"] == "xyz"
    assert report["differences"] == []
    assert {"exchange": 1, "fields": ["L"]} in report["ignored"]


def test_a_real_field_that_differs_is_reported_where_it_differs(tmp_path: Path) -> None:
    trace = tmp_path / "status.jsonl"
    record(trace, "xyz", "status")
    zoffset = letter(recorded_reply(trace), b"z")
    edited = trace.read_text().replace(f"z:{zoffset.decode()}\\n", f"z:{int(zoffset) + 1}\\n")
    edited = re.sub(r"L:1,[0-9]+", "L:1,7", edited)  # a varying value of another length before it
    assert edited != trace.read_text()
    trace.write_text(edited)
    sim = start_simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000")
    try:
        result = run_cli("--json", "trace", "replay", str(trace), "--to", sim.url, "--quiet", "1")
    finally:
        sim.stop()
    assert result.returncode == 6, result.stderr
    report = json.loads(result.stdout)
    [difference] = report["differences"]
    got = difference["got"].encode("latin-1")
    offset = difference["offset"]
    line_start = got.index(b"\nz:") + 1
    assert line_start + 2 <= offset < got.index(b"\n", line_start)  # in the z-offset line, not at L before it
    assert {"exchange": 1, "fields": ["L"]} in report["ignored"]


def test_a_lineus_diagnostics_replay_ignores_the_clock(tmp_path: Path) -> None:
    trace = tmp_path / "info.jsonl"
    record(trace, "lineus", "info")
    later = start_simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    try:
        result = run_cli("--json", "trace", "replay", str(trace), "--to", later.url, "--quiet", "1")
    finally:
        later.stop()
    assert result.returncode == 0, result.stdout + result.stderr
    report = json.loads(result.stdout)
    assert report["protocol"] == "lineus"
    assert {name for entry in report["ignored"] for name in entry["fields"]} <= {"Uptime", "Time", "FreeHeap"}


def _with(reply: bytes, name: bytes, value: bytes) -> bytes:
    return re.sub(rb"(?m)^" + name + rb":[^\n]*$", lambda _: name + b":" + value, reply)


digits = st.integers(0, 10**9).map(lambda n: str(n).encode())


@given(machine=digits, last=digits, bed=digits, extruder=digits, target=digits, rssi=digits, nozzle=digits)
def test_xyz_status_values_that_vary_are_ignored(machine: bytes, last: bytes, bed: bytes, extruder: bytes,
                                                 target: bytes, rssi: bytes, nozzle: bytes) -> None:
    got = _with(STATUS, b"L", b"1," + machine + b",28581," + last)
    got = _with(got, b"b", bed)
    got = _with(got, b"t", b"1," + extruder + b"," + target)
    got = _with(got, b"X", b"2,GB-0002-0000-TH-68T-0250-" + nozzle)
    got = got.replace(b'"rssiValue":"39"', b'"rssiValue":"' + rssi + b'"')
    difference, ignored = compare(Exchange(1, b"XYZv3/query=a\r\n", STATUS), got, XYZ, strict=False)
    assert difference is None
    assert ignored is None or set(ignored.fields) <= {"L", "b", "t", "X", "4"}
    strict, _ = compare(Exchange(1, b"XYZv3/query=a\r\n", STATUS), got, XYZ, strict=True)
    assert (strict is None) == (got == STATUS)


@given(machine=digits, name=st.sampled_from([b"j", b"e", b"p", b"i", b"z", b"c", b"v"]),
       value=st.binary(min_size=1, max_size=12).filter(lambda b: b"\n" not in b))
def test_xyz_status_real_fields_are_compared_and_located(machine: bytes, name: bytes, value: bytes) -> None:
    expected = _with(STATUS, name, value)
    got = _with(STATUS, b"L", b"1," + machine + b",28581,66")
    difference, _ = compare(Exchange(1, b"XYZv3/query=a\r\n", expected), got, XYZ, strict=False)
    if expected == STATUS:
        assert difference is None
        return
    assert difference is not None
    line_start = got.index(b"\n" + name + b":") + 1
    line_end = got.index(b"\n", line_start)
    assert line_start + 2 <= difference.offset <= line_end  # inside the changed line of the reply received


def test_a_status_line_that_is_missing_is_a_difference() -> None:
    got = STATUS.replace(b"t:1,22,0\n", b"")
    difference, _ = compare(Exchange(1, b"XYZv3/query=a", STATUS), got, XYZ, strict=False)
    assert difference is not None


def test_lineus_and_mmu_varying_values() -> None:
    def diag(uptime: bytes, clock: bytes, name: bytes = b"line-us") -> bytes:
        return (b"ok ChipID:1575520 name:" + name + b" FreeHeap:25728 Uptime:" + uptime + b' Time:"' + clock
                + b'" FSUsed:112197\r\n\x00')

    recorded = diag(b"0d0h0m1s", b"Sun Nov 29 16:00:01 2026")
    same, ignored = compare(Exchange(1, b"M122\x00", recorded), diag(b"0d2h10m5s", b"Mon Nov 30 01:02:03 2026"),
                            LINEUS, strict=False)
    assert same is None
    assert ignored is not None
    assert ignored.fields == ("Uptime", "Time")
    renamed, _ = compare(Exchange(1, b"M122\x00", recorded), diag(b"0d0h0m1s", b"Sun Nov 29 16:00:01 2026", b"bob"),
                         LINEUS, strict=False)
    assert renamed is not None
    progress, ignored = compare(Exchange(1, b"Q0*ea\n", b"T1 P5*af\n"), b"T1 P6*3c\n", MMU, strict=False)
    assert progress is None
    assert ignored is not None
    assert ignored.fields == ("P",)
    failed, _ = compare(Exchange(1, b"Q0*ea\n", b"T1 P5*af\n"), b"T1 E8004*6b\n", MMU, strict=False)
    assert failed is not None


def test_masking_keeps_track_of_where_values_were() -> None:
    masked = mask(b"L:1,301080,28581,66\nz:245\n", XYZ)
    assert masked.values == {"L": [b"301080,28581,66"]}
    z_at = masked.data.index(b"z:")
    assert masked.raw_offset(z_at) == b"L:1,301080,28581,66\nz:245\n".index(b"z:")
    assert mask(b"anything", None).data == b"anything"


def test_the_protocol_comes_from_the_capture_or_its_bytes(tmp_path: Path) -> None:
    named = tmp_path / "named.jsonl"
    TraceWriter.to_file(named, url="tcp://127.0.0.1:1", peer="p", device="mmu").close()
    assert trace_device(named) == "mmu"
    older = tmp_path / "older.jsonl"
    TraceWriter.to_file(older, url="tcp://127.0.0.1:1", peer="p").close()
    assert trace_device(older) is None
    (tmp_path / "junk.jsonl").write_bytes(b"\xff\xfe[[[[")
    assert trace_device(tmp_path / "junk.jsonl") is None
    assert sniff(b"XYZv3/query=a\r\n", b"") is XYZ
    assert sniff(b"", b'hello VERSION:"3.2.0" NAME:line-us SERIAL:1\r\n\x00') is LINEUS
    assert sniff(b"S0*c6\n", b"S0 A3*22\n") is MMU
    assert sniff(b"GET / HTTP/1.1\r\n", b"HTTP/1.1 200 OK\r\n") is None


def replay_to_a_device_answering(tmp_path: Path, exchanges: list[tuple[bytes, bytes]], answers: dict[bytes, bytes],
                                 *options: str) -> subprocess.CompletedProcess[str]:
    """Write a capture of `exchanges` (sent, reply) that names no protocol, and replay it to a device on loopback
    that answers each `\\n`-ended request line found in `answers`, and nothing else."""
    trace = tmp_path / "capture.jsonl"
    writer = TraceWriter.to_file(trace, url="tcp://127.0.0.1:1", peer="p")
    for sent, reply in exchanges:
        writer.chunk(">", sent)
        writer.chunk("<", reply)
    writer.close()
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        port = server.getsockname()[1]

        def answer() -> None:
            conn, _ = server.accept()
            buffered = b""
            with conn:
                while chunk := conn.recv(100):
                    buffered += chunk
                    *lines, buffered = buffered.split(b"\n")
                    for line in lines:
                        conn.sendall(answers.get(line + b"\n", b""))

        helper = threading.Thread(target=answer, daemon=True)
        helper.start()
        result = run_cli("trace", "replay", str(trace), "--to", f"127.0.0.1:{port}", "--quiet", "0.5", *options)
        helper.join(30)
    return result


def test_an_unknown_protocol_is_compared_byte_for_byte(tmp_path: Path) -> None:
    result = replay_to_a_device_answering(tmp_path, [(b"HELLO?\n", b"L:1,5\n")], {b"HELLO?\n": b"L:1,6\n"})
    assert result.returncode == 6
    assert "(differs from byte 4)" in result.stdout
    assert result.stdout.splitlines()[-1].startswith("ignored: nothing (the capture's protocol is unknown")


def test_the_protocol_can_be_named_for_a_capture_that_does_not_tell(tmp_path: Path) -> None:
    """A capture that starts mid-conversation (no handshake to recognise) replays by the protocol named."""
    exchanges = [(b"\n", b""), (b"Q0*ea\n", b"T1 P5*af\n")]
    answers = {b"Q0*ea\n": b"T1 P6*3c\n"}
    unknown = replay_to_a_device_answering(tmp_path, exchanges, answers)
    assert unknown.returncode == 6, unknown.stdout
    named = replay_to_a_device_answering(tmp_path, exchanges, answers, "--protocol", "mmu")
    assert named.returncode == 0, named.stdout
    assert named.stdout.splitlines() == [
        "every reply matches the recording",
        "ignored: P (a running command's progress) in exchange 2 — mmu values that vary by nature (--strict "
        "compares them)"]
