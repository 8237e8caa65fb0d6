"""A print farm on one broker: two agent processes, each bridging 500 simulated printers whose state changes at
1 Hz, through one local Mosquitto, while a subscriber watches every state and sends QoS-1 commands.

The printers are simulated at the agent contract (devices / state / subscribe / act), not on the wire, so the
figures are the bridge's and the broker's: CPU per agent process, age of each state when the subscriber gets it
(from the state's own "ts"), the longest a printer's state went unrefreshed, and how often each command ran.
Run alone: `python benchmarks/bench_mqtt_fleet.py`.
"""

from __future__ import annotations

import asyncio
import json
import random
import resource
import subprocess
import sys
import tempfile
import threading
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests" / "mqtt"))

from common import Figure  # noqa: E402

PRINTERS = 500
AGENTS = 2
SECONDS = 9.0
WARMUP = 4.0
COMMANDS = 180  # 20 a second, as before


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


class FarmAgent:
    """500 printers: each one's state changes once a second, on its own phase; `act` counts every run."""

    def __init__(self, name: str, count: int) -> None:
        from fabwire.agent.core import DeviceInfo

        self.state_dir = None
        self.infos = [DeviceInfo(f"xyz-{name}{i:04d}", f"{name} printer {i}", "xyz", "da Vinci 1.0 Pro",
                                 f"{name.upper()}{i:04d}", "1.1.J", f"10.9.{i // 250}.{i % 250}:9100")
                      for i in range(count)]
        self.states: dict[str, dict[str, Any]] = {}
        self.queues: list[asyncio.Queue[dict[str, Any]]] = []
        self.runs: dict[str, int] = {}
        self.generated = 0
        for info in self.infos:
            self._tick(info.id, 0)

    def _tick(self, device: str, n: int) -> dict[str, Any]:
        state = {"ts": _now(), "online": True, "device": device, "kind": "xyz", "name": device,
                 "summary": {"state": "printing", "progress_percent": n % 100, "extruder_temp_c": 210 + n % 3,
                             "bed_temp_c": 60.0},
                 "status": {"state": "printing", "tick": n}, "job": None}
        self.states[device] = state
        return state

    def devices(self) -> list[Any]:
        return list(self.infos)

    def state(self, device_id: str) -> dict[str, Any]:
        return self.states[device_id]

    def subscribe(self, device_id: str | None = None) -> Any:
        queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self.queues.append(queue)
        agent = self

        class Sub:
            def __aiter__(self) -> Any:
                return self

            async def __anext__(self) -> dict[str, Any]:
                return await queue.get()

            def close(self) -> None:
                agent.queues.remove(queue)

        return Sub()

    async def act(self, device_id: str, action: str, params: dict[str, Any]) -> dict[str, Any]:
        key = str(params.get("n"))
        self.runs[key] = self.runs.get(key, 0) + 1
        return {"done": action}

    async def run(self) -> None:
        slots = 20
        per_slot = [self.infos[k::slots] for k in range(slots)]
        n = 0
        start = time.monotonic()
        while True:
            n += 1
            for k, group in enumerate(per_slot):
                await asyncio.sleep(max(0.0, start + n - 1 + k / slots - time.monotonic()))
                self.generated += len(group)
                for info in group:
                    event = {"ts": _now(), "device": info.id, "type": "state", "state": self._tick(info.id, n)}
                    for queue in self.queues:
                        queue.put_nowait(event)


async def agent_main(name: str, url: str) -> None:
    """One agent process: "ready" once bridged; then standard input says "start" and "stop" (the measuring
    window) and "quit" (after the commands were answered), when it prints its figures."""
    from fabwire.mqtt.bridge import run_bridge

    farm = FarmAgent(name, PRINTERS)
    made: asyncio.Future[Any] = asyncio.get_running_loop().create_future()
    bridge_task = asyncio.create_task(run_bridge(farm, url, agent_id=f"farm-{name}", on_bridge=made.set_result))
    ticker = asyncio.create_task(farm.run())
    bridge = await made
    await bridge.connected.wait()
    print("ready", flush=True)

    async def line() -> str:
        return (await asyncio.to_thread(sys.stdin.readline)).strip()

    assert await line() == "start"
    before = resource.getrusage(resource.RUSAGE_SELF)
    began = time.monotonic()
    generated, published = farm.generated, bridge.states_published
    assert await line() == "stop"
    generated, published = farm.generated - generated, bridge.states_published - published
    after = resource.getrusage(resource.RUSAGE_SELF)
    wall = time.monotonic() - began
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    await line()
    ticker.cancel()
    bridge_task.cancel()
    print(json.dumps({"cores": cpu / wall, "runs": farm.runs, "rate": generated / wall,
                      "published": published / max(generated, 1)}), flush=True)


