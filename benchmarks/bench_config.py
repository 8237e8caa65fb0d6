"""Loading devices.toml grows linearly with the number of devices (and a status query does not read it at all
when -d is an address)."""

from __future__ import annotations

import tempfile
from pathlib import Path

from common import Figure, cpu_seconds
from fabwire.config import load_devices


def config_text(count: int) -> str:
    return "".join(f'# printer {i}\n[devices.p{i}]\nkind = "xyz"\n'
                   f'url = "10.{i // 65536}.{i // 256 % 256}.{i % 256}"\nlink = "wifi"\n\n' for i in range(count))


def run() -> list[Figure]:
    per_device = {}
    with tempfile.TemporaryDirectory() as tmp:
        for count in (1_000, 10_000):
            path = Path(tmp) / f"devices-{count}.toml"
            path.write_text(config_text(count))
            seconds = min(cpu_seconds(lambda path=path: load_devices(path)) for _ in range(3))
            per_device[count] = seconds / count * 1e6
    growth = per_device[10_000] / per_device[1_000]
    return [
        Figure("load 10,000 devices, per device", per_device[10_000], "µs"),
        Figure("per-device cost, 10,000 vs 1,000 devices", growth, "x", "<= 2 (linear)", growth <= 2),
    ]
