"""`fabwire fleet` and `fabwire serve --mqtt` pointed at a server that is no MQTT broker name what answered (every
row of `fabwire.transport.peers.FOREIGN`, a real `python -m http.server` and a real Line-us simulator) instead of
waiting out the MQTT client's timeout; a real broker, with or without a login, is taken as one."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import httpx
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from mqtttools import Mosquitto, free_port

from clitools import cli_env, run_cli
from fabwire.mqtt.probe import CONNACK, SILENT, connect_packet, not_a_broker
from fabwire.mqtt.topics import MQTT_OFF
from fabwire.transport.peers import FOREIGN
from peertools import SAID, saying

NOBODY = b"\x00\x01\x02 not a protocol anyone speaks"
NAMED = [row for row in FOREIGN if row.name != "mqtt"]  # a broker's CONNACK is what fleet waits for


def _fleet(port: int, tmp_path: Path) -> str:
    told = run_cli("fleet", "--mqtt", f"mqtt://127.0.0.1:{port}", env=cli_env(tmp_path), timeout=60)
    assert told.returncode == 8, told.stderr
    line, = told.stderr.splitlines()
    assert line.endswith("check that an MQTT broker listens there (port 1883, 8883 with TLS) on this network"), line
    return line


@pytest.mark.parametrize("name", [row.name for row in NAMED] + [""], ids=[row.name for row in NAMED] + ["?"])
@pytest.mark.parametrize("first", [True, False], ids=["greets", "answers-a-line"])
def test_fleet_names_the_server_it_found(name: str, first: bool, tmp_path: Path) -> None:
    what = next((row.what for row in NAMED if row.name == name), "")
    with saying(SAID[name] if name else NOBODY, first=first) as port:
        line = _fleet(port, tmp_path)
    if what:
        assert f"127.0.0.1:{port} is not an MQTT broker: it is {what} (it said " in line
    else:
        assert f"127.0.0.1:{port} is not an MQTT broker: it answered " in line
        assert "where a broker answers with CONNACK" in line


def test_fleet_names_a_real_web_server(tmp_path: Path) -> None:
    port = free_port()
    web = subprocess.Popen([sys.executable, "-m", "http.server", str(port), "--bind", "127.0.0.1"],
                           cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        for _ in range(200):
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=1):
                break
            web.poll()
            assert web.returncode is None
            threading.Event().wait(0.05)
        assert "is not an MQTT broker: it is a web server" in _fleet(port, tmp_path)
    finally:
        web.terminate()
        web.wait(10)


def test_fleet_names_a_real_line_us(simulator: Any, tmp_path: Path) -> None:
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    port = int(sim.url.rsplit(":", 1)[1])
    assert "is not an MQTT broker: it is a Line-us drawing robot" in _fleet(port, tmp_path)


@pytest.mark.parametrize(("kind", "what"), [("xyz", "an XYZv3 printer"), ("mmu", "a Prusa MMU3")])
def test_fleet_names_a_real_machine_that_answers_only_its_own_language(kind: str, what: str, simulator: Any,
                                                                       tmp_path: Path) -> None:
    """A da Vinci and an MMU ignore a CONNECT and a line end: they are asked in their own languages. (The MMU is
    sped up: after power-on it hears nothing for its 4 s self-test, and this one has just been switched on.)"""
    sim = simulator(kind, "--listen", "127.0.0.1:0", *(["--speed", "40"] if kind == "mmu" else []))
    port = int(sim.url.rsplit(":", 1)[1])
    assert f"is not an MQTT broker: it is {what}" in _fleet(port, tmp_path)


def test_a_silent_server_is_still_no_answer(tmp_path: Path) -> None:
    with saying(None) as port:
        line = _fleet(port, tmp_path)
    assert f"no answer from 127.0.0.1:{port}" in line


@pytest.mark.parametrize("anonymous", [True, False], ids=["anonymous", "login-needed"])
def test_a_real_broker_answers_connack(tmp_path: Path, anonymous: bool) -> None:
    broker = Mosquitto(tmp_path, anonymous=anonymous)
    broker.start()
    try:
        assert asyncio.run(not_a_broker("127.0.0.1", broker.port)) is None
        with socket.create_connection(("127.0.0.1", broker.port), timeout=10) as raw:
            raw.sendall(connect_packet("fabwire-test"))
            assert raw.recv(1)[0] == CONNACK  # what the probe looks for, from Mosquitto itself
    finally:
        broker.stop()


def test_silence_is_told_apart() -> None:
    with saying(None) as port:
        assert asyncio.run(not_a_broker("127.0.0.1", port, timeout_s=1.0)) == SILENT


def test_serve_says_what_answers_where_its_broker_should_be(tmp_path: Path) -> None:
    with saying(SAID["http"]) as port:
        process = subprocess.Popen([sys.executable, "-m", "fabwire", "serve", "--listen", "127.0.0.1:0",
                                    "--state-dir", str(tmp_path / "state"), "--mqtt", f"mqtt://127.0.0.1:{port}"],
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=cli_env(tmp_path))
        try:
            assert process.stderr is not None
            assert process.stdout is not None
            url = process.stdout.readline().split(" listening on ", 1)[1].strip()
            line = process.stderr.readline()
            while line and not line.startswith("fabwire: MQTT broker"):
                line = process.stderr.readline()
            health = httpx.get(f"{url}api/v1/agent", timeout=30)  # the agent goes on without its bridge
        finally:
            process.terminate()
            process.communicate(timeout=60)
    assert line.startswith(f"fabwire: MQTT broker mqtt://127.0.0.1:{port}: 127.0.0.1:{port} is not an MQTT broker: "
                           "it is a web server"), line
    assert line.rstrip().endswith(f"; {MQTT_OFF}"), line  # another server there is no reason to ask it again
    assert health.status_code == 200, health.text
