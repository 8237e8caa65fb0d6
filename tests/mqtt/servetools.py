"""`fabwire serve --mqtt` as real processes for the MQTT tests: agents started and killed, a blocking observer of
the broker, and the retained topics as a newcomer to the broker gets them."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
from mqtttools import Mosquitto

from clitools import cli_env

ANNOUNCEMENT = "fabwire agent listening on "


class Agents:
    """`fabwire serve` processes, killed at the end."""

    def __init__(self, tmp_path: Path) -> None:
        self.tmp_path = tmp_path
        self.processes: list[subprocess.Popen[str]] = []
        self.urls: dict[str, str] = {}

    def start(self, name: str, broker: Mosquitto, *devices: str, options: tuple[str, ...] = (),
              state_dir: bool = True) -> subprocess.Popen[str]:
        """`serve --state-dir TMP/name --mqtt BROKER --device …` (no state directory: a new agent id each run)."""
        args = [sys.executable, "-m", "fabwire", "serve", "--listen", "127.0.0.1:0", "--mqtt", broker.url,
                *(["--state-dir", str(self.tmp_path / name)] if state_dir else []), *options]
        for device in devices:
            args += ["--device", device]
        process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                   env=cli_env(self.tmp_path))
        self.processes.append(process)
        assert process.stdout is not None
        line = process.stdout.readline()
        assert line.startswith(ANNOUNCEMENT), line + (process.stderr.read() if process.stderr else "")
        self.urls[name] = line.removeprefix(ANNOUNCEMENT).strip()
        return process

    def stop_all(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                process.kill()
            process.wait(10)
            for stream in (process.stdout, process.stderr):
                if stream:
                    stream.close()


class Watch:
    """A plain (blocking) MQTT client in its own thread: each topic's latest payload, and a way to publish."""

    def __init__(self, broker: Mosquitto) -> None:
        self.latest: dict[str, bytes] = {}
        self.log: list[tuple[str, bytes]] = []
        self.client = paho.Client(paho.CallbackAPIVersion.VERSION2)
        self.client.on_message = self._message
        self.client.connect("127.0.0.1", broker.port)
        self.client.subscribe("fabwire/#", qos=1)
        self.client.subscribe("homeassistant/#", qos=1)
        self.client.loop_start()

    def _message(self, client: Any, userdata: Any, message: Any) -> None:
        self.latest[message.topic] = message.payload
        self.log.append((message.topic, message.payload))

    def until(self, predicate: Any, timeout: float = 30.0) -> Any:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            value = predicate(self)
            if value:
                return value
            time.sleep(0.05)
        raise AssertionError(f"not seen in {timeout} s; topics: {sorted(self.latest)}")

    def json(self, topic: str) -> Any:
        payload = self.latest.get(topic)
        return json.loads(payload) if payload else None

    def device_of_kind(self, kind: str) -> str | None:
        for topic, payload in list(self.latest.items()):
            info = json.loads(payload) if topic.endswith("/info") and payload else {}
            if topic.startswith("fabwire/device/") and info.get("kind") == kind:
                return topic.split("/")[2]
        return None

    def send(self, device: str, body: dict[str, Any]) -> None:
        self.client.publish(f"fabwire/device/{device}/command", json.dumps(body), qos=1).wait_for_publish(10)

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()


def retained(broker: Mosquitto) -> dict[str, bytes]:
    """Every retained message under fabwire/ and homeassistant/, as a newcomer to the broker gets them: the marker
    published after subscribing comes back after all of them."""
    fresh = Watch(broker)
    try:
        fresh.client.publish("fabwire/test/marker", b"end", qos=1).wait_for_publish(10)
        fresh.until(lambda w: "fabwire/test/marker" in w.latest)
        return {t: p for t, p in fresh.latest.items() if p and t != "fabwire/test/marker"}
    finally:
        fresh.close()


def of_demo(topic: str) -> bool:
    """Whether an MQTT topic is one of a demo machine's (its device topics or its Home Assistant discovery)."""
    from fabwire.agent.core import DEMO_IDS

    return any(part in DEMO_IDS or part.removeprefix("fabwire_") in DEMO_IDS for part in topic.split("/"))
