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
from hatools import check_device_discovery, check_entity_discovery, render_command, render_value
from mqtttools import lineus, mmu, printer

from fabwire.agent.drivers.base import summary
from fabwire.errors import InputError
from fabwire.mqtt.commands import parse_command
from fabwire.mqtt.discovery import discovery_messages, discovery_payload, discovery_topics
from fabwire.mqtt.fleet_view import FleetView
from fabwire.mqtt.topics import agent_topic, claim_topic, discovery_topic, parse_broker

DEVICES = [printer(), printer("3DP02P", "garage"), mmu(), lineus()]
DASHBOARD = "http://raspberrypi.local:8765/"


def payloads() -> list[tuple[str, dict[str, Any]]]:
    """Every discovery message the bridge publishes for these devices, as topic and payload."""
    return [(discovery_topic(info.id), discovery_payload(info.to_dict(), "bench-a", url))
            for info in DEVICES for url in (DASHBOARD, None)]


@pytest.mark.parametrize(("topic", "payload"), payloads(), ids=[f"{t}-{bool(p['device'].get('configuration_url'))}"
                                                               for t, p in payloads()])
def test_every_payload_passes_home_assistants_discovery_rules(topic: str, payload: dict[str, Any]) -> None:
    assert check_device_discovery(topic, json.loads(json.dumps(payload))) == []


@pytest.mark.parametrize("info", DEVICES, ids=[d.id for d in DEVICES])
def test_per_entity_messages_for_older_home_assistant_pass_the_rules(info: Any) -> None:
    device = discovery_payload(info.to_dict(), "bench-a", DASHBOARD)
    messages = discovery_messages(info.to_dict(), "bench-a", DASHBOARD, "entity")
    assert len(messages) == len(device["components"])  # one per entity, none lost
    for topic, payload in messages:
        assert check_entity_discovery(topic, json.loads(json.dumps(payload))) == [], topic
        assert payload["device"] == device["device"]  # grouped under the same machine
    assert [t for t, _ in messages] == discovery_topics(info.id, "entity")  # what removal empties
    assert {p["unique_id"] for _, p in messages} == {c["unique_id"] for c in device["components"].values()}


def test_every_kind_has_unique_ids_and_its_device_block() -> None:
    unique_ids: list[str] = []
    identifiers: set[str] = set()
    for info in DEVICES:
        payload = discovery_payload(info.to_dict(), "bench-a", DASHBOARD)
        unique_ids += [c["unique_id"] for c in payload["components"].values()]
        device = payload["device"]
        assert device["serial_number"] == info.serial
        assert device["sw_version"] == info.firmware
        assert device["model"] == info.model
        assert device["manufacturer"]
        assert device["configuration_url"] == DASHBOARD
        identifiers.add(device["identifiers"][0])
        assert payload["origin"]["name"] == "fabwire"
        assert [a["topic"] for a in payload["availability"]] == [
            agent_topic("bench-a", "status"), f"fabwire/device/{info.id}/availability"]
        assert discovery_topic(info.id).startswith("homeassistant/device/")
    assert len(unique_ids) == len(set(unique_ids))
    assert len(identifiers) == len(DEVICES)


