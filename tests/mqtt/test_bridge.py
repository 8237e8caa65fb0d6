"""The bridge against a real Mosquitto broker, with an in-test agent behind it: retained state and availability,
discovery, commands with replies (each id once), Home Assistant's birth message, removal, broker restarts and two
agents sharing devices."""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import aiomqtt
import pytest
from hatools import check_device_discovery, check_entity_discovery
from mqtttools import FakeAgent, Mosquitto, lineus, mmu, observing, printer
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties

from fabwire.agent.core import now_iso
from fabwire.errors import InputError, LinkError
from fabwire.mqtt.bridge import Bridge, run_bridge
from fabwire.mqtt.discovery import discovery_topics
from fabwire.mqtt.topics import agent_topic, claim_topic, device_topic, discovery_topic

pytestmark = pytest.mark.timeout(90)
PRINTER = printer()


@contextlib.asynccontextmanager
async def bridged(agent: FakeAgent, broker: Mosquitto, agent_id: str = "bench-a", *,
                  setup: Callable[[Bridge], None] | None = None) -> AsyncIterator[Bridge]:
    """Run a bridge until the block ends (cancelled, as `fabwire serve` stops it); `setup` sees it before it
    starts, as `fabwire serve` sets its options."""
    made: asyncio.Future[Bridge] = asyncio.get_running_loop().create_future()

    def created(bridge: Bridge) -> None:
        if setup is not None:
            setup(bridge)
        made.set_result(bridge)

    task = asyncio.create_task(run_bridge(agent, broker.url, agent_id=agent_id, on_bridge=created))
    try:
        async with asyncio.timeout(15):
            bridge = await made
            await bridge.connected.wait()
        yield bridge
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


async def command(broker: Mosquitto, device: str, payload: dict[str, Any] | str) -> None:
    async with aiomqtt.Client("127.0.0.1", broker.port) as client:
        body = payload if isinstance(payload, str) else json.dumps(payload)
        await client.publish(device_topic(device, "command"), body, qos=1)


async def test_state_availability_info_and_discovery_are_retained(broker: Mosquitto) -> None:
    agent = FakeAgent([PRINTER, mmu(), lineus()])
    async with bridged(agent, broker):
        agent.set_state(PRINTER.id, "printing", progress_percent=42.0, extruder_temp_c=210.5)
        async with observing(broker, "fabwire/#", "homeassistant/#") as seen:
            state = await seen.wait_for(lambda o: (s := o.json(device_topic(PRINTER.id, "state")))
                                        and s["summary"]["state"] == "printing" and s)
            assert state["summary"]["progress_percent"] == 42.0
            assert state == agent.states[PRINTER.id]  # the agent's own schema, untouched
            assert seen.latest[device_topic(PRINTER.id, "availability")] == b"online"
            assert seen.latest[agent_topic("bench-a", "status")] == b"online"
            info = seen.json(device_topic(PRINTER.id, "info"))
            assert (info["serial"], info["agent"]) == ("3DP01P", "bench-a")
            for device in (PRINTER.id, mmu().id, lineus().id):
                payload = await seen.wait_for(lambda o, d=device: o.json(discovery_topic(d)))
                assert payload["state_topic"] == device_topic(device, "state")
        async with observing(broker, "fabwire/device/#", "homeassistant/#") as late:  # a late subscriber gets them
            wanted = {discovery_topic(d) for d in (PRINTER.id, mmu().id, lineus().id)}
            wanted |= {device_topic(PRINTER.id, leaf) for leaf in ("state", "info", "availability")}
            await late.wait_for(lambda o: wanted <= {t for t, _, retained in o.log if retained})


async def test_every_discovery_message_published_passes_home_assistants_rules(broker: Mosquitto) -> None:
    devices = [PRINTER, printer("3DP02P", "garage"), mmu(), lineus()]
    agent = FakeAgent(devices)

    def linked(bridge: Bridge) -> None:
        bridge.dashboard_url = "http://bench.local:8765/"

    async with bridged(agent, broker, setup=linked), observing(broker, "homeassistant/#") as seen:
        wanted = {discovery_topic(d.id) for d in devices}
        await seen.wait_for(lambda o: wanted <= set(o.latest))
        async with aiomqtt.Client("127.0.0.1", broker.port) as ha:  # and again when Home Assistant restarts
            await ha.publish("homeassistant/status", "online", qos=1)
        await seen.wait_for(lambda o: all(o.count(t) >= 2 for t in wanted))
        published = [(topic, payload) for topic, payload, _ in seen.log if payload and topic.endswith("/config")]
    assert len(published) >= 2 * len(devices)
    for topic, payload in published:
        body = json.loads(payload)
        assert check_device_discovery(topic, body) == [], topic
        assert body["device"]["configuration_url"] == "http://bench.local:8765/"


