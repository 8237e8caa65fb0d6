"""A client pointed at another kind of machine or server names what it found, from the first bytes that peer sent,
however they arrive (whole, a byte at a time, cut anywhere), or from its answer to a probe when it said nothing:
every row of `FOREIGN` against each client kind, over real TCP through the real CLI, and the real peers themselves
(the other simulators, `fabwire serve`, Python's http.server, Mosquitto)."""

from __future__ import annotations

import contextlib
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clitools import RunningSimulator, run_cli, start_simulator
from fabwire.lineus.client import _greeting_error
from fabwire.transport.peers import FOREIGN, HEAD_BYTES, PROBES, FirstBytes, identify, undecided, wrong_peer

sys.path.insert(0, str(Path(__file__).parents[1] / "mqtt"))
sys.path.insert(0, str(Path(__file__).parents[1] / "agent"))
from agenttools import start_agent
from mqtttools import Mosquitto

from peertools import SAID

OWN: dict[str, list[bytes]] = {
    "xyz": [b"j:9511,0\n", b"ok\n", b"$\n", b"E4$\n", b"b:20\n", b"t:1,180,200\n", SAID["xyz"]],
    "mmu": [b"S0 A1*3f\n", b"X0 A0*a1\n", b"Q0 E8008*1c\n", SAID["mmu"]],
    "lineus": [SAID["lineus"], b"ok X:1000 Y:1000 Z:1000\r\n\0"],
}
"""What each machine of ours says itself: never taken for another peer by its own client."""

CLIENTS = {"xyz": ("xyz", "status"), "mmu": ("mmu", "version"), "lineus": ("lineus", "info")}
EXPECTED = {"xyz": "an XYZv3 printer", "mmu": "a Prusa MMU3", "lineus": "a Line-us"}
ROWS = {row.name: row for row in FOREIGN}


def test_every_row_has_what_its_peer_says() -> None:
    assert set(ROWS) == set(SAID)
    for row in FOREIGN:
        assert row.source
        for kind in CLIENTS:
            if row.kind != kind:
                assert identify(SAID[row.name], kind) is row, (row.name, kind)


def test_every_probe_names_its_source() -> None:
    assert all(probe.source and probe.says for probe in PROBES)


@pytest.mark.parametrize("kind", OWN)
def test_a_machine_of_ours_is_not_taken_for_another(kind: str) -> None:
    for said in OWN[kind]:
        for end in range(1, len(said) + 1):
            assert identify(said[:end], kind) is None, said[:end]
        assert identify(said, kind, final=True) is None, said


@given(st.binary(max_size=300))
def test_identify_takes_any_bytes(data: bytes) -> None:
    found = identify(data, "xyz", final=True)
    assert found is None or found.pattern.match(data[:HEAD_BYTES])


CASES = [(kind, name) for kind in CLIENTS for name, row in ROWS.items() if row.kind != kind]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=st.sampled_from(CASES), data=st.data())
def test_a_verdict_waits_for_conclusive_bytes(case: tuple[str, str], data: st.DataObject) -> None:
    """However the words are cut into reads, no verdict before the bytes gathered so far are conclusive, and then
    the row they are: never another row, never 'not a Line-us' from a start that is still the start of a row."""
    kind, name = case
    said = SAID[name]
    cuts = sorted(data.draw(st.sets(st.integers(1, max(1, len(said) - 1)), max_size=8)))
    first = FirstBytes()
    verdicts = []
    for start, end in zip([0, *cuts], [*cuts, len(said)], strict=True):
        first.feed(said[start:end])
        verdicts.append(identify(first.data, kind))
        if kind == "lineus":
            error = _greeting_error(first.data, "127.0.0.1:1")
            assert error is None or f"it is {ROWS[name].what} " in str(error), (first.data, error)
    assert all(v in (None, ROWS[name]) for v in verdicts), verdicts
    assert identify(first.data, kind, final=True) is ROWS[name]


