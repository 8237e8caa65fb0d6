"""Discovery payloads against Home Assistant's documented device-discovery schema, the broker address, command
parsing and the ownership rule."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parent))
from mqtttools import lineus, mmu, printer

from fabwire.errors import InputError
from fabwire.mqtt.commands import parse_command
from fabwire.mqtt.discovery import discovery_payload
from fabwire.mqtt.fleet_view import FleetView
from fabwire.mqtt.topics import agent_topic, claim_topic, discovery_topic, parse_broker

PLATFORM_NEEDS = {
    # What each platform needs beyond `platform` and `unique_id` (Home Assistant's MQTT platform options).
    "sensor": {"value_template"},
    "button": {"payload_press"},
    "select": {"options", "command_template", "value_template"},
}


def check_device_discovery(payload: dict[str, Any]) -> list[str]:
    """The documented rules of a device discovery payload; returns what breaks them."""
    problems = []
    device = payload.get("device")
    if not isinstance(device, dict) or not device.get("identifiers"):
        problems.append("device mapping with identifiers is required")
    origin = payload.get("origin")
    if not isinstance(origin, dict) or not origin.get("name"):
        problems.append("origin mapping with a name is required")
    components = payload.get("components")
    if not isinstance(components, dict) or not components:
        problems.append("components mapping is required")
        return problems
    for key, component in components.items():
        platform = component.get("platform")
        if platform not in PLATFORM_NEEDS:
            problems.append(f"{key}: unknown platform {platform!r}")
            continue
        if not component.get("unique_id"):
            problems.append(f"{key}: unique_id is required")
        missing = PLATFORM_NEEDS[platform] - set(component)
        if missing:
            problems.append(f"{key}: {platform} lacks {sorted(missing)}")
        if platform == "sensor" and not payload.get("state_topic") and not component.get("state_topic"):
            problems.append(f"{key}: a sensor needs a state topic")
        if platform in ("button", "select") and not payload.get("command_topic"):
            problems.append(f"{key}: {platform} needs a command topic")
    for entry in payload.get("availability", []):
        if not entry.get("topic"):
            problems.append("availability entries need a topic")
    if payload.get("availability_mode") not in (None, "all", "any", "latest"):
        problems.append("availability_mode must be all, any or latest")
    return problems


DEVICES = [printer(), printer("3DP02P", "garage"), mmu(), lineus()]


def test_every_kind_passes_the_schema_with_unique_ids_and_its_device_block() -> None:
    unique_ids: list[str] = []
    identifiers: set[str] = set()
    for info in DEVICES:
        payload = discovery_payload(info.to_dict(), "bench-a")
        assert check_device_discovery(payload) == [], info.kind
        json.dumps(payload)  # plain JSON
        unique_ids += [c["unique_id"] for c in payload["components"].values()]
        device = payload["device"]
        assert device["serial_number"] == info.serial
        assert device["sw_version"] == info.firmware
        assert device["model"] == info.model
        assert device["manufacturer"]
        identifiers.add(device["identifiers"][0])
        assert payload["origin"]["name"] == "fabwire"
        assert [a["topic"] for a in payload["availability"]] == [
            agent_topic("bench-a", "status"), f"fabwire/device/{info.id}/availability"]
        assert discovery_topic(info.id).startswith("homeassistant/device/")
    assert len(unique_ids) == len(set(unique_ids))
    assert len(identifiers) == len(DEVICES)


@pytest.mark.parametrize(("info", "expected"), [
    (printer(), {"Extruder temperature", "Bed temperature", "Progress", "Time left", "State", "Filament left",
                 "Error", "Pause", "Resume", "Cancel", "Home"}),
    (mmu(), {"Active slot", "Filament position", "Error", "Retry", "Continue", "Stop", "Tool change", "State"}),
    (lineus(), {"State", "Drawing progress", "Error", "Home"}),
])
def test_each_kind_has_the_entities_a_user_expects(info: Any, expected: set[str]) -> None:
    components = discovery_payload(info.to_dict(), "a")["components"].values()
    assert {c["name"] for c in components} == expected


def test_buttons_send_commands_the_bridge_understands() -> None:
    components = discovery_payload(printer().to_dict(), "a")["components"].values()
    presses = {c["name"]: parse_command(c["payload_press"].encode()) for c in components if c["platform"] == "button"}
    assert presses["Pause"].action == "pause"
    assert presses["Cancel"].params == {"confirm": True}  # cancel is destructive: the agent wants confirmation
    select = next(c for c in discovery_payload(mmu().to_dict(), "a")["components"].values()
                  if c["platform"] == "select")
    rendered = select["command_template"].replace("{{ value | int }}", "3")
    assert parse_command(rendered.encode()).params == {"slot": 3}


def test_the_schema_check_catches_broken_payloads() -> None:
    payload = discovery_payload(printer().to_dict(), "a")
    broken = {**payload, "origin": {}, "components": {"x": {"platform": "sensor"}}}
    assert len(check_device_discovery(broken)) == 3


@pytest.mark.parametrize(("url", "host", "port", "tls"), [
    ("mqtt://broker.lan", "broker.lan", 1883, False),
    ("mqtts://broker.lan", "broker.lan", 8883, True),
    ("broker.lan:1884", "broker.lan", 1884, False),
    ("mqtt://[::1]:1999", "::1", 1999, False),
])
def test_broker_urls(url: str, host: str, port: int, tls: bool) -> None:
    broker = parse_broker(url)
    assert (broker.host, broker.port, broker.tls) == (host, port, tls)


def test_broker_credentials_from_url_or_options() -> None:
    assert parse_broker("mqtt://u%40x:p%3A@h").username == "u@x"
    assert parse_broker("mqtt://u:p@h").password == "p"
    assert parse_broker("mqtt://u:p@h", username="v").username == "v"


@pytest.mark.parametrize("url", ["http://h", "mqtt://", "mqtt://h:99999", "mqtt://h/path", "mqtt://h?x=1"])
def test_bad_broker_urls(url: str) -> None:
    with pytest.raises(InputError):
        parse_broker(url)


@pytest.mark.parametrize(("payload", "error"), [
    (b"", "empty"), (b"\xff\xfe", "UTF-8"), (b"[1]", "action name"), (b'["a"]', "action name"),
    (b'{"params": {}}', '"action"'),
    (b'{"action": "x", "params": 3}', '"params"'), (b"two words", "action name"), (b"{bad", "valid JSON"),
])
def test_bad_commands_say_what_is_wrong(payload: bytes, error: str) -> None:
    with pytest.raises(InputError, match=error):
        parse_command(payload)


@given(st.binary(max_size=200))
def test_any_bytes_parse_or_fail_as_input_errors(payload: bytes) -> None:
    try:
        command = parse_command(payload)
    except InputError:
        return
    assert command.action


agents = st.sampled_from(["a", "b", "c", "d"])


@given(st.sets(agents), st.dictionaries(agents, st.sampled_from(["online", "offline"])), agents)
def test_every_agent_computes_the_same_owner(claims: set[str], statuses: dict[str, str], me: str) -> None:
    view = FleetView()
    for agent, status in statuses.items():
        view.take(agent_topic(agent, "status"), status.encode())
    for agent in claims:
        view.take(claim_topic("xyz-1", agent), b"1")
    owner = view.owner("xyz-1")
    live = sorted(a for a in claims if statuses.get(a) == "online")
    assert owner == (live[0] if live else None)
    if me in claims and statuses.get(me) == "online":
        assert view.owner("xyz-1", me=me) == owner  # an agent's own view agrees with everyone else's


def test_fleet_view_ignores_garbage_and_releases_claims() -> None:
    view = FleetView()
    assert view.take("fabwire/device/xyz-1/state", b"not json") == "xyz-1"
    assert view.take("elsewhere/topic", b"1") is None
    view.take(agent_topic("a", "status"), b"maybe")
    assert "a" not in view.agents
    view.take(claim_topic("xyz-2", "a"), b"1")
    view.take(claim_topic("xyz-2", "a"), b"")
    assert "xyz-2" not in view.devices
