"""Home Assistant MQTT discovery: one device discovery message per machine, naming every entity a user expects.

Schema (Home Assistant's MQTT integration, "device discovery payload"): the topic is
`<discovery_prefix>/device/<object_id>/config`; the payload has a `device` mapping (with `identifiers`), an
`origin` mapping (with `name`), shared `availability` / `state_topic` / `command_topic` / `qos`, and a `components`
mapping whose values each name their `platform` and carry a `unique_id`. An empty retained payload removes the
device. Values are read from the state topic with `value_template`; a template rendering `None` shows as unknown.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from fabwire import __version__
from fabwire.mqtt.topics import OFFLINE, ONLINE, agent_topic, device_topic, object_id

MANUFACTURERS = {"xyz": "XYZprinting", "lineus": "Line-us", "mmu": "Prusa Research"}
MODELS = {"xyz": "da Vinci printer", "lineus": "Line-us", "mmu": "MMU3"}
ORIGIN = {"name": "fabwire", "sw_version": __version__}


@dataclass(frozen=True)
class Entity:
    key: str
    """Suffix of the unique id (stable: renaming an entity must not change it)."""
    platform: str
    name: str
    options: tuple[tuple[str, Any], ...] = ()


def _sensor(key: str, name: str, summary_key: str, **options: Any) -> Entity:
    return Entity(key, "sensor", name, (("value_template", f"{{{{ value_json.summary.{summary_key} }}}}"),
                                        *options.items()))


def _button(action: str, name: str, **params: Any) -> Entity:
    payload: dict[str, Any] = {"action": action}
    if params:
        payload["params"] = params
    return Entity(action, "button", name, (("payload_press", json.dumps(payload)),))


TEMPERATURE = {"device_class": "temperature", "unit_of_measurement": "°C", "state_class": "measurement"}
PERCENT = {"unit_of_measurement": "%", "state_class": "measurement"}
STATE = _sensor("state", "State", "state")
ERROR = _sensor("error", "Error", "error")

ENTITIES: dict[str, tuple[Entity, ...]] = {
    "xyz": (
        STATE,
        _sensor("extruder_temperature", "Extruder temperature", "extruder_temp_c", **TEMPERATURE),
        _sensor("bed_temperature", "Bed temperature", "bed_temp_c", **TEMPERATURE),
        _sensor("progress", "Progress", "progress_percent", **PERCENT),
        _sensor("time_left", "Time left", "time_left_s", device_class="duration", unit_of_measurement="s"),
        _sensor("filament_left", "Filament left", "filament_left_mm", device_class="distance",
                unit_of_measurement="mm"),
        ERROR,
        _button("pause", "Pause"),
        _button("resume", "Resume"),
        _button("cancel", "Cancel", confirm=True),
        _button("home", "Home"),
    ),
    "mmu": (
        STATE,
        _sensor("active_slot", "Active slot", "active_slot"),
        _sensor("filament_position", "Filament position", "filament_position"),
        ERROR,
        _button("retry", "Retry"),
        _button("continue", "Continue"),
        _button("stop", "Stop"),
        Entity("tool_change", "select", "Tool change", (
            ("options", [str(slot) for slot in range(5)]),
            ("value_template", "{{ value_json.summary.active_slot }}"),
            ("command_template", '{"action": "tool_change", "params": {"slot": {{ value | int }}}}'),
        )),
    ),
    "lineus": (
        STATE,
        _sensor("progress", "Drawing progress", "progress_percent", **PERCENT),
        ERROR,
        _button("home", "Home"),
    ),
}


TWO_SPOOLS = (
    _sensor("extruder2_temperature", "Extruder 2 temperature", "extruder2_temp_c", **TEMPERATURE),
    _sensor("filament2_left", "Filament 2 left", "filament2_left_mm", device_class="distance",
            unit_of_measurement="mm"),
)
"""What a da Vinci with two spools or extruders (Jr. 2.0 Mix, 2.0 Duo) has besides."""


def _two_spools(kind: str, model: str | None) -> bool:
    if kind != "xyz" or not model:
        return False
    from fabwire.errors import InputError
    from fabwire.xyz.models import find_model

    try:
        return find_model(model).dual_extruder
    except InputError:
        return False


def discovery_payload(info: dict[str, Any], agent: str) -> dict[str, Any]:
    """The device discovery payload for a device (`DeviceInfo` as a dict) published by `agent`.

    Availability needs both the agent (its last will) and the device's own link to be online."""
    device_id: str = info["id"]
    kind: str = info["kind"]
    base = object_id(device_id)
    device: dict[str, Any] = {"identifiers": [base], "name": info.get("name") or device_id,
                              "manufacturer": MANUFACTURERS.get(kind, kind),
                              "model": info.get("model") or MODELS.get(kind, kind)}
    if info.get("serial"):
        device["serial_number"] = info["serial"]
    if info.get("firmware"):
        device["sw_version"] = info["firmware"]
    components: dict[str, dict[str, Any]] = {}
    extra = TWO_SPOOLS if _two_spools(kind, info.get("model")) else ()
    for entity in (*ENTITIES.get(kind, (STATE,)), *extra):
        unique = f"{base}_{entity.key}"
        components[unique] = {"platform": entity.platform, "name": entity.name, "unique_id": unique,
                              **dict(entity.options)}
    return {
        "device": device,
        "origin": ORIGIN,
        "availability": [
            {"topic": agent_topic(agent, "status"), "payload_available": ONLINE, "payload_not_available": OFFLINE},
            {"topic": device_topic(device_id, "availability"), "payload_available": ONLINE,
             "payload_not_available": OFFLINE},
        ],
        "availability_mode": "all",
        "state_topic": device_topic(device_id, "state"),
        "command_topic": device_topic(device_id, "command"),
        "qos": 1,
        "components": components,
    }