def test_gathered_bytes_are_bounded() -> None:
    first = FirstBytes()
    for _ in range(10_000):
        first.feed(b"SSH-2.0-" + b"x" * 5000)
    assert len(first.data) == HEAD_BYTES
    assert identify(first.data, "xyz") is ROWS["ssh"]
    assert not undecided(b"x" * HEAD_BYTES, "xyz")
    assert undecided(b"SS", "lineus")


@pytest.mark.parametrize(("name", "quoted"), [
    ("ssh", "'SSH-2.0-OpenSSH_9.2p1 Debian-2+deb12u3'"),
    ("http", "'HTTP/1.1 400 Bad Request'"),
    ("html", "'<!DOCTYPE HTML>'"),
    ("lineus", "'hello VERSION:\"3.2.0 Nov 17 2019 17:54:57\" NAME:line-us SERI…'"),
    ("mqtt", "b' \\x02\\x00\\x00'"),
    ("telnet", repr(SAID["telnet"])),
])
def test_the_message_names_the_address_and_quotes_the_first_line(name: str, quoted: str) -> None:
    """Text as its first line (at most 60 characters), binary words as bytes."""
    error = wrong_peer(SAID[name], "an XYZv3 printer", "xyz", "10.0.0.7:9100", final=True)
    assert str(error) == f"10.0.0.7:9100 is not an XYZv3 printer: it is {ROWS[name].what} (it said {quoted})"


# -- over real TCP, through the CLI --------------------------------------------------------------------------------

Sender = Callable[[socket.socket, bytes], None]


def whole(conn: socket.socket, said: bytes) -> None:
    conn.sendall(said)


def byte_by_byte(conn: socket.socket, said: bytes) -> None:
    for i in range(len(said)):
        conn.sendall(said[i:i + 1])
        time.sleep(0.01)


def cut_at(*points: int) -> Sender:
    def send(conn: socket.socket, said: bytes) -> None:
        last = 0
        for point in [*points, len(said)]:
            conn.sendall(said[last:point])
            last = point
            time.sleep(0.15)
    return send


class Peer:
    """A TCP server on a free loopback port that sends `said` on each connection in the way `send` cuts it, then
    reads and ignores what it is sent until the client goes."""

    def __init__(self, said: bytes, send: Sender) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.said, self.send = said, send
        self.stop = threading.Event()
        threading.Thread(target=self._accept, daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        with conn:
            try:
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self.send(conn, self.said)
                while not self.stop.is_set() and conn.recv(4096):
                    pass
            except OSError:
                pass

    def _accept(self) -> None:
        while not self.stop.is_set():
            try:
                conn, _ = self.server.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def close(self) -> None:
        self.stop.set()
        self.server.close()


def assert_named(kind: str, where: str, what: str) -> None:
    result = run_cli(*CLIENTS[kind][:1], "-d", where, *CLIENTS[kind][1:])
    assert result.returncode == 6, result.stderr  # a protocol error, not a link timeout (exit 9)
    line, = result.stderr.splitlines()
    assert line.startswith(f"fabwire: error: {where} is not {EXPECTED[kind]}: it is {what} (it said "), line


SENDERS = {"whole": whole, "byte-by-byte": byte_by_byte, "split": cut_at(2)}


@pytest.mark.parametrize("how", SENDERS)
@pytest.mark.parametrize(("kind", "name"), CASES, ids=[f"{k}-{n}" for k, n in CASES])
def test_a_client_names_the_peer_it_reached(kind: str, name: str, how: str) -> None:
    peer = Peer(SAID[name], SENDERS[how])
    try:
        assert_named(kind, f"127.0.0.1:{peer.port}", ROWS[name].what)
    finally:
        peer.close()


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=st.sampled_from([c for c in CASES if c[1] in ("ssh", "html", "http", "marlin", "agent")]),
       data=st.data())
def test_a_client_names_a_greeting_cut_anywhere(case: tuple[str, str], data: st.DataObject) -> None:
    kind, name = case
    said = SAID[name]
    points = sorted(data.draw(st.sets(st.integers(1, len(said) - 1), min_size=1, max_size=4)))
    peer = Peer(said, cut_at(*points))
    try:
        assert_named(kind, f"127.0.0.1:{peer.port}", ROWS[name].what)
    finally:
        peer.close()


