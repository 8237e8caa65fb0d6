"""Home Assistant MQTT discovery: one device discovery message per machine, naming every entity a user expects.

Schema (Home Assistant's MQTT integration, "device discovery payload"): the topic is
`<discovery_prefix>/device/<object_id>/config`; the payload has a `device` mapping (with `identifiers`), an
`origin` mapping (with `name`), shared `availability` / `state_topic` / `command_topic` / `qos`, and a `components`
mapping whose values each name their `platform` and carry a `unique_id`. An empty retained payload removes the
device. Values are read from the state topic with `value_template`; a template rendering `None` shows as unknown.
`event` entities read the event topic instead (Home Assistant ignores retained events). Needs Home Assistant
2024.11 or newer (`MINIMUM_HOME_ASSISTANT`); `discovery_messages(..., mode="entity")` is the per-entity form
(`<prefix>/<platform>/<node_id>/<object_id>/config`) for older versions.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from fabwire import __version__
from fabwire.mqtt.topics import DISCOVERY_PREFIX, OFFLINE, ONLINE, agent_topic, device_topic, discovery_topic, object_id

MANUFACTURERS = {"xyz": "XYZprinting", "lineus": "Line-us", "mmu": "Prusa Research"}
MODELS = {"xyz": "da Vinci printer", "lineus": "Line-us", "mmu": "MMU3"}
ORIGIN = {"name": "fabwire", "sw_version": __version__}


MINIMUM_HOME_ASSISTANT = "2024.11"
"""Device discovery (one message per machine with a `components` mapping) arrived in Home Assistant 2024.11; the
`event` platform in 2023.8 and `text` in 2022.12. Older versions ignore the message: `discovery_messages` in
`entity` mode gives them one message per entity instead."""


@dataclass(frozen=True)
class Entity:
    key: str
    """Suffix of the unique id (stable: renaming an entity must not change it)."""
    platform: str
    name: str
    options: tuple[tuple[str, Any], ...] = ()


def _sensor(key: str, name: str, template: str, **options: Any) -> Entity:
    """A sensor read from the state topic; `template` is a Jinja expression over `value_json` (the agent's state),
    or a dotted summary key."""
    expression = template if " " in template or "(" in template else f"value_json.summary.{template}"
    return Entity(key, "sensor", name, (("value_template", f"{{{{ {expression} }}}}"), *options.items()))


def _binary(key: str, name: str, condition: str, device_class: str) -> Entity:
    return Entity(key, "binary_sensor", name, (
        ("value_template", f"{{{{ 'ON' if {condition} else 'OFF' }}}}"), ("device_class", device_class)))


def _button(action: str, name: str, key: str | None = None, **params: Any) -> Entity:
    payload: dict[str, Any] = {"action": action}
    if params:
        payload["params"] = params
    return Entity(key or action, "button", name, (("payload_press", json.dumps(payload)),))


def _job_event(name: str, what: str) -> Entity:
    """An `event` entity on the event topic: the agent's job record reaching its end becomes `finished`,
    `failed` or `cancelled`, with the file name and the closing words as attributes."""
    ending = "{'done': 'finished', 'failed': 'failed', 'cancelled': 'cancelled'}"
    template = ("{% set job = value_json.job if value_json.type == 'job' else none %}"
                f"{{% if job and job.state in {ending} %}}"
                f"{{{{ {{'event_type': {ending}[job.state], 'file': job.filename | default(none), "
                "'message': job.message | default(none)} "
                "| tojson }}{% endif %}")
    return Entity(what, "event", name, (("event_types", ["finished", "failed", "cancelled"]),
                                        ("value_template", template), ("state_topic", EVENT_TOPIC)))


EVENT_TOPIC = "{event_topic}"
"""Placeholder for the device's event topic in entity options (filled in per device)."""
DIAGNOSTIC = {"entity_category": "diagnostic"}
TEMPERATURE = {"device_class": "temperature", "unit_of_measurement": "°C", "state_class": "measurement"}
TARGET = {"device_class": "temperature", "unit_of_measurement": "°C"}
PERCENT = {"unit_of_measurement": "%", "state_class": "measurement"}
DURATION = {"device_class": "duration", "unit_of_measurement": "s"}
STATE = _sensor("state", "State", "state")
ERROR = _sensor("error", "Error", "error")
PROBLEM = _binary("problem", "Problem", "value_json.summary.state == 'error'", "problem")
SLOTS = range(5)
ESTIMATED_FINISH = ("(as_datetime(value_json.ts) + timedelta(seconds=value_json.summary.time_left_s)).isoformat() "
                    "if value_json.summary.time_left_s is number else none")

ENTITIES: dict[str, tuple[Entity, ...]] = {
    "xyz": (
        STATE,
        _binary("printing", "Printing", "value_json.summary.state in ('printing', 'paused')", "running"),
        PROBLEM,
        _sensor("extruder_temperature", "Extruder temperature", "extruder_temp_c", **TEMPERATURE),
        _sensor("extruder_target", "Extruder target", "extruder_target_c", **TARGET),
        _sensor("bed_temperature", "Bed temperature", "bed_temp_c", **TEMPERATURE),
        _sensor("bed_target", "Bed target", "bed_target_c", **TARGET),
        _sensor("progress", "Progress", "progress_percent", **PERCENT),
        _sensor("job_file", "Job file", "value_json.job.filename if value_json.job else none"),
        _sensor("elapsed", "Print time", "elapsed_s", **DURATION),
        _sensor("time_left", "Time left", "time_left_s", **DURATION),
        _sensor("estimated_finish", "Estimated finish", ESTIMATED_FINISH, device_class="timestamp"),
        _sensor("filament_left", "Filament left", "filament_left_mm", device_class="distance",
                unit_of_measurement="mm"),
        ERROR,
        _job_event("Print", "print"),
        _button("pause", "Pause"),
        _button("resume", "Resume"),
        _button("cancel", "Cancel", confirm=True),
        _button("acknowledge", "Print removed"),
        _button("home", "Home"),
        _sensor("firmware", "Firmware", "value_json.status.firmware if value_json.status else none", **DIAGNOSTIC),
        _sensor("wifi_signal", "Wi-Fi signal",
                "value_json.status.network.rssi_dbm if value_json.status and value_json.status.network else none",
                device_class="signal_strength", unit_of_measurement="dBm", state_class="measurement", **DIAGNOSTIC),
        _sensor("wifi_network", "Wi-Fi network",
                "value_json.status.network.ssid if value_json.status and value_json.status.network else none",
                **DIAGNOSTIC),
        _sensor("ip_address", "IP address",
                "value_json.status.network.ip if value_json.status and value_json.status.network else none",
                **DIAGNOSTIC),
    ),
    "mmu": (
        STATE,
        _sensor("active_slot", "Active slot", "active_slot"),
        _sensor("filament_position", "Filament position", "filament_position"),
        ERROR,
        PROBLEM,
        Entity("mmu_error", "event", "MMU error", (
            ("event_types", ["error"]),
            ("value_template", "{% if value_json.type == 'event' and value_json.event.event == 'error' %}"
                               "{{ {'event_type': 'error', 'error': value_json.event.error | default(none), "
                               "'command': value_json.event.command | default(none), "
                               "'auto_retry': value_json.event.auto_retry | default(false)} | tojson }}{% endif %}"),
            ("state_topic", EVENT_TOPIC),
        )),
        _button("retry", "Retry"),
        _button("continue", "Continue"),
        _button("stop", "Stop"),
        Entity("tool_change", "select", "Tool change", (
            ("options", [str(slot) for slot in SLOTS]),
            ("value_template", "{{ value_json.summary.active_slot }}"),
            ("command_template", '{"action": "tool_change", "params": {"slot": {{ value | int }}}}'),
        )),
        *(_button("load", f"Load slot {slot}", f"load_{slot}", slot=slot) for slot in SLOTS),
        _button("unload", "Unload"),
        *(_button("eject", f"Eject slot {slot}", f"eject_{slot}", slot=slot) for slot in SLOTS),
    ),
    "lineus": (
        STATE,
        _sensor("progress", "Drawing progress", "progress_percent", **PERCENT),
        ERROR,
        PROBLEM,
        _job_event("Drawing", "drawing"),
        Entity("text", "text", "Write text", (
            ("command_template", '{"action": "text", "params": {"text": {{ value | tojson }}}}'),
            ("value_template", "{{ value_json.job.params.text[:255] if value_json.job and value_json.job.params "
                               "and value_json.job.params.text else '' }}"),
            ("max", 255),
        )),
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


def discovery_payload(info: dict[str, Any], agent: str, dashboard_url: str | None = None) -> dict[str, Any]:
    """The device discovery payload for a device (`DeviceInfo` as a dict) published by `agent`; `dashboard_url`
    becomes the device's `configuration_url` (Home Assistant's "Visit" link).

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
    if dashboard_url:
        device["configuration_url"] = dashboard_url
    events = device_topic(device_id, "event")
    components: dict[str, dict[str, Any]] = {}
    extra = TWO_SPOOLS if _two_spools(kind, info.get("model")) else ()
    for entity in (*ENTITIES.get(kind, (STATE,)), *extra):
        unique = f"{base}_{entity.key}"
        options = {key: events if value == EVENT_TOPIC else value for key, value in entity.options}
        components[unique] = {"platform": entity.platform, "name": entity.name, "unique_id": unique, **options}
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


DISCOVERY_MODES = ("device", "entity")
"""`device`: one message per machine (Home Assistant 2024.11+); `entity`: one per entity, for older versions."""
PLATFORM_TOPICS = {"sensor": ("state_topic",), "binary_sensor": ("state_topic",), "event": ("state_topic",),
                   "button": ("command_topic",), "select": ("state_topic", "command_topic"),
                   "text": ("state_topic", "command_topic")}
"""The device-level topics each platform takes (a per-entity message carries only those)."""
_SHARED = ("device", "origin", "availability", "availability_mode", "qos")


def entity_topic(device_id: str, platform: str, key: str) -> str:
    """`homeassistant/<platform>/<node_id>/<object_id>/config`, the per-entity discovery topic."""
    return f"{DISCOVERY_PREFIX}/{platform}/{object_id(device_id)}/{key}/config"


def discovery_messages(info: dict[str, Any], agent: str, dashboard_url: str | None = None,
                       mode: str = "device") -> list[tuple[str, dict[str, Any]]]:
    """(topic, payload) for every discovery message of a device: the device message, or in `entity` mode one
    message per entity with the device block, origin, availability and its own topics in it."""
    payload = discovery_payload(info, agent, dashboard_url)
    if mode == "device":
        return [(discovery_topic(info["id"]), payload)]
    shared = {key: payload[key] for key in _SHARED if key in payload}
    base = object_id(info["id"])
    out = []
    for component in payload["components"].values():
        platform = component["platform"]
        topics = {key: payload[key] for key in PLATFORM_TOPICS[platform] if key in payload}
        body = {**shared, **topics, **{k: v for k, v in component.items() if k != "platform"}}
        out.append((entity_topic(info["id"], platform, component["unique_id"].removeprefix(f"{base}_")), body))
    return out


def discovery_topics(device_id: str, mode: str = "device") -> list[str]:
    """Every discovery topic a device may have been published on (emptied when it is removed); the kind is the
    id's first word (`fabwire.agent.core.device_id`)."""
    if mode == "device":
        return [discovery_topic(device_id)]
    kind = device_id.split("-", 1)[0]
    info = {"id": device_id, "kind": kind, "name": device_id}
    return [topic for topic, _ in discovery_messages(info, "", None, mode)]
