"""Home Assistant's MQTT discovery rules (the table in data/ha_discovery_rules.json, each entry naming its source
in home-assistant/core) as a checker, and its templates rendered the way Home Assistant renders them (Jinja2 in a
sandbox, with the `as_datetime` and `timedelta` globals Home Assistant adds)."""

from __future__ import annotations

import json
import re
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from jinja2.sandbox import ImmutableSandboxedEnvironment

RULES: dict[str, Any] = json.loads((Path(__file__).parent / "data" / "ha_discovery_rules.json").read_text("utf-8"))
PLATFORMS: dict[str, Any] = RULES["platforms"]


def _check_topic(where: str, value: Any, *, publish: bool) -> list[str]:
    if not isinstance(value, str) or not value or "\0" in value or len(value.encode()) > RULES["topics"]["max_bytes"]:
        return [f"{where}: not a valid MQTT topic ({value!r})"]
    if publish and ("+" in value or "#" in value):
        return [f"{where}: a publish topic cannot hold wildcards"]
    return []


def _check_keys(where: str, given: dict[str, Any], required: list[str], allowed: list[str]) -> list[str]:
    problems = [f"{where}: {key} is required" for key in required if key not in given]
    problems += [f"{where}: {key} is not an option Home Assistant knows" for key in given if key not in allowed]
    return problems


def check_component(key: str, component: dict[str, Any], shared: dict[str, Any]) -> list[str]:
    """One component of a device discovery payload (or one per-entity payload, with `shared` empty)."""
    platform = component.get("platform")
    if platform not in PLATFORMS:
        return [f"{key}: platform {platform!r} is not one this checker has rules for"]
    rules = PLATFORMS[platform]
    # Home Assistant copies the shared options into every component and then drops the ones a platform does not
    # take: inherited keys count for what is required, a component's own keys must each be known.
    merged = {**{k: v for k, v in shared.items() if k in RULES["shared_options"]["keys"]}, **component}
    allowed = RULES["entity_common"]["allowed"] + rules["allowed"]
    problems = _check_keys(key, merged, RULES["entity_common"]["required"] + rules["required"], list(merged))
    problems += _check_keys(key, component, [], allowed)
    if not isinstance(component.get("unique_id"), str) or not component["unique_id"]:
        problems.append(f"{key}: unique_id is required for a discovered entity to be editable")
    category = component.get("entity_category")
    if category is not None and category not in rules["categories"]:
        problems.append(f"{key}: entity_category {category!r} is not allowed for a {platform}")
    device_class = component.get("device_class")
    if device_class is not None and device_class not in RULES["device_classes"].get(platform, []):
        problems.append(f"{key}: {platform} device_class {device_class!r} does not exist")
    if platform == "sensor":
        unit, state_class = component.get("unit_of_measurement"), component.get("state_class")
        if device_class in RULES["non_numeric"]["device_classes"] and (unit or state_class):
            problems.append(f"{key}: a {device_class} sensor takes no unit or state_class")
        if device_class in RULES["sensor_units"] and unit not in RULES["sensor_units"][device_class]:
            problems.append(f"{key}: {unit!r} is not a unit of {device_class}")
        if state_class is not None and state_class not in RULES["state_classes"]["values"]:
            problems.append(f"{key}: state_class {state_class!r} does not exist")
    if platform == "select" and (not isinstance(component.get("options"), list) or not component["options"]
                                 or not all(isinstance(o, str) for o in component["options"])):
        problems.append(f"{key}: select options must be a non-empty list of strings")
    if platform == "event" and (not isinstance(component.get("event_types"), list) or not component["event_types"]):
        problems.append(f"{key}: event_types must be a non-empty list")
    if platform == "text":
        low, high = component.get("min", 0), component.get("max", rules["max_length"])
        if not (0 <= low < high <= rules["max_length"]):
            problems.append(f"{key}: text length needs 0 <= min < max <= {rules['max_length']}")
    for name in ("state_topic", "json_attributes_topic"):
        if name in merged:
            problems += _check_topic(f"{key}.{name}", merged[name], publish=False)
    if "command_topic" in merged:
        problems += _check_topic(f"{key}.command_topic", merged["command_topic"], publish=True)
    for name in rules["templates"]:
        if name in component:
            try:
                ENVIRONMENT.from_string(component[name])
            except Exception as exc:
                problems.append(f"{key}.{name}: not a template: {exc}")
    return problems