def test_a_long_greeting_without_a_line_end_is_named() -> None:
    def flood(conn: socket.socket, said: bytes) -> None:
        conn.sendall(said)
        chunk = b"x" * 65536
        for _ in range(800):  # 50 MB, no newline
            conn.sendall(chunk)

    for kind in CLIENTS:
        peer = Peer(b"SSH-2.0-", flood)
        try:
            assert_named(kind, f"127.0.0.1:{peer.port}", "an SSH server")
        finally:
            peer.close()


@pytest.mark.parametrize("kind", CLIENTS)
def test_a_peer_that_never_says_anything_is_a_timeout_at_its_address(kind: str) -> None:
    """Nothing to name it by, whatever it is asked: the client's own timeout, in one line with the address."""
    peer = Peer(b"", whole)
    try:
        where = f"127.0.0.1:{peer.port}"
        result = run_cli(*CLIENTS[kind][:1], "-d", where, *CLIENTS[kind][1:])
    finally:
        peer.close()
    assert result.returncode == 9, result.stderr  # a link timeout
    line, = result.stderr.splitlines()
    assert where in line, line
    assert "is not" not in line, line


@pytest.mark.parametrize("kind", CLIENTS)
def test_a_silent_peer_with_one_connection_slot_is_probed_after_the_link_is_let_go(kind: str) -> None:
    """A peer that serves one connection at a time (a serial bridge, a small broker) and says nothing until it
    hears its own protocol: the client lets its link go before it probes, or the probe would wait in the queue."""
    server = socket.create_server(("127.0.0.1", 0))

    def serve() -> None:
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            with conn, contextlib.suppress(OSError):
                while chunk := conn.recv(4096):
                    if chunk.startswith(b"\x10"):  # an MQTT CONNECT
                        conn.sendall(SAID["mqtt"])

    threading.Thread(target=serve, daemon=True).start()
    try:
        assert_named(kind, f"127.0.0.1:{server.getsockname()[1]}", "an MQTT broker")
    finally:
        server.close()


# -- the real peers --------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def sims() -> Iterator[dict[str, RunningSimulator]]:
    speed = {"xyz": "1000", "mmu": "1", "lineus": "0"}
    running = {kind: start_simulator(kind, "--listen", "127.0.0.1:0", "--speed", speed[kind]) for kind in CLIENTS}
    yield running
    for sim in running.values():
        sim.stop()


@pytest.mark.parametrize("kind", CLIENTS)
@pytest.mark.parametrize("other", CLIENTS)
def test_a_client_names_each_other_simulator(sims: dict[str, RunningSimulator], kind: str, other: str) -> None:
    if kind == other:
        return
    assert_named(kind, sims[other].url.removeprefix("tcp://"), ROWS[other].what)


@pytest.mark.parametrize("kind", CLIENTS)
def test_a_client_names_python_http_server(kind: str, tmp_path: Path) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = subprocess.Popen([sys.executable, "-m", "http.server", str(port), "--bind", "127.0.0.1",
                               "--directory", str(tmp_path)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
                break
            except OSError:
                time.sleep(0.05)
        assert_named(kind, f"127.0.0.1:{port}", "a web server")
    finally:
        server.terminate()
        server.wait(10)


@pytest.mark.parametrize("kind", CLIENTS)
def test_a_client_names_mosquitto(kind: str, tmp_path: Path) -> None:
    broker = Mosquitto(tmp_path)
    broker.start()
    try:
        assert_named(kind, f"127.0.0.1:{broker.port}", "an MQTT broker")
    finally:
        broker.stop()


def test_each_client_names_fabwire_serve(sims: dict[str, RunningSimulator], tmp_path: Path) -> None:
    agent = start_agent(tmp_path / "state", "--listen", "127.0.0.1:0", "--device", f"xyz={sims['xyz'].url}")
    try:
        where = agent.url.removeprefix("http://").rstrip("/")
        for kind in CLIENTS:
            assert_named(kind, where, "fabwire's agent, `fabwire serve`")
    finally:
        agent.stop()