class Subscriber:
    """Ages of states on arrival, the longest gap per printer, and the replies to commands."""

    def __init__(self, port: int) -> None:
        import paho.mqtt.client as paho

        self.ages: list[float] = []
        self.last: dict[str, float] = {}
        self.gaps: list[float] = []
        self.replies: list[dict[str, Any]] = []
        self.measuring = False
        self.lock = threading.Lock()
        self.client = paho.Client(paho.CallbackAPIVersion.VERSION2)
        self.client.max_inflight_messages_set(1000)
        self.client.on_message = self._message
        self.client.connect("127.0.0.1", port)
        self.client.subscribe("fabwire/device/+/state", qos=0)  # a dashboard's view: newest state, no acks
        self.client.subscribe("fabwire/device/+/reply", qos=1)
        self.client.loop_start()

    def _message(self, client: Any, userdata: Any, message: Any) -> None:
        now = time.time()
        if message.topic.endswith("/reply"):
            with self.lock:
                self.replies.append(json.loads(message.payload))
            return
        if not self.measuring or message.retain or not message.payload:
            return
        state = json.loads(message.payload)
        sent = datetime.fromisoformat(state["ts"].replace("Z", "+00:00")).timestamp()
        device = state["device"]
        with self.lock:
            self.ages.append(now - sent)
            if device in self.last:
                self.gaps.append(now - self.last[device])
            self.last[device] = now

    def command(self, device: str, n: int) -> None:
        body = json.dumps({"action": "pause", "params": {"n": n}, "id": f"bench-{n}"})
        self.client.publish(f"fabwire/device/{device}/command", body, qos=1)

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()


def tell(agents: list[subprocess.Popen[str]], word: str) -> None:
    for process in agents:
        assert process.stdin is not None
        process.stdin.write(word + "\n")
        process.stdin.flush()


def _quantile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else float("nan")


def run() -> list[Figure]:
    from mqtttools import Mosquitto

    with tempfile.TemporaryDirectory() as tmp:
        broker = Mosquitto(Path(tmp))
        broker.start()
        agents: list[subprocess.Popen[str]] = []
        try:
            names = [chr(ord("a") + k) for k in range(AGENTS)]
            for name in names:
                agents.append(subprocess.Popen([sys.executable, __file__, "--agent", name, broker.url],
                                               stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True))
            for process in agents:
                assert process.stdout is not None
                assert process.stdout.readline().strip() == "ready"
            watcher = Subscriber(broker.port)
            time.sleep(WARMUP)
            tell(agents, "start")
            watcher.measuring = True
            window = time.monotonic()
            rng = random.Random(7)
            sent = 0
            while time.monotonic() - window < SECONDS:
                if sent < COMMANDS:
                    name = rng.choice(names)
                    watcher.command(f"xyz-{name}{rng.randrange(PRINTERS):04d}", sent)
                    sent += 1
                time.sleep(SECONDS / COMMANDS)
            tell(agents, "stop")
            watcher.measuring = False
            window = time.monotonic() - window
            deadline = time.monotonic() + 60  # every command answered, however loaded the machine
            while len({r["id"] for r in watcher.replies}) < sent and time.monotonic() < deadline:
                time.sleep(0.2)
            tell(agents, "quit")
            results = []
            for process in agents:
                out, _ = process.communicate(timeout=60)
                results.append(json.loads(out.strip().splitlines()[-1]))
            time.sleep(0.5)
            watcher.close()
        finally:
            for process in agents:
                if process.poll() is None:
                    process.kill()
            broker.stop()
    runs: dict[str, int] = {}
    for result in results:
        for key, count in result["runs"].items():
            runs[key] = runs.get(key, 0) + count
    exactly_once = sum(1 for n in range(sent) if runs.get(str(n)) == 1)
    replied = len({r["id"] for r in watcher.replies if r.get("ok")})
    worst_core = max(r["cores"] for r in results)
    max_age = max(watcher.ages)
    max_gap = max(watcher.gaps)
    delivered = len(watcher.ages) / (sum(r["rate"] for r in results) * window)
    rate = sum(r["rate"] for r in results) / (AGENTS * PRINTERS)
    return [
        Figure(f"{AGENTS} agents x {PRINTERS} printers at 1 Hz: busiest agent CPU", worst_core, "cores", "<= 1",
               worst_core <= 1.0),
        Figure("state age at the subscriber, p99", _quantile(watcher.ages, 0.99), "s", "<= 2",
               _quantile(watcher.ages, 0.99) <= 2.0),
        Figure("state age at the subscriber, max", max_age, "s", "<= 2", max_age <= 2.0),
        Figure("state changes generated per printer (1 Hz asked)", rate, "Hz"),
        Figure("state changes the agents published", min(r["published"] for r in results), "share"),
        Figure("longest gap between one printer's updates", max_gap, "s"),
        Figure("state updates delivered (newer ones replace waiting older ones)", delivered, "share", ">= 0.9",
               delivered >= 0.9),
        Figure("QoS-1 commands run exactly once", exactly_once, "cmds", f"= {sent} sent", exactly_once == sent),
        Figure("commands answered", replied, "cmds", f"= {sent} sent", replied == sent),
    ]


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--agent":
        asyncio.run(agent_main(sys.argv[2], sys.argv[3]))
    else:
        for figure in run():
            print(f"{figure.name:55s} {figure.value:12.3f} {figure.unit:6s} {figure.target:16s} {figure.meets_target}")
