"""`fabwire serve --mqtt` as real processes: a simulator behind the agent, the broker in front, commands that move
the simulated arm, the last will when an agent is killed, two agents on one device, and `fabwire fleet`."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from hatools import check_device_discovery, check_entity_discovery
from mqtttools import Mosquitto
from servetools import ANNOUNCEMENT, Agents, Watch, of_demo, retained

from clitools import cli_env, run_cli
from fabwire.mqtt.discovery import discovery_topics

pytestmark = pytest.mark.timeout(120)


def test_agent_publishes_a_simulator_and_its_commands_move_it(broker: Mosquitto, agents: Agents, watch: Watch,
                                                             simulator: Any, tmp_path: Path) -> None:
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    agent = agents.start("a", broker, f"arm:lineus={sim.url}")
    device = watch.until(lambda w: w.device_of_kind("lineus"))
    discovery = watch.until(lambda w: w.json(f"homeassistant/device/fabwire_{device}/config"))
    assert discovery["device"]["manufacturer"] == "Line-us"
    assert discovery["device"]["configuration_url"] == agents.urls["a"]  # Home Assistant's link to the dashboard
    assert check_device_discovery(f"homeassistant/device/fabwire_{device}/config", discovery) == []
    watch.until(lambda w: w.latest.get(f"fabwire/device/{device}/availability") == b"online")
    # the first state may be published before the agent's first poll: wait for the one that says online
    state = watch.until(lambda w: (s := w.json(f"fabwire/device/{device}/state")) and s["online"] and s)
    assert state["kind"] == "lineus"
    assert state["online"] is True
    watch.send(device, {"action": "move", "params": {"x": 1200, "y": 150}, "id": "move-1"})
    reply = watch.until(lambda w: w.json(f"fabwire/device/{device}/reply"))
    assert reply["ok"], reply
    assert reply["id"] == "move-1"
    position = run_cli("--json", "lineus", "-d", sim.url, "position", env=cli_env(tmp_path))
    assert position.returncode == 0, position.stderr
    where = json.loads(position.stdout)
    assert (round(where["machine_units"]["x"]), round(where["machine_units"]["y"])) == (1200, 150)
    # The fleet as seen on the broker: the device and the agent that runs it.
    fleet = run_cli("--json", "fleet", "--mqtt", broker.url, env=cli_env(tmp_path))
    assert fleet.returncode == 0, fleet.stderr
    rows = json.loads(fleet.stdout)["devices"]
    assert [(r["device"], r["kind"], r["agent_online"]) for r in rows] == [(device, "lineus", True)]
    agent_id = rows[0]["agent"]
    assert agent.stdout is not None  # the owner is told the bridge is live, as where the agent listens
    assert agent.stdout.readline() == f"fabwire agent publishing to {broker.url} as agent {agent_id}\n"
    # Killed without a goodbye: the broker's last will says the agent is offline.
    os.kill(agent.pid, signal.SIGKILL)
    watch.until(lambda w: w.latest.get(f"fabwire/agent/{agent_id}/status") == b"offline")
    after = json.loads(run_cli("--json", "fleet", "--mqtt", broker.url, env=cli_env(tmp_path)).stdout)
    assert [(r["agent"], r["agent_online"], r["availability"]) for r in after["devices"]] == [
        (agent_id, False, "offline")]


def test_two_agents_with_one_device_take_turns(broker: Mosquitto, agents: Agents, watch: Watch, simulator: Any,
                                               tmp_path: Path) -> None:
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    first = agents.start("a", broker, f"arm:lineus={sim.url}")
    second = agents.start("b", broker, f"arm:lineus={sim.url}")
    device = watch.until(lambda w: w.device_of_kind("lineus"))
    claims = watch.until(lambda w: (c := sorted(t.rsplit("/", 1)[1] for t, p in w.latest.items()
                                               if t.startswith(f"fabwire/device/{device}/claim/") and p))
                         and len(c) == 2 and c)
    owner, standby = claims
    watch.until(lambda w: (w.json(f"fabwire/device/{device}/info") or {}).get("agent") == owner)
    watch.send(device, {"action": "pen_up", "id": "up-1"})
    watch.until(lambda w: w.json(f"fabwire/device/{device}/reply"))
    time.sleep(0.5)
    replies = [json.loads(p) for t, p in watch.log if t == f"fabwire/device/{device}/reply"]
    assert [r["agent"] for r in replies] == [owner]  # answered once, by the owner
    fleet = json.loads(run_cli("--json", "fleet", "--mqtt", broker.url, env=cli_env(tmp_path)).stdout)
    assert [(r["agent"], r["standby"]) for r in fleet["devices"]] == [(owner, [standby])]
    # The owner dies; the standby agent takes the device over.
    by_id = {"a": first, "b": second}
    dying = next(p for name, p in by_id.items() if owner.endswith(_digest(tmp_path / name)))
    dying.send_signal(signal.SIGKILL)
    watch.until(lambda w: (w.json(f"fabwire/device/{device}/info") or {}).get("agent") == standby)
    watch.until(lambda w: w.latest.get(f"fabwire/device/{device}/availability") == b"online")


def test_the_owner_writes_its_device_again_when_another_agent_wrote_over_it(
        broker: Mosquitto, agents: Agents, watch: Watch, simulator: Any) -> None:
    """An agent that could not see the owner alive (a late heartbeat) may publish the device's retained info in
    its own name; the owner writes it back, so the broker ends naming the agent that answers commands."""
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    agents.start("a", broker, f"arm:lineus={sim.url}")
    device = watch.until(lambda w: w.device_of_kind("lineus"))
    owner = watch.until(lambda w: (w.json(f"fabwire/device/{device}/info") or {}).get("agent"))
    info = watch.json(f"fabwire/device/{device}/info")
    watch.client.publish(f"fabwire/device/{device}/info", json.dumps({**info, "agent": "vm-000000"}), qos=1,
                         retain=True).wait_for_publish(10)
    def publishers(w: Watch) -> list[str]:
        return [json.loads(p).get("agent") for t, p in w.log if t == f"fabwire/device/{device}/info" and p]

    watch.until(lambda w: "vm-000000" in publishers(w))
    watch.until(lambda w: publishers(w)[publishers(w).index("vm-000000"):][-1] == owner)


def _digest(state_dir: Path) -> str:
    from fabwire.mqtt.topics import default_agent_id

    return default_agent_id(state_dir).rsplit("-", 1)[1]


def test_fleet_command_errors_are_one_line(tmp_path: Path) -> None:
    bad = run_cli("fleet", "--mqtt", "http://nowhere", env=cli_env(tmp_path))
    assert bad.returncode == 2  # a broker address that cannot work is a usage error
    errors = [line for line in bad.stderr.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1
    assert "mqtt://host[:port]" in errors[0]
    from mqtttools import free_port

    down = run_cli("fleet", "--mqtt", f"mqtt://127.0.0.1:{free_port()}", env=cli_env(tmp_path))
    assert down.returncode == 8, down.stderr
    assert "Traceback" not in down.stderr
    assert "nothing listens on port" in down.stderr  # what to check, as for a device; no raw errno
    assert "Errno" not in down.stderr


def test_fleet_at_a_port_where_no_broker_speaks_says_to_check_for_a_broker(tmp_path: Path) -> None:
    """Another server there (it greets as SSH does, then answers no CONNACK): the broker's check, not a device's."""
    server = socket.create_server(("127.0.0.1", 0))
    held: list[socket.socket] = []

    def greet() -> None:
        with contextlib.suppress(OSError):
            while True:
                conn, _ = server.accept()
                held.append(conn)
                conn.sendall(b"SSH-2.0-OpenSSH_9.2p1 Debian-2\r\n")

    threading.Thread(target=greet, daemon=True).start()
    try:
        told = run_cli("fleet", "--mqtt", f"mqtt://127.0.0.1:{server.getsockname()[1]}", env=cli_env(tmp_path))
    finally:
        server.close()
        for conn in held:
            conn.close()
    assert told.returncode == 8, told.stderr
    line, = told.stderr.splitlines()
    assert "check that an MQTT broker listens there (port 1883, 8883 with TLS)" in line, line
    assert "device" not in line


def test_per_entity_discovery_from_serve(broker: Mosquitto, agents: Agents, watch: Watch, simulator: Any) -> None:
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    agents.start("a", broker, f"arm:lineus={sim.url}", options=("--mqtt-discovery", "entity"))
    device = watch.until(lambda w: w.device_of_kind("lineus"))
    topics = discovery_topics(device, "entity")
    watch.until(lambda w: all(w.latest.get(t) for t in topics))
    for topic in topics:
        payload = watch.json(topic)
        assert check_entity_discovery(topic, payload) == [], topic
        assert payload["device"]["configuration_url"] == agents.urls["a"]
    assert not watch.latest.get(f"homeassistant/device/fabwire_{device}/config")


@pytest.mark.parametrize("state_dir", [False, True], ids=["no-state-dir", "state-dir"])
def test_a_demo_leaves_no_ghost_machines_on_the_broker(broker: Mosquitto, watch: Watch, tmp_path: Path,
                                                      state_dir: bool) -> None:
    """The demo's machines exist while it runs: a clean stop takes them off the broker with their Home Assistant
    discovery; an agent whose id is new each run (no --state-dir) takes its own records too, and with a state
    directory it stays, offline, as any agent does."""
    args = [sys.executable, "-m", "fabwire", "serve", "--demo", "--speed", "30", "--listen", "127.0.0.1:0",
            "--mqtt", broker.url, *(["--state-dir", str(tmp_path / "state")] if state_dir else [])]
    process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=cli_env(tmp_path))
    try:
        assert process.stdout is not None
        assert process.stdout.readline().startswith(ANNOUNCEMENT)
        demo = ("xyz-demo", "lineus-demo", "mmu-demo")
        watch.until(lambda w: all(w.latest.get(f"homeassistant/device/fabwire_{d}/config") for d in demo)
                    and all(w.latest.get(f"fabwire/device/{d}/availability") == b"online" for d in demo))
        agent = watch.until(lambda w: next((t.split("/")[2] for t, p in w.latest.items()
                                            if t.startswith("fabwire/agent/") and t.endswith("/info") and p), None))
        process.send_signal(signal.SIGTERM)
        _, stderr = process.communicate(timeout=60)
        assert process.returncode == 0, stderr
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    left = retained(broker)
    assert not [t for t in left if of_demo(t)], left
    kept = sorted(t for t in left if t.startswith(f"fabwire/agent/{agent}/"))
    if state_dir:
        assert kept == [f"fabwire/agent/{agent}/info", f"fabwire/agent/{agent}/status"]
        assert left[f"fabwire/agent/{agent}/status"] == b"offline"
    else:
        assert kept == []


def test_a_broker_that_is_not_there_yet_is_said_once_then_connected(agents: Agents, tmp_path: Path) -> None:
    """`fabwire: MQTT broker …; retrying` once (its retries are logged with -v only), then the connection."""
    from mqtttools import free_port

    broker = Mosquitto(tmp_path / "broker", port=free_port())
    (tmp_path / "broker").mkdir()
    agent = agents.start("a", broker, options=("-v",))
    assert agent.stderr is not None
    said = []
    retries = 0
    while retries < 3:  # the agent's own log (-v) shows each retry; the terminal line comes once
        line = agent.stderr.readline()
        assert line, said
        said += [line] if line.startswith("fabwire: MQTT broker") else []
        retries += "fabwire.mqtt: MQTT broker" in line and "retrying in" in line
    broker.start()
    try:
        assert agent.stdout is not None
        assert agent.stdout.readline().startswith(f"fabwire agent publishing to {broker.url} as agent ")
    finally:
        agent.send_signal(signal.SIGTERM)
        _, rest = agent.communicate(timeout=60)
        broker.stop()
    said += [line for line in rest.splitlines(keepends=True) if line.startswith("fabwire: MQTT broker")]
    assert len(said) == 1, said
    assert said[0].startswith(f"fabwire: MQTT broker {broker.url}: connection refused by 127.0.0.1:{broker.port}")
    assert said[0].rstrip().endswith("retrying in 0.5 s")


@pytest.mark.parametrize("action", ["cancel", "pause", "resume"])
def test_a_job_action_on_an_idle_printer_says_there_is_nothing_to_act_on(
        broker: Mosquitto, agents: Agents, watch: Watch, simulator: Any, action: str) -> None:
    """Not "cancel cannot be undone: send confirm": what cannot happen now is refused as such."""
    sim = simulator("xyz", "--listen", "127.0.0.1:0")
    agents.start("a", broker, f"desk:xyz={sim.url}")
    device = watch.until(lambda w: w.device_of_kind("xyz"))
    watch.until(lambda w: (s := w.json(f"fabwire/device/{device}/state")) and s["online"]
                and s["summary"]["state"] == "idle")
    watch.send(device, {"action": action, "id": f"{action}-1"})
    reply = watch.until(lambda w: w.json(f"fabwire/device/{device}/reply"))
    assert reply["ok"] is False, reply
    assert reply["error"].startswith(f"desk has nothing to {action}: it is idle"), reply
    assert "confirm" not in reply["error"].split(";")[0]


def test_a_clean_stop_leaves_the_retained_state_offline(broker: Mosquitto, agents: Agents, watch: Watch,
                                                         simulator: Any) -> None:
    """Whoever reads only a machine's retained state (not its availability) after the agent's clean stop sees it
    offline, with the reason, rather than the last "online" state."""
    sim = simulator("xyz", "--listen", "127.0.0.1:0")
    agent = agents.start("a", broker, f"jr:xyz={sim.url}")
    device = watch.until(lambda w: w.device_of_kind("xyz"))
    watch.until(lambda w: (s := w.json(f"fabwire/device/{device}/state")) and s["online"] and s)
    agent.send_signal(signal.SIGTERM)
    assert agent.wait(timeout=30) == 0
    state = json.loads(retained(broker)[f"fabwire/device/{device}/state"])
    assert state["online"] is False
    assert state["summary"]["state"] == "offline"
    assert state["summary"]["state_text"].endswith("stopped")
    assert state["kind"] == "xyz"  # the rest of the record stays as it was
    assert retained(broker)[f"fabwire/device/{device}/availability"] == b"offline"
