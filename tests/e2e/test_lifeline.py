"""Simulators started as children end with their parent, however the parent ends (SIGKILL included)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from agent.agenttools import start_agent, wait_for
from clitools import cli_env, start_simulator
from fabwire.lifeline import GRACE

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="finds child processes in /proc")

GONE_WITHIN = GRACE + 30.0
"""The simulators stop at once when the lifeline is cut; GRACE is the bound on a stuck one, the rest is slack for
a loaded machine. The wait polls: a quick stop ends it early."""


def _stat(pid: int) -> tuple[str, int] | None:
    """(state, parent pid) of a process, or None when there is no such process."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text.rsplit(")", 1)[1].split()
    return fields[0], int(fields[1])


def simulators_of(parent: int) -> list[int]:
    """The `fabwire sim …` processes whose parent is `parent`."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or (stat := _stat(int(entry.name))) is None or stat[1] != parent:
            continue
        try:
            words = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"fabwire" in words and b"sim" in words:
            found.append(int(entry.name))
    return sorted(found)


def gone(pid: int) -> bool:
    stat = _stat(pid)
    return stat is None or stat[0] in ("Z", "X")  # a zombie has ended; reaping it is its new parent's business


def accepting(port: int) -> bool:
    with socket.socket() as sock:
        sock.settimeout(5)
        return sock.connect_ex(("127.0.0.1", port)) == 0


def assert_all_end(pids: list[int], ports: list[int]) -> None:
    wait_for(lambda: all(gone(pid) for pid in pids) or [p for p in pids if not gone(p)],
             "the simulator processes ending", timeout=GONE_WITHIN)
    wait_for(lambda: not any(accepting(port) for port in ports), "the simulator ports closing", timeout=GONE_WITHIN)


def test_an_agent_killed_with_sigkill_takes_its_demo_simulators_with_it(tmp_path: Path) -> None:
    agent = start_agent(tmp_path / "state", "--demo", "--speed", "30")
    try:
        with agent.client() as client:
            devices = wait_for(lambda: (d := client.get("/api/v1/devices").json()) and all(
                x["state"]["online"] for x in d) and d, "the demo's machines online")
        ports = [int(d["address"].rsplit(":", 1)[1]) for d in devices]
        pids = simulators_of(agent.process.pid)
        assert len(pids) == 3, pids
        assert all(accepting(port) for port in ports)
        agent.process.kill()
        agent.process.wait(30)
    finally:
        agent.stop()
    assert agent.process.returncode == -signal.SIGKILL
    assert_all_end(pids, ports)


PARENT = textwrap.dedent("""
    import sys, threading, time
    from fabwire.demo.runner import start_simulators

    started = []
    starter = threading.Thread(target=lambda: started.extend(start_simulators([("lineus", []), ("xyz", [])])))
    starter.start()
    starter.join()  # the thread that started the children is gone; the children must not go with it
    print(" ".join(s.url for s in started), flush=True)
    time.sleep(3600)
""")


def test_simulators_outlive_the_thread_that_started_them_but_not_the_process() -> None:
    parent = subprocess.Popen([sys.executable, "-c", PARENT], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, env=cli_env())
    try:
        assert parent.stdout is not None
        urls = parent.stdout.readline().split()
        assert len(urls) == 2, parent.stderr.read() if parent.stderr else ""
        ports = [int(url.rsplit(":", 1)[1]) for url in urls]
        pids = simulators_of(parent.pid)
        assert len(pids) == 2, pids
        lineus = socket.create_connection(("127.0.0.1", ports[0]), timeout=10)
        with lineus:
            assert lineus.recv(100).startswith(b"hello")  # alive and serving after its starter thread ended
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait(30)
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()
        for stream in (parent.stdout, parent.stderr):
            if stream is not None:
                stream.close()
    assert_all_end(pids, ports)


def test_a_cut_lifeline_stops_a_simulator_as_sigterm_does(tmp_path: Path) -> None:
    """Closing the lifeline is a graceful stop: exit code 0, and what the simulator records on stop is written."""
    record = tmp_path / "drawn.svg"
    sim = start_simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0", "--record", str(record))
    port = int(sim.url.rsplit(":", 1)[1])
    with socket.create_connection(("127.0.0.1", port), timeout=10) as client:
        assert client.recv(100).startswith(b"hello")
        client.sendall(b"G01 X900 Y0 Z0\0G01 X1200 Y300 Z0\0G01 X1200 Y300 Z1000\0")
        replies = b""
        while replies.count(b"\0") < 3:
            replies += client.recv(200)
    assert sim.process.stdin is not None
    sim.process.stdin.close()
    assert sim.process.wait(GONE_WITHIN) == 0
    stderr = sim.stop()
    assert "recorded 1 stroke(s)" in stderr, stderr
    assert "<svg" in record.read_text()
    assert not accepting(port)


def test_a_simulator_started_by_hand_ignores_its_stdin(tmp_path: Path) -> None:
    """Without the lifeline variable, an at-once end-of-file on stdin (`< /dev/null`, a closed terminal) is no
    reason to stop: the simulator still answers after its stdin has been read to the end and closed."""
    env = cli_env(tmp_path)
    command = [sys.executable, "-m", "fabwire", "sim", "lineus", "--listen", "127.0.0.1:0", "--speed", "0"]
    with subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                          env=env) as process:
        try:
            assert process.stdin is not None
            assert process.stdout is not None
            process.stdin.close()
            url = process.stdout.readline().rsplit(" ", 1)[1].strip()
            port = int(url.rsplit(":", 1)[1])
            for _ in range(3):
                with socket.create_connection(("127.0.0.1", port), timeout=10) as client:
                    assert client.recv(100).startswith(b"hello")
            assert process.poll() is None
        finally:
            process.terminate()
            process.wait(30)