PARITY = [
    # (kind, entity name, platform, extra options): what owners compare with the OctoPrint and Moonraker integrations
    ("xyz", "Print removed", "button", {}),  # the da Vinci's finished state takes only this
    ("xyz", "Printing", "binary_sensor", {"device_class": "running"}),
    ("xyz", "Problem", "binary_sensor", {"device_class": "problem"}),
    ("xyz", "Extruder target", "sensor", {"device_class": "temperature"}),
    ("xyz", "Bed target", "sensor", {"device_class": "temperature"}),
    ("xyz", "Job file", "sensor", {}),
    ("xyz", "Print time", "sensor", {"device_class": "duration"}),
    ("xyz", "Estimated finish", "sensor", {"device_class": "timestamp"}),
    ("xyz", "Print", "event", {"event_types": ["finished", "failed", "cancelled"]}),
    ("xyz", "Firmware", "sensor", {"entity_category": "diagnostic"}),
    ("xyz", "Wi-Fi signal", "sensor", {"entity_category": "diagnostic", "device_class": "signal_strength"}),
    ("mmu", "MMU error", "event", {"event_types": ["error"]}),
    ("mmu", "Load slot 0", "button", {}),
    ("mmu", "Load slot 4", "button", {}),
    ("mmu", "Unload", "button", {}),
    ("mmu", "Eject slot 2", "button", {}),
    ("mmu", "Problem", "binary_sensor", {"device_class": "problem"}),
    ("lineus", "Write text", "text", {}),
    ("lineus", "Drawing", "event", {"event_types": ["finished", "failed", "cancelled"]}),
]
INFOS = {"xyz": printer(), "mmu": mmu(), "lineus": lineus()}


@pytest.mark.parametrize(("kind", "name", "platform", "options"), PARITY, ids=[f"{r[0]}-{r[1]}" for r in PARITY])
def test_home_assistant_parity_entities(kind: str, name: str, platform: str, options: dict[str, Any]) -> None:
    components = discovery_payload(INFOS[kind].to_dict(), "a")["components"].values()
    [found] = [c for c in components if c["name"] == name]
    assert found["platform"] == platform
    assert {k: found.get(k) for k in options} == options


@pytest.mark.parametrize(("info", "expected"), [
    (printer(), {"Extruder temperature", "Bed temperature", "Progress", "Time left", "State", "Filament left",
                 "Error", "Pause", "Resume", "Cancel", "Home", "Print removed", "Printing", "Problem",
                 "Extruder target", "Bed target", "Job file", "Print time", "Estimated finish", "Print", "Firmware",
                 "Wi-Fi signal", "Wi-Fi network", "IP address"}),
    (mmu(), {"Active slot", "Filament position", "Error", "Retry", "Continue", "Stop", "Tool change", "State",
             "Problem", "MMU error", "Unload", *(f"Load slot {n}" for n in range(5)),
             *(f"Eject slot {n}" for n in range(5))}),
    (lineus(), {"State", "Drawing progress", "Error", "Home", "Problem", "Drawing", "Write text"}),
])
def test_each_kind_has_the_entities_a_user_expects(info: Any, expected: set[str]) -> None:
    components = discovery_payload(info.to_dict(), "a")["components"].values()
    assert {c["name"] for c in components} == expected


def test_buttons_send_commands_the_bridge_understands() -> None:
    for info in INFOS.values():
        components = discovery_payload(info.to_dict(), "a")["components"].values()
        for button in (c for c in components if c["platform"] == "button"):
            parse_command(button["payload_press"].encode())
    components = discovery_payload(printer().to_dict(), "a")["components"].values()
    presses = {c["name"]: parse_command(c["payload_press"].encode()) for c in components if c["platform"] == "button"}
    assert presses["Pause"].action == "pause"
    assert presses["Print removed"].action == "acknowledge"
    assert presses["Cancel"].params == {"confirm": True}  # cancel is destructive: the agent wants confirmation
    mmu_parts = {c["name"]: c for c in discovery_payload(mmu().to_dict(), "a")["components"].values()}
    assert parse_command(mmu_parts["Eject slot 3"]["payload_press"].encode()).params == {"slot": 3}
    assert parse_command(render_command(mmu_parts["Tool change"]["command_template"], "3").encode()).params \
        == {"slot": 3}


@pytest.mark.parametrize("words", ["hello", 'say "hi" {{ x }}', "ünïcode ✓", "a\\b"])
def test_the_text_entity_sends_what_is_typed(words: str) -> None:
    text = next(c for c in discovery_payload(lineus().to_dict(), "a")["components"].values()
                if c["platform"] == "text")
    command = parse_command(render_command(text["command_template"], words).encode())
    assert (command.action, command.params) == ("text", {"text": words})