async def test_per_entity_discovery_for_older_home_assistant_is_published_and_removed(broker: Mosquitto) -> None:
    agent = FakeAgent([PRINTER, mmu()])

    def per_entity(bridge: Bridge) -> None:
        bridge.discovery_mode = "entity"

    async with bridged(agent, broker, setup=per_entity), observing(broker, "homeassistant/#") as seen:
        wanted = set(discovery_topics(PRINTER.id, "entity")) | set(discovery_topics(mmu().id, "entity"))
        await seen.wait_for(lambda o: wanted <= {t for t, p in o.latest.items() if p})
        for topic in wanted:
            assert check_entity_discovery(topic, json.loads(seen.latest[topic])) == [], topic
        assert discovery_topic(PRINTER.id) not in seen.latest  # no device message beside them
        del agent.infos[PRINTER.id]  # removed from the agent
        gone = set(discovery_topics(PRINTER.id, "entity"))
        await seen.wait_for(lambda o: all(o.latest.get(t) == b"" for t in gone))


async def test_events_and_availability_changes_follow_the_agent(broker: Mosquitto) -> None:
    agent = FakeAgent([PRINTER])
    async with bridged(agent, broker), observing(broker, "fabwire/device/#") as seen:
        await seen.wait_for(lambda o: o.latest.get(device_topic(PRINTER.id, "availability")) == b"online")
        agent.emit({"ts": now_iso(), "device": PRINTER.id, "type": "offline", "reason": "link lost", "retry_in_s": 1})
        await seen.wait_for(lambda o: o.latest.get(device_topic(PRINTER.id, "availability")) == b"offline")
        agent.emit({"ts": now_iso(), "device": PRINTER.id, "type": "event", "event": {"text": "filament runout"}})
        event = await seen.wait_for(lambda o: o.json(device_topic(PRINTER.id, "event")))
        assert event["event"] == {"text": "filament runout"}
        agent.emit({"ts": now_iso(), "device": PRINTER.id, "type": "online", "info": PRINTER.to_dict()})
        await seen.wait_for(lambda o: o.latest.get(device_topic(PRINTER.id, "availability")) == b"online")


async def test_commands_run_once_per_id_and_are_answered(broker: Mosquitto) -> None:
    agent = FakeAgent([PRINTER])
    async with bridged(agent, broker) as bridge, observing(broker, device_topic(PRINTER.id, "reply")) as seen:
        topic = device_topic(PRINTER.id, "reply")
        for _ in range(3):  # QoS 1 may deliver a command again: the same id runs once
            await command(broker, PRINTER.id, {"action": "pause", "params": {}, "id": "c-1"})
        await seen.wait_for(lambda o: o.count(topic) >= 3)
        replies = [json.loads(p) for t, p, _ in seen.log if t == topic]
        assert {r["id"] for r in replies} == {"c-1"}
        assert all(r["ok"] and r["result"] == {"done": "pause"} for r in replies)
        assert agent.calls == [(PRINTER.id, "pause", {})]
        await command(broker, PRINTER.id, "home")  # a Home Assistant button press: a bare action name
        await command(broker, PRINTER.id, {"action": "explode", "id": 7})
        await command(broker, PRINTER.id, "not json {")
        await seen.wait_for(lambda o: o.count(topic) >= 6)
        replies = [json.loads(p) for t, p, _ in seen.log if t == topic][3:]
        assert [(r["ok"], r["action"], r["id"]) for r in replies] == [(True, "home", None), (False, "explode", 7),
                                                                      (False, None, None)]
        assert replies[1]["exit_code"] == 4
        assert "JSON object or an action name" in replies[2]["error"]
        assert bridge.runner.executed == 3  # pause, home, explode (refused by the agent)


async def test_mqtt5_askers_get_the_reply_on_their_response_topic(broker: Mosquitto) -> None:
    agent = FakeAgent([PRINTER])
    async with bridged(agent, broker), aiomqtt.Client("127.0.0.1", broker.port,
                                                      protocol=aiomqtt.ProtocolVersion.V5) as client:
        await client.subscribe("me/replies", qos=1)
        props = Properties(PacketTypes.PUBLISH)
        props.ResponseTopic = "me/replies"
        props.CorrelationData = b"ask-9"
        await client.publish(device_topic(PRINTER.id, "command"), '{"action": "resume"}', qos=1, properties=props)
        async with asyncio.timeout(15):
            message = await anext(aiter(client.messages))
        assert json.loads(message.payload)["action"] == "resume"
        assert message.properties.CorrelationData == b"ask-9"


