"""The MQTT tests' broker: Debian's Mosquitto, started per test on a free loopback port."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from mqtttools import Mosquitto
from servetools import Agents, Watch


@pytest.fixture
def broker(tmp_path: Path) -> Iterator[Mosquitto]:
    server = Mosquitto(tmp_path)
    server.start()
    yield server
    server.stop()


@pytest.fixture
def agents(tmp_path: Path) -> Iterator[Agents]:
    started = Agents(tmp_path)
    yield started
    started.stop_all()


@pytest.fixture
def watch(broker: Mosquitto) -> Iterator[Watch]:
    w = Watch(broker)
    yield w
    w.close()
