"""The demo's machines on a shared broker, as real processes: their ids are never a real machine's, and every
retained topic an agent publishes is emptied by the one `fabwire.mqtt.topics.RETAINED_TOPICS` names, when it says,
including after a demo is killed."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from mqtttools import Mosquitto
from servetools import Agents, Watch, of_demo, retained

from fabwire.agent.core import DEMO_IDS, KINDS, demo_id
from fabwire.mqtt.topics import RETAINED_TOPICS, default_agent_id

pytestmark = pytest.mark.timeout(180)
DEMO = tuple(demo_id(kind) for kind in KINDS)


def _stop(process: subprocess.Popen[str]) -> str:
    """SIGTERM (a clean stop, as a service manager's); its stderr."""
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 0, stderr
    return stderr


def _published(watch: Watch) -> None:
    watch.until(lambda w: all(w.latest.get(f"homeassistant/device/fabwire_{d}/config") for d in DEMO)
                and all(w.latest.get(f"fabwire/device/{d}/availability") == b"online" for d in DEMO))


def _agent_of(watch: Watch, device: str) -> Any:
    return (watch.json(f"fabwire/device/{device}/info") or {}).get("agent")


def _claimants(watch: Watch, device: str) -> set[str]:
    prefix = f"fabwire/device/{device}/claim/"
    return {t.removeprefix(prefix) for t, p in list(watch.latest.items()) if t.startswith(prefix) and p}


def test_a_demo_never_takes_a_real_machines_topics(broker: Mosquitto, agents: Agents, watch: Watch,
                                                   simulator: Any) -> None:
    """A Line-us whose serial is `demo` does not get the demo's id `lineus-demo` (`DEVICE_IDS`). A demo agent
    beside the real one leaves the real machine's info, availability and discovery alone, and its clean stop
    leaves no claim of its own on any machine."""
    robot = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0", "--serial", "demo")
    agents.start("real", broker, f"real:lineus={robot.url}")
    real = watch.until(lambda w: next((t.split("/")[2] for t in list(w.latest) if t.startswith("fabwire/device/")
                                       and t.endswith("/info") and (w.json(t) or {}).get("serial") == "demo"), None))
    assert real.startswith("lineus-demo-")
    assert real not in DEMO_IDS
    watch.until(lambda w: w.latest.get(f"homeassistant/device/fabwire_{real}/config"))
    real_agent = _agent_of(watch, real)
    demo = agents.start("demo", broker, options=("--demo", "--speed", "30"), state_dir=False)
    _published(watch)
    demo_agent = _agent_of(watch, demo_id("lineus"))
    assert demo_agent != real_agent
    assert _agent_of(watch, real) == real_agent
    assert _claimants(watch, real) == {real_agent}
    _stop(demo)
    left = retained(broker)
    assert json.loads(left[f"fabwire/device/{real}/info"])["serial"] == "demo"
    assert left[f"fabwire/device/{real}/availability"] == b"online"
    assert left[f"homeassistant/device/fabwire_{real}/config"]
    assert not [t for t in left if demo_agent in t or of_demo(t)], left
    assert not [(t, p) for t, p in watch.log if t.startswith((f"fabwire/device/{real}/",
                                                              f"homeassistant/device/fabwire_{real}/"))
                and not p], "the real machine's topics were emptied"


def test_a_demo_stopping_leaves_its_machines_to_another_live_demo(broker: Mosquitto, agents: Agents, watch: Watch,
                                                                 tmp_path: Path) -> None:
    """Two demos claim the same demo machines: the owner's clean stop takes its claims away, not the machines'
    topics (the other demo publishes them from then on); the last demo's stop empties them."""
    names = sorted(("one", "two"), key=lambda n: default_agent_id(tmp_path / n))  # the owner sorts first
    first = agents.start(names[0], broker, options=("--demo", "--speed", "30"))
    second = agents.start(names[1], broker, options=("--demo", "--speed", "30"))
    owner, standby = (default_agent_id(tmp_path / n) for n in names)
    _published(watch)
    watch.until(lambda w: all(_claimants(w, d) == {owner, standby} for d in DEMO))
    assert all(_agent_of(watch, d) == owner for d in DEMO)
    _stop(first)
    watch.until(lambda w: all(_agent_of(w, d) == standby for d in DEMO))
    assert all(_claimants(watch, d) == {standby} for d in DEMO)
    emptied = [t for t, p in watch.log if not p and of_demo(t) and "/claim/" not in t]
    assert emptied == [], "a live demo's machines were emptied"
    _stop(second)
    left = retained(broker)
    assert not [t for t in left if of_demo(t)], left


def test_what_a_killed_demo_left_is_cleared_by_the_next_agent(broker: Mosquitto, agents: Agents, watch: Watch
                                                             ) -> None:
    """A demo killed (no goodbye) leaves its machines online, its claims and, with no state directory, records
    under an id never used again: the next agent to connect, any agent, clears them once the broker's last will
    says the demo is offline."""
    demo = agents.start("demo", broker, options=("--demo", "--speed", "30"), state_dir=False)
    _published(watch)
    dead = _agent_of(watch, DEMO[0])
    assert json.loads(watch.latest[f"fabwire/agent/{dead}/info"])["passing"] is True
    demo.send_signal(signal.SIGKILL)
    demo.wait(10)
    watch.until(lambda w: w.latest.get(f"fabwire/agent/{dead}/status") == b"offline")
    assert retained(broker).get(f"homeassistant/device/fabwire_{DEMO[0]}/config")  # the ghost, before
    agents.start("next", broker)  # an agent with no machines at all
    watch.until(lambda w: not [t for t, p in w.latest.items() if p and (of_demo(t) or dead in t)
                               and not t.endswith(("/heartbeat", "/sync"))])
    left = retained(broker)
    assert not [t for t in left if of_demo(t) or dead in t], left


def test_a_killed_agent_with_a_state_directory_keeps_its_records(broker: Mosquitto, agents: Agents, watch: Watch,
                                                                 simulator: Any, tmp_path: Path) -> None:
    """An agent with a state directory comes back under the same id: killed, its machine stays on the broker,
    offline, with its claim, as the README says (only a demo's records go)."""
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    killed = agents.start("a", broker, f"arm:lineus={sim.url}")
    device = watch.until(lambda w: w.device_of_kind("lineus"))
    agent = default_agent_id(tmp_path / "a")
    watch.until(lambda w: _claimants(w, device) == {agent} and _agent_of(w, device) == agent)
    killed.send_signal(signal.SIGKILL)
    killed.wait(10)
    watch.until(lambda w: w.latest.get(f"fabwire/agent/{agent}/status") == b"offline")
    other = simulator("mmu", "--listen", "127.0.0.1:0")
    agents.start("b", broker, f"m:mmu={other.url}")  # its first publication comes with its first sweep
    watch.until(lambda w: (mmu := w.device_of_kind("mmu")) and _agent_of(w, mmu) == default_agent_id(tmp_path / "b")
                and w.latest.get(f"fabwire/device/{mmu}/state"))
    left = retained(broker)
    assert left[f"fabwire/device/{device}/claim/{agent}"] == b"1"
    assert json.loads(left[f"fabwire/device/{device}/info"])["agent"] == agent
    assert left[f"fabwire/agent/{agent}/info"]


COVERED = {
    ("fabwire/agent/AGENT/status", 0): "test_serve_mqtt.py::test_a_demo_leaves_no_ghost_machines_on_the_broker",
    ("fabwire/agent/AGENT/status", 1): "test_what_a_killed_demo_left_is_cleared_by_the_next_agent",
    ("fabwire/agent/AGENT/info", 0): "test_serve_mqtt.py::test_a_demo_leaves_no_ghost_machines_on_the_broker",
    ("fabwire/agent/AGENT/info", 1): "test_what_a_killed_demo_left_is_cleared_by_the_next_agent",
    ("fabwire/device/DEVICE/claim/AGENT", 0): "test_bridge.py::test_a_removed_device_is_cleaned_up",
    ("fabwire/device/DEVICE/claim/AGENT", 1): "test_a_demo_never_takes_a_real_machines_topics",
    ("fabwire/device/DEVICE/claim/AGENT", 2): "test_broker_trust.py::test_claims_nobody_stands_behind_go_stale",
    ("fabwire/device/DEVICE/claim/AGENT", 3): "test_what_a_killed_demo_left_is_cleared_by_the_next_agent",
    ("fabwire/device/DEVICE/info, state, availability", 0): "test_bridge.py::test_a_removed_device_is_cleaned_up",
    ("fabwire/device/DEVICE/info, state, availability", 1):
        "test_a_demo_stopping_leaves_its_machines_to_another_live_demo",
    ("fabwire/device/DEVICE/info, state, availability", 2):
        "test_what_a_killed_demo_left_is_cleared_by_the_next_agent",
    ("homeassistant/device/fabwire_DEVICE/config (or one per entity)", 0):
        "test_bridge.py::test_per_entity_discovery_for_older_home_assistant_is_published_and_removed",
    ("homeassistant/device/fabwire_DEVICE/config (or one per entity)", 1):
        "test_a_demo_stopping_leaves_its_machines_to_another_live_demo",
    ("homeassistant/device/fabwire_DEVICE/config (or one per entity)", 2):
        "test_what_a_killed_demo_left_is_cleared_by_the_next_agent",
}
"""Which test empties each retained topic as each row of RETAINED_TOPICS says."""


@pytest.mark.parametrize(("topic", "index"), [(row[0], i) for row in RETAINED_TOPICS for i in range(len(row[2]))])
def test_every_way_a_retained_topic_goes_has_its_test(topic: str, index: int) -> None:
    where = COVERED[(topic, index)]
    file, _, name = where.rpartition("::")
    source = (Path(__file__).parent / (file or Path(__file__).name)).read_text()
    assert f"def {name}(" in source, where