async def test_home_assistant_coming_online_gets_discovery_again(broker: Mosquitto) -> None:
    agent = FakeAgent([PRINTER])
    async with bridged(agent, broker), observing(broker, discovery_topic(PRINTER.id)) as seen:
        await seen.wait_for(lambda o: o.count(discovery_topic(PRINTER.id)) == 1)
        async with aiomqtt.Client("127.0.0.1", broker.port) as ha:
            await ha.publish("homeassistant/status", "online", qos=1)
            await ha.publish("homeassistant/status", "offline", qos=1)  # nothing to do when it goes away
        await seen.wait_for(lambda o: o.count(discovery_topic(PRINTER.id)) == 2)
        assert not seen.log[-1][2]  # a live republish, not the retained copy


async def test_a_removed_device_is_cleaned_up(broker: Mosquitto) -> None:
    agent = FakeAgent([PRINTER, lineus()])
    async with bridged(agent, broker), observing(broker, "fabwire/#", "homeassistant/#") as seen:
        await seen.wait_for(lambda o: o.json(discovery_topic(PRINTER.id)))
        del agent.infos[PRINTER.id]
        await seen.wait_for(lambda o: o.latest.get(discovery_topic(PRINTER.id)) == b"", timeout=20)
        for leaf in ("state", "info", "availability"):
            await seen.wait_for(lambda o, leaf=leaf: o.latest.get(device_topic(PRINTER.id, leaf)) == b"")
        await seen.wait_for(lambda o: o.latest.get(claim_topic(PRINTER.id, "bench-a")) == b"")
        assert seen.json(discovery_topic(lineus().id))  # the other device stays
    async with observing(broker, "homeassistant/#", "fabwire/device/#") as after:
        await asyncio.sleep(0.5)  # retained copies arrive at once
        assert discovery_topic(PRINTER.id) not in after.latest
        assert discovery_topic(lineus().id) in after.latest


async def test_a_device_removed_while_the_agent_was_away_is_cleaned_up_at_the_next_start(broker: Mosquitto) -> None:
    async with bridged(FakeAgent([PRINTER, lineus()]), broker):
        pass
    async with observing(broker, "homeassistant/#") as seen:
        await seen.wait_for(lambda o: o.json(discovery_topic(PRINTER.id)))
        async with bridged(FakeAgent([lineus()]), broker):
            await seen.wait_for(lambda o: o.latest.get(discovery_topic(PRINTER.id)) == b"")
            assert seen.json(discovery_topic(lineus().id))


async def test_broker_restart_reconnects_and_republishes(broker: Mosquitto) -> None:
    agent = FakeAgent([PRINTER])
    async with bridged(agent, broker) as bridge:
        bridge.backoff = (0.1, 0.5)
        broker.stop()  # nothing persists: the broker forgets every retained message
        await asyncio.sleep(0.3)
        broker.start()
        async with observing(broker, "fabwire/#", "homeassistant/#") as seen:
            await seen.wait_for(lambda o: o.json(device_topic(PRINTER.id, "state")), timeout=30)
            await seen.wait_for(lambda o: o.json(discovery_topic(PRINTER.id)))
            assert seen.latest[agent_topic("bench-a", "status")] == b"online"
            agent.set_state(PRINTER.id, "paused")
            await seen.wait_for(lambda o: o.json(device_topic(PRINTER.id, "state"))["summary"]["state"] == "paused")


async def test_a_clean_stop_leaves_agent_and_devices_offline(broker: Mosquitto) -> None:
    async with bridged(FakeAgent([PRINTER]), broker):
        pass
    async with observing(broker, "fabwire/#") as seen:
        await seen.wait_for(lambda o: o.latest.get(agent_topic("bench-a", "status")) == b"offline")
        await seen.wait_for(lambda o: o.latest.get(device_topic(PRINTER.id, "availability")) == b"offline")