BREAKAGES = [  # (what is done to a valid payload, words of the problem): the checker catches each class
    (lambda p: p.pop("origin"), "origin is required"),
    (lambda p: p["device"].pop("identifiers"), "identifiers or connections"),
    (lambda p: p["device"].update(configuration_url="raspberrypi:8765"), "not a URL"),
    (lambda p: p.update(availability_mode="some"), "availability_mode"),
    (lambda p: next(iter(p["components"].values())).update(platform="gizmo"), "platform 'gizmo'"),
    (lambda p: next(iter(p["components"].values())).pop("unique_id"), "unique_id is required"),
    (lambda p: next(iter(p["components"].values())).update(valu_template="{{ x }}"), "valu_template"),
    (lambda p: p.pop("state_topic"), "state_topic is required"),
    (lambda p: p.pop("command_topic"), "command_topic is required"),
    (lambda p: p.update(command_topic="fabwire/#"), "wildcards"),
    (lambda p: _first(p, "sensor").update(device_class="temperature", unit_of_measurement="s"), "not a unit"),
    (lambda p: _first(p, "sensor").update(device_class="timestamp", state_class="measurement"), "no unit"),
    (lambda p: _first(p, "sensor").update(entity_category="config"), "not allowed for a sensor"),
    (lambda p: _first(p, "binary_sensor").update(device_class="printing"), "does not exist"),
    (lambda p: _first(p, "event").update(event_types=[]), "event_types"),
    (lambda p: _first(p, "sensor").update(value_template="{{ value_json.x "), "not a template"),
]


def _first(payload: dict[str, Any], platform: str) -> dict[str, Any]:
    return next(c for c in payload["components"].values() if c["platform"] == platform)


@pytest.mark.parametrize(("damage", "words"), BREAKAGES, ids=[w for _, w in BREAKAGES])
def test_the_rules_catch_broken_payloads(damage: Any, words: str) -> None:
    payload = json.loads(json.dumps(discovery_payload(printer().to_dict(), "a", DASHBOARD)))
    damage(payload)
    problems = check_device_discovery(discovery_topic(printer().id), payload)
    assert any(words in p for p in problems), problems


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


# ---------------------------------------------------------------------------------------------- templates on states

def _state(kind: str, status: dict[str, Any] | None = None, job: dict[str, Any] | None = None,
           **values: Any) -> dict[str, Any]:
    """A state as the agent publishes it (`fabwire.agent.core.Agent.state`)."""
    return {"ts": "2026-12-03T10:00:00.000Z", "online": True, "device": INFOS[kind].id, "kind": kind,
            "name": INFOS[kind].name, "summary": summary(**values), "status": status, "job": job}


PRINT_JOB = {"id": "j1", "type": "print", "filename": "benchy.gcode", "state": "running", "params": {}}
NETWORK = {"connected": True, "ip": "10.0.0.5", "ssid": "workshop", "mac": None, "rssi_dbm": -61,
           "signal_percent": 78}
