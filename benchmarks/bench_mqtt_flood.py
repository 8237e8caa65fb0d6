"""The agent under a command flood from the broker: `fabwire serve --demo --mqtt URL` as the owner runs it, one
local Mosquitto, and a stranger publishing 20,000 commands at one device as fast as the broker takes them, while
the owner sends one command to another device.

Figures: the agent's peak resident memory before and after the flood (VmHWM from /proc: the flood must not be
kept), and whether the other device's command was answered while the flood was under way.
Run alone: `python benchmarks/bench_mqtt_flood.py`.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests" / "mqtt"))

from common import Figure  # noqa: E402

FLOOD = 20_000
GROWTH_LIMIT_MB = 40.0
"""The agent's memory may grow by a constant under a flood, never by what the flood sends."""


def peak_rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmHWM in /proc")


class Watcher:
    """Device infos and replies as the broker delivers them."""

    def __init__(self, port: int) -> None:
        import paho.mqtt.client as paho

        self.devices: dict[str, dict[str, Any]] = {}
        self.replies: dict[str, list[dict[str, Any]]] = {}
        self.lock = threading.Lock()
        self.client = paho.Client(paho.CallbackAPIVersion.VERSION2)
        self.client.on_message = self._message
        self.client.connect("127.0.0.1", port)
        self.client.subscribe("fabwire/device/+/info", qos=1)
        self.client.subscribe("fabwire/device/+/reply", qos=1)
        self.client.loop_start()

    def _message(self, client: Any, userdata: Any, message: Any) -> None:
        device = message.topic.split("/")[2]
        if not message.payload:
            return
        with self.lock:
            if message.topic.endswith("/info"):
                self.devices[device] = json.loads(message.payload)
            else:
                self.replies.setdefault(device, []).append(json.loads(message.payload))

    def wait(self, predicate: Any, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                if predicate():
                    return True
            time.sleep(0.05)
        return False

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()


def run() -> list[Figure]:
    import paho.mqtt.client as paho
    from mqtttools import Mosquitto

    with tempfile.TemporaryDirectory() as tmp:
        broker = Mosquitto(Path(tmp))
        broker.start()
        env = dict(os.environ, FABWIRE_CONFIG=str(Path(tmp) / "none.toml"))
        agent = subprocess.Popen([sys.executable, "-m", "fabwire", "serve", "--demo", "--listen", "127.0.0.1:0",
                                  "--state-dir", str(Path(tmp) / "state"), "--mqtt", broker.url],
                                 stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env)
        watcher = Watcher(broker.port)
        try:
            if not watcher.wait(lambda: len(watcher.devices) >= 2, 60):
                raise RuntimeError("the agent did not publish its devices")
            time.sleep(2.0)
            flooded, other = sorted(watcher.devices)[:2]
            before = peak_rss_mb(agent.pid)
            stranger = paho.Client(paho.CallbackAPIVersion.VERSION2)
            stranger.connect("127.0.0.1", broker.port)
            stranger.loop_start()
            body = json.dumps({"action": "status", "params": {"pad": "x" * 2000}}).encode()
            for n in range(FLOOD):
                stranger.publish(f"fabwire/device/{flooded}/command", body, qos=0)
                if n == FLOOD // 2:
                    stranger.publish(f"fabwire/device/{other}/command",
                                     json.dumps({"action": "status", "id": "owner"}), qos=1)
            answered = watcher.wait(lambda: any(r.get("id") == "owner" for r in watcher.replies.get(other, [])), 60)
            watcher.wait(lambda: False, 3.0)  # let the agent work through what it kept
            after = peak_rss_mb(agent.pid)
            stranger.loop_stop()
            stranger.disconnect()
        finally:
            watcher.close()
            agent.terminate()
            try:
                agent.wait(20)
            except subprocess.TimeoutExpired:
                agent.kill()
            broker.stop()
    growth = after - before
    return [
        Figure("agent peak RSS before a 20,000-command flood", before, "MB"),
        Figure("agent peak RSS growth through the flood (2 kB commands, 40 MB sent)", growth, "MB",
               f"<= {GROWTH_LIMIT_MB:g}", growth <= GROWTH_LIMIT_MB),
        Figure("another device's command answered during the flood", 1.0 if answered else 0.0, "yes=1", "1",
               answered),
    ]


if __name__ == "__main__":
    for figure in run():
        print(figure)
