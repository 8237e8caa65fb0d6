"""MQTT test helpers: a real Mosquitto broker on a free loopback port (restartable on the same port), an observer
client that keeps what the broker delivers, and a small stand-in for the agent's contract."""

from __future__ import annotations

import asyncio
import contextlib
import shutil
import socket
import subprocess
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import aiomqtt
import pytest

from fabwire.agent.core import DeviceInfo, now_iso
from fabwire.errors import InputError


def mosquitto_program() -> str:
    found = shutil.which("mosquitto") or next((p for p in ("/usr/sbin/mosquitto", "/usr/bin/mosquitto")
                                                if Path(p).exists()), None)
    if found is None:
        pytest.fail("the MQTT tests need Debian's mosquitto: run scripts/ensure-system-packages "
                    "(or apt-get install mosquitto)")
    return found


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Mosquitto:
    """`mosquitto -c CONF` listening on 127.0.0.1:port only, nothing kept on disk."""

    directory: Path
    port: int = field(default_factory=free_port)
    anonymous: bool = True
    process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    def start(self) -> None:
        conf = self.directory / "mosquitto.conf"
        conf.write_text(f"listener {self.port} 127.0.0.1\nallow_anonymous {str(self.anonymous).lower()}\n"
                        "persistence false\nlog_dest none\nmax_queued_messages 100000\n")
        self.process = subprocess.Popen([mosquitto_program(), "-c", str(conf)], stdout=subprocess.DEVNULL,
                                        stderr=subprocess.PIPE)
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                why = self.process.stderr.read().decode() if self.process.stderr else ""
                raise RuntimeError(f"mosquitto exited: {why}")
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", self.port), timeout=0.5):
                return
            time.sleep(0.05)
        raise RuntimeError("mosquitto did not start listening")

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.process is not None and self.process.stderr is not None:
            self.process.stderr.close()
        self.process = None


class Observer:
    """A client that subscribes to everything and keeps each topic's latest payload and every delivery."""

    def __init__(self, client: aiomqtt.Client) -> None:
        self.client = client
        self.latest: dict[str, bytes] = {}
        self.log: list[tuple[str, bytes, bool]] = []
        self._changed = asyncio.Condition()

    async def run(self) -> None:
        async for message in self.client.messages:
            payload = message.payload if isinstance(message.payload, bytes) else b""
            async with self._changed:
                self.latest[message.topic.value] = payload
                self.log.append((message.topic.value, payload, message.retain))
                self._changed.notify_all()

    async def wait_for(self, predicate: Any, timeout: float = 30.0) -> Any:
        """Wait until `predicate(self)` is truthy (re-checked on each message); returns its value."""
        async with asyncio.timeout(timeout), self._changed:
            while not (value := predicate(self)):
                await self._changed.wait()
            return value

    def json(self, topic: str) -> Any:
        import json

        payload = self.latest.get(topic)
        return json.loads(payload) if payload else None

    def count(self, topic: str) -> int:
        return sum(1 for t, _, _ in self.log if t == topic)


@contextlib.asynccontextmanager
async def observing(broker: Mosquitto, *topics: str) -> AsyncIterator[Observer]:
    async with aiomqtt.Client("127.0.0.1", broker.port, protocol=aiomqtt.ProtocolVersion.V5) as client:
        for topic in topics or ("#",):
            await client.subscribe(topic, qos=1)
        observer = Observer(client)
        task = asyncio.create_task(observer.run())
        try:
            yield observer
        finally:
            task.cancel()
            with contextlib.suppress(BaseException):
                await task


class FakeSubscription:
    def __init__(self, agent: FakeAgent) -> None:
        self.queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self.agent = agent
        agent.subscriptions.append(self)

    def __aiter__(self) -> FakeSubscription:
        return self

    async def __anext__(self) -> dict[str, Any]:
        return await self.queue.get()

    def close(self) -> None:
        if self in self.agent.subscriptions:
            self.agent.subscriptions.remove(self)


class FakeAgent:
    """The agent contract (devices, state, subscribe, act) over in-memory devices; `act` records each call."""

    def __init__(self, devices: list[DeviceInfo], state_dir: Path | None = None) -> None:
        self.state_dir = state_dir
        self.infos = {d.id: d for d in devices}
        self.states: dict[str, dict[str, Any]] = {d.id: self.make_state(d, "idle") for d in devices}
        self.subscriptions: list[FakeSubscription] = []
        self.calls: list[tuple[str, str, dict[str, Any]]] = []

    @staticmethod
    def make_state(info: DeviceInfo, state: str, **summary: Any) -> dict[str, Any]:
        return {"ts": now_iso(), "online": True, "device": info.id, "kind": info.kind,
                "name": info.name, "summary": {"state": state, **summary}, "status": {"state": state}, "job": None}

    def devices(self) -> list[DeviceInfo]:
        return list(self.infos.values())

    def state(self, device_id: str) -> dict[str, Any]:
        return self.states[device_id]

    def subscribe(self, device_id: str | None = None) -> FakeSubscription:
        return FakeSubscription(self)

    async def act(self, device_id: str, action: str, params: dict[str, Any]) -> dict[str, Any]:
        if device_id not in self.infos:
            raise InputError(f"no device {device_id!r}")
        if action == "explode":
            raise InputError("a printer has no action 'explode'")
        self.calls.append((device_id, action, params))
        return {"done": action}

    def emit(self, event: dict[str, Any]) -> None:
        for sub in list(self.subscriptions):
            sub.queue.put_nowait(event)

    def set_state(self, device_id: str, state: str, **summary: Any) -> None:
        self.states[device_id] = self.make_state(self.infos[device_id], state, **summary)
        self.emit({"ts": now_iso(), "device": device_id, "type": "state", "state": self.states[device_id]})


def printer(serial: str = "3DP01P", name: str = "office") -> DeviceInfo:
    return DeviceInfo(f"xyz-{serial.lower()}", name, "xyz", "da Vinci 1.0 Pro", serial, "1.1.J", "10.0.0.5:9100")


def mmu(serial: str = "MMU-7") -> DeviceInfo:
    return DeviceInfo(f"mmu-{serial.lower()}", "mmu", "mmu", "MMU3", serial, "3.0.4", "/dev/ttyACM0")


def lineus(serial: str = "123456") -> DeviceInfo:
    return DeviceInfo(f"lineus-{serial}", "arm", "lineus", "Line-us", serial, "3.2.0", "10.0.0.7:1337")