STATES = [  # (a state, entity name → what Home Assistant shows)
    (_state("xyz", state="idle", extruder_temp_c=24, extruder_target_c=0, actions=["home"]),
     {"Printing": "OFF", "Problem": "OFF", "Estimated finish": "None", "Job file": "None", "Extruder target": "0",
      "Firmware": "None", "Wi-Fi signal": "None"}),
    (_state("xyz", {"firmware": "1.1.J", "network": NETWORK}, PRINT_JOB, state="printing", progress_percent=40,
            elapsed_s=1200, time_left_s=1800, extruder_temp_c=210, extruder_target_c=210, bed_temp_c=60,
            bed_target_c=60),
     {"Printing": "ON", "Problem": "OFF", "Estimated finish": "2026-12-03T10:30:00+00:00", "Job file": "benchy.gcode",
      "Print time": "1200", "Time left": "1800", "Bed target": "60", "Firmware": "1.1.J", "Wi-Fi signal": "-61",
      "Wi-Fi network": "workshop", "IP address": "10.0.0.5"}),
    (_state("xyz", {"firmware": "1.1.J", "network": None}, state="paused"), {"Printing": "ON",
                                                                            "Wi-Fi signal": "None"}),
    (_state("xyz", state="error", error="extruder heater timeout"),
     {"Problem": "ON", "Printing": "OFF", "Error": "extruder heater timeout"}),
    (_state("mmu", state="error", active_slot=None), {"Problem": "ON", "Tool change": "None"}),
    (_state("mmu", state="idle", active_slot=2), {"Problem": "OFF", "Tool change": "2", "Active slot": "2"}),
    (_state("lineus", job={"id": "j2", "type": "text", "filename": None, "state": "running",
                           "params": {"text": "hello"}}, state="drawing"), {"Write text": "hello"}),
    (_state("lineus", job={"id": "j3", "type": "text", "filename": None, "state": "running",
                           "params": {"text": "x" * 400}}, state="drawing"), {"Write text": "x" * 255}),
    (_state("lineus", state="idle"), {"Write text": "", "Problem": "OFF"}),
]


@pytest.mark.parametrize(("state", "shown"), STATES, ids=[f"{s['kind']}-{s['summary']['state']}" for s, _ in STATES])
def test_templates_render_what_home_assistant_shows(state: dict[str, Any], shown: dict[str, str]) -> None:
    components = discovery_payload(INFOS[state["kind"]].to_dict(), "a")["components"].values()
    rendered = {c["name"]: render_value(c["value_template"], json.loads(json.dumps(state)))
                for c in components if "value_template" in c and c["platform"] != "event"}
    assert {name: rendered[name] for name in shown} == shown
    for component in components:
        value = rendered.get(component["name"])
        if component.get("unit_of_measurement") and value != "None":
            float(value)  # a number, or None (unknown)
        if component["platform"] == "binary_sensor":
            assert value in ("ON", "OFF")


EVENTS = [  # (kind, an event on the event topic, the event entity's event_type or None for no event)
    ("xyz", {"type": "job", "job": {**PRINT_JOB, "state": "done", "message": "print done"}}, "finished"),
    ("xyz", {"type": "job", "job": {**PRINT_JOB, "state": "failed", "message": "heater"}}, "failed"),
    ("xyz", {"type": "job", "job": {**PRINT_JOB, "state": "cancelled"}}, "cancelled"),
    ("xyz", {"type": "job", "job": {**PRINT_JOB, "state": "running"}}, None),
    ("xyz", {"type": "error", "message": "x", "exit_code": 1}, None),
    ("lineus", {"type": "job", "job": {"id": "j", "type": "text", "filename": None, "state": "done"}}, "finished"),
    ("mmu", {"type": "event", "event": {"event": "error", "command": "T1", "error": "FINDA didn't trigger",
                                        "auto_retry": False}}, "error"),
    ("mmu", {"type": "event", "event": {"event": "progress", "command": "T1", "text": "feeding"}}, None),
]


@pytest.mark.parametrize(("kind", "event", "expected"), EVENTS)
def test_event_entities_fire_on_endings_only(kind: str, event: dict[str, Any], expected: str | None) -> None:
    [entity] = [c for c in discovery_payload(INFOS[kind].to_dict(), "a")["components"].values()
                if c["platform"] == "event"]
    assert entity["state_topic"] == f"fabwire/device/{INFOS[kind].id}/event"
    rendered = render_value(entity["value_template"], {"ts": "t", "device": INFOS[kind].id, **event})
    if expected is None:
        assert rendered == ""  # Home Assistant ignores an empty rendering
        return
    fired = json.loads(rendered)
    assert fired["event_type"] == expected
    assert expected in entity["event_types"]