def _check_shared(payload: dict[str, Any]) -> list[str]:
    """The device block, origin and availability: the same rules in device and per-entity messages."""
    problems: list[str] = []
    device = payload.get("device")
    if isinstance(device, dict):
        device_rules = RULES["device"]
        problems += _check_keys("device", device, [], device_rules["allowed"])
        if not any(device.get(k) for k in device_rules["required_one_of"]):
            problems.append("device: identifiers or connections are required")
        problems += [f"device.{k}: must be text" for k in device_rules["strings"]
                     if k in device and not isinstance(device[k], str)]
        if "configuration_url" in device:
            url = urlsplit(str(device["configuration_url"]))
            if url.scheme not in device_rules["url_schemes"]["schemes"] or not (url.netloc or url.scheme ==
                                                                                "homeassistant"):
                problems.append(f"device.configuration_url: {device['configuration_url']!r} is not a URL")
    else:
        problems.append("device: must be a mapping")
    origin = payload.get("origin")
    if isinstance(origin, dict):
        problems += _check_keys("origin", origin, RULES["origin"]["required"], RULES["origin"]["allowed"])
    else:
        problems.append("origin: must be a mapping")
    availability = RULES["availability"]
    if "availability" in payload and "availability_topic" in payload:
        problems.append("availability and availability_topic are exclusive")
    for i, entry in enumerate(payload.get("availability") or []):
        problems += _check_keys(f"availability[{i}]", entry, availability["entry_required"],
                                availability["entry_allowed"])
        problems += _check_topic(f"availability[{i}].topic", entry.get("topic"), publish=False)
    if payload.get("availability_mode", "latest") not in availability["modes"]:
        problems.append("availability_mode must be all, any or latest")
    if payload.get("qos", 0) not in (0, 1, 2):
        problems.append("qos must be 0, 1 or 2")
    return problems


def check_entity_discovery(topic: str, payload: dict[str, Any]) -> list[str]:
    """Every rule of the table for one per-entity discovery message (the platform is the topic's)."""
    match = re.match(RULES["discovery_topic"]["pattern"], topic)
    if not match:
        return [f"{topic}: not a discovery topic Home Assistant reads"]
    platform = match.group("component")
    problems = check_component(topic, {**payload, "platform": platform}, {})
    if "platform" in payload:
        problems.append(f"{topic}: the platform is the topic's, not a key")
    if "device" not in payload or "origin" not in payload:
        problems.append(f"{topic}: device and origin are needed to group the entity under its machine")
    return problems + _check_shared(payload)


def check_device_discovery(topic: str, payload: dict[str, Any]) -> list[str]:
    """Every rule of the table for one device discovery message; returns what breaks them."""
    problems = []
    if not re.match(RULES["discovery_topic"]["pattern"], topic):
        problems.append(f"{topic}: not a discovery topic Home Assistant reads")
    rules = RULES["device_discovery"]
    problems += _check_keys("payload", payload, rules["required"], rules["allowed"])
    problems += _check_shared(payload)
    components = payload.get("components")
    if not isinstance(components, dict) or not components:
        return [*problems, "components: must be a non-empty mapping"]
    unique_ids = [c.get("unique_id") for c in components.values()]
    if len(unique_ids) != len(set(unique_ids)):
        problems.append("components: unique_id repeated")
    for key, component in components.items():
        problems += check_component(key, component, payload)
    return problems


def _as_datetime(value: Any) -> datetime | None:
    try:
        return datetime.fromisoformat(str(value))
    except ValueError:
        return None


ENVIRONMENT = ImmutableSandboxedEnvironment()
ENVIRONMENT.globals.update(as_datetime=_as_datetime, timedelta=timedelta)


def render_value(template: str, payload: dict[str, Any]) -> str:
    """A value_template on a JSON payload, as Home Assistant renders it (`value` and `value_json`)."""
    return ENVIRONMENT.from_string(template).render(value=json.dumps(payload), value_json=payload).strip()


def render_command(template: str, value: Any) -> str:
    return ENVIRONMENT.from_string(template).render(value=value).strip()