async def test_two_agents_share_devices_without_fighting(broker: Mosquitto) -> None:
    shared, only_b = printer("SHARED1"), mmu("B-ONLY")
    first, second = FakeAgent([shared, lineus()]), FakeAgent([shared, only_b])
    async with bridged(second, broker, "bench-b") as b, observing(broker, "fabwire/#") as seen:
        async with bridged(first, broker, "bench-a") as a:
            # bench-a sorts first: it owns the shared printer, bench-b stands by.
            await seen.wait_for(lambda o: (o.json(device_topic(shared.id, "info")) or {}).get("agent") == "bench-a")
            assert shared.id in a.owned
            assert shared.id not in b.owned
            assert only_b.id in b.owned
            await command(broker, shared.id, {"action": "pause", "id": "once"})
            await seen.wait_for(lambda o: o.count(device_topic(shared.id, "reply")) >= 1)
            await asyncio.sleep(0.3)
            assert first.calls == [(shared.id, "pause", {})]
            assert second.calls == []
            second.set_state(shared.id, "printing")  # the standby agent's view is not published
            first.set_state(shared.id, "paused")
            await seen.wait_for(lambda o: o.json(device_topic(shared.id, "state"))["summary"]["state"] == "paused")
        # bench-a stops: bench-b takes the printer over.
        await seen.wait_for(lambda o: (o.json(device_topic(shared.id, "info")) or {}).get("agent") == "bench-b")
        assert shared.id in b.owned
        await seen.wait_for(lambda o: o.latest.get(device_topic(shared.id, "availability")) == b"online")
        await command(broker, shared.id, {"action": "resume", "id": "two"})
        await seen.wait_for(lambda o: any(json.loads(p).get("agent") == "bench-b"
                                          for t, p, _ in o.log if t == device_topic(shared.id, "reply")))
        assert second.calls == [(shared.id, "resume", {})]


async def test_bad_url_and_refused_login_are_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="mqtt://host"):
        await run_bridge(FakeAgent([]), "http://127.0.0.1:1")
    locked = Mosquitto(tmp_path, anonymous=False)
    await asyncio.to_thread(locked.start)
    try:
        with pytest.raises(LinkError, match="refused"):
            async with asyncio.timeout(20):
                await run_bridge(FakeAgent([]), locked.url, username="nobody", password="wrong")
    finally:
        await asyncio.to_thread(locked.stop)


async def test_a_state_older_than_a_link_event_never_flips_availability_back(broker: Mosquitto) -> None:
    agent = FakeAgent([PRINTER])
    async with bridged(agent, broker), observing(broker, "fabwire/device/#") as seen:
        topic = device_topic(PRINTER.id, "availability")
        await seen.wait_for(lambda o: o.latest.get(topic) == b"online")
        for _ in range(20):  # offline, then back: a state from the offline spell is queued behind the online event
            stale = {**agent.states[PRINTER.id], "online": False}
            agent.emit({"ts": now_iso(), "device": PRINTER.id, "type": "offline", "reason": "link lost",
                        "retry_in_s": 1})
            agent.emit({"ts": now_iso(), "device": PRINTER.id, "type": "state", "state": stale})
            agent.emit({"ts": now_iso(), "device": PRINTER.id, "type": "online", "info": None})
            await asyncio.sleep(0.05)
        agent.set_state(PRINTER.id, "idle")
        await seen.wait_for(lambda o: o.json(device_topic(PRINTER.id, "state"))["online"] is True
                            and o.latest.get(topic) == b"online")
        flips = [payload for t, payload, _ in seen.log if t == topic]
        assert flips == [b"online"] + [b"offline", b"online"] * 20, flips


async def test_a_state_older_than_one_published_is_never_published(broker: Mosquitto) -> None:
    """An event queued before the bridge took a snapshot of the device (when it came to own it) arrives after
    that snapshot went out: it is older, and neither its state nor its availability is published."""
    agent = FakeAgent([PRINTER])
    async with bridged(agent, broker), observing(broker, "fabwire/device/#") as seen:
        state_topic, availability = device_topic(PRINTER.id, "state"), device_topic(PRINTER.id, "availability")
        await seen.wait_for(lambda o: o.json(state_topic) and o.latest.get(availability) == b"online")
        before = "2000-01-01T00:00:00.000Z"
        old = {**agent.states[PRINTER.id], "ts": before, "online": False, "summary": {"state": "offline"}}
        agent.emit({"ts": before, "device": PRINTER.id, "type": "offline", "reason": "not connected yet",
                    "retry_in_s": 1})
        agent.emit({"ts": before, "device": PRINTER.id, "type": "state", "state": old})
        agent.set_state(PRINTER.id, "printing")
        await seen.wait_for(lambda o: o.json(state_topic)["summary"]["state"] == "printing")
        states = [json.loads(p)["summary"]["state"] for t, p, _ in seen.log if t == state_topic and p]
        assert "offline" not in states, states
        assert [p for t, p, _ in seen.log if t == availability] == [b"online"]
