"""What arrives from a shared broker is outside input: claims count only while their agent is provably alive, a
command flood on one device neither starves another nor grows memory, payloads are read within bounds, text from
the broker never drives the terminal, and a password in a broker URL is never shown."""

from __future__ import annotations

import asyncio
import contextlib
import json
import subprocess
import sys
from typing import Any

import aiomqtt
import pytest
from hypothesis import given
from hypothesis import strategies as st
from mqtttools import FakeAgent, Mosquitto, lineus, observing, printer
from test_bridge import bridged

from clitools import cli_env
from fabwire.errors import InputError, visible
from fabwire.jsontext import MAX_DEPTH, parse_json
from fabwire.mqtt import bridge as bridge_module
from fabwire.mqtt.commands import parse_command
from fabwire.mqtt.fleet_view import HEARTBEAT_TTL_S, STALE_CLAIM_S, FleetView
from fabwire.mqtt.topics import (
    MAX_COMMAND_BYTES,
    PING,
    agent_topic,
    claim_topic,
    device_topic,
    parse_broker,
    redact_password,
)

pytestmark = pytest.mark.timeout(120)
DEVICE = "lineus-demo"


# ------------------------------------------------------------------------------------------ the ownership rule


def phantom_view(now: float = 0.0) -> FleetView:
    """Agent "0" left a retained status and claim and never sent a heartbeat."""
    view = FleetView()
    view.take(agent_topic("0", "status"), b"online", now=now, retained=True)
    view.take(claim_topic(DEVICE, "0"), b"1", now=now, retained=True)
    return view


def test_a_retained_claim_without_a_live_heartbeat_never_wins() -> None:
    view = phantom_view()
    assert view.owner(DEVICE, me="real", now=1.0) == "real"


def test_a_replayed_heartbeat_proves_nothing() -> None:
    view = phantom_view()
    view.take(agent_topic("0", "heartbeat"), b"7", now=1.0, retained=True)
    assert view.owner(DEVICE, me="real", now=1.0) == "real"


def test_a_live_heartbeat_makes_the_claimant_alive_until_it_goes_silent() -> None:
    view = phantom_view()
    view.take(agent_topic("0", "heartbeat"), b"1", now=10.0)
    assert view.owner(DEVICE, me="real", now=10.0 + HEARTBEAT_TTL_S) == "0"  # alive: the first id owns it
    assert view.owner(DEVICE, me="real", now=10.1 + HEARTBEAT_TTL_S) == "real"  # three heartbeats missed
    assert view.living(10.0) == {"0"}
    assert view.living(11.0 + HEARTBEAT_TTL_S) == frozenset()


def test_a_heartbeat_does_not_outlive_the_last_will() -> None:
    view = phantom_view()
    view.take(agent_topic("0", "heartbeat"), b"1", now=10.0)
    view.take(agent_topic("0", "status"), b"offline", now=10.5)
    assert view.owner(DEVICE, me="real", now=11.0) == "real"


def test_claims_nobody_stands_behind_go_stale() -> None:
    view = phantom_view(now=100.0)
    assert view.stale_claims(DEVICE, 100.0 + STALE_CLAIM_S - 1) == []
    assert view.stale_claims(DEVICE, 100.0 + STALE_CLAIM_S) == ["0"]
    view.take(agent_topic("0", "heartbeat"), b"1", now=100.0 + STALE_CLAIM_S)  # it speaks again: not stale
    assert view.stale_claims(DEVICE, 100.0 + STALE_CLAIM_S + 1) == []


@given(st.lists(st.tuples(st.sampled_from(["0", "a", "b"]),
                          st.sampled_from(["status:online", "status:offline", "heartbeat", "heartbeat-retained",
                                           "claim", "unclaim"]),
                          st.floats(min_value=0, max_value=1000, allow_nan=False)), max_size=30))
def test_only_an_alive_claimant_or_me_ever_owns(messages: list[tuple[str, str, float]]) -> None:
    view = FleetView()
    now = 0.0
    for agent, kind, step in messages:
        now += step
        if kind.startswith("status:"):
            view.take(agent_topic(agent, "status"), kind.split(":")[1].encode(), now=now)
        elif kind.startswith("heartbeat"):
            view.take(agent_topic(agent, "heartbeat"), b"1", now=now, retained=kind.endswith("retained"))
        else:
            view.take(claim_topic(DEVICE, agent), b"1" if kind == "claim" else b"", now=now)
    owner = view.owner(DEVICE, me="m", now=now)
    assert owner == "m" or (view.alive(owner, now) and owner < "m") if owner else False


# ------------------------------------------------------------------------------------------ against a broker


async def publish(broker: Mosquitto, *messages: tuple[str, bytes, bool]) -> None:
    async with aiomqtt.Client("127.0.0.1", broker.port) as client:
        for topic, payload, retain in messages:
            await client.publish(topic, payload, qos=1, retain=retain)


async def ask(broker: Mosquitto, device: str, commands: list[bytes], replies: int,
              timeout: float = 30.0) -> list[dict[str, Any]]:
    """Send `commands` to `device` and collect its first `replies` replies."""
    async with observing(broker, device_topic(device, "reply")) as seen:
        await publish(broker, *((device_topic(device, "command"), body, False) for body in commands))
        await seen.wait_for(lambda o: o.count(device_topic(device, "reply")) >= replies, timeout)
        return [json.loads(p) for t, p, _ in seen.log if t == device_topic(device, "reply")]


async def test_a_phantom_claim_does_not_silence_the_real_agent(broker: Mosquitto) -> None:
    """A retained "online" status and claim by an agent that sorts first, with nothing live behind them (a
    stranger's, or a crashed agent's whose will was lost): the real agent keeps publishing and answering."""
    arm = lineus()
    await publish(broker, (agent_topic("0", "status"), b"online", True), (claim_topic(arm.id, "0"), b"1", True))
    agent = FakeAgent([arm])
    async with bridged(agent, broker) as bridge:
        assert arm.id in bridge.owned
        replies = await ask(broker, arm.id, [b'{"action": "home", "id": "h1"}'], 1)
        assert replies[0]["ok"]
        assert replies[0]["agent"] == "bench-a"
        assert agent.calls == [(arm.id, "home", {})]


async def test_a_live_agent_that_sorts_first_still_takes_over(broker: Mosquitto) -> None:
    """The heartbeat does not break the sharing rule: a live agent whose id sorts first owns the device."""
    shared = printer()
    first, second = FakeAgent([shared]), FakeAgent([shared])
    async with bridged(second, broker, "bench-b"), observing(broker, device_topic(shared.id, "info")) as seen:
        await seen.wait_for(lambda o: (o.json(device_topic(shared.id, "info")) or {}).get("agent") == "bench-b")
        async with bridged(first, broker, "bench-a"):
            await seen.wait_for(lambda o: (o.json(device_topic(shared.id, "info")) or {}).get("agent") == "bench-a")
            replies = await ask(broker, shared.id, [b'{"action": "home", "id": "x"}'], 1)
            assert replies[0]["agent"] == "bench-a"
            assert second.calls == []


async def test_a_ping_is_answered_with_a_heartbeat(broker: Mosquitto) -> None:
    async with bridged(FakeAgent([printer()]), broker), observing(broker, "fabwire/agent/+/heartbeat") as seen:
        before = seen.count(agent_topic("bench-a", "heartbeat"))
        await publish(broker, (PING, b"me", False))
        await seen.wait_for(lambda o: o.count(agent_topic("bench-a", "heartbeat")) > before)


class SlowAgent(FakeAgent):
    """Every action on the flooded device waits until released."""

    def __init__(self, *args: Any, slow: str, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.slow = slow
        self.release = asyncio.Event()

    async def act(self, device_id: str, action: str, params: dict[str, Any]) -> dict[str, Any]:
        if device_id == self.slow:
            await self.release.wait()
        return await super().act(device_id, action, params)


async def test_a_command_flood_on_one_device_neither_starves_another_nor_is_kept(broker: Mosquitto) -> None:
    flooded, other = printer(), lineus()
    agent = SlowAgent([flooded, other], slow=flooded.id)
    flood = 400
    async with bridged(agent, broker) as bridge, observing(broker, "fabwire/device/+/reply") as seen:
        await publish(broker, *((device_topic(flooded.id, "command"), json.dumps({"action": "home", "id": i}).encode(),
                                 False) for i in range(flood)))
        replies = await ask(broker, other.id, [b'{"action": "home", "id": "other"}'], 1)
        assert replies[0]["ok"], replies  # answered while the flooded device's first command still waits
        busy = await seen.wait_for(lambda o: [json.loads(p) for t, p, _ in o.log
                                              if t == device_topic(flooded.id, "reply")])
        assert not busy[0]["ok"]
        assert busy[0]["error"].startswith("busy:")
        waiting = sum(q.qsize() for q in bridge._commands.values())
        assert waiting <= bridge_module.COMMAND_QUEUE  # the rest was refused, not kept
        agent.release.set()
        await seen.wait_for(lambda o: sum(1 for c in agent.calls if c[0] == flooded.id) >= 2)
    ran = sum(1 for c in agent.calls if c[0] == flooded.id)
    assert ran <= bridge_module.COMMAND_QUEUE + 1  # the one running plus the queue
    assert bridge.commands_refused >= flood - bridge_module.COMMAND_QUEUE - 1


@pytest.mark.parametrize(("payload", "said"), [
    (b'{"action": "home", "params": {"x": ' + b"[" * 20_000 + b"]" * 20_000 + b"}}", "nests deeper"),
    (b'{"action": "home", "params": ' + b'{"a": ' * 40 + b"1" + b"}" * 41, "nests deeper"),
    (b'{"action": "home", "params": {"pad": "' + b"x" * MAX_COMMAND_BYTES + b'"}}', "at most"),
    (b"\xff\xfe", "UTF-8"),
    (b'{"action": ', "not valid JSON"),
])
async def test_a_malformed_command_is_answered_with_what_is_wrong(broker: Mosquitto, payload: bytes,
                                                                  said: str) -> None:
    arm = lineus()
    agent = FakeAgent([arm])
    async with bridged(agent, broker):
        replies = await ask(broker, arm.id, [payload], 1)
    assert not replies[0]["ok"]
    assert said in replies[0]["error"]
    assert len(replies[0]["error"]) < 200
    assert agent.calls == []


async def test_a_retained_command_is_not_run_again(broker: Mosquitto) -> None:
    """A command left retained would run again whenever an agent connects."""
    arm = lineus()
    await publish(broker, (device_topic(arm.id, "command"), b"home", True))
    agent = FakeAgent([arm])
    async with bridged(agent, broker):
        replies = await ask(broker, arm.id, [b'{"action": "home", "id": "now"}'], 1)
    assert [r["id"] for r in replies] == ["now"]
    assert len(agent.calls) == 1
    await publish(broker, (device_topic(arm.id, "command"), b"", True))


# ------------------------------------------------------------------------------------------ fleet and URLs


def fleet(broker: Mosquitto, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "fabwire", "fleet", "--mqtt", broker.url, *args],
                          capture_output=True, text=True, timeout=60, env=cli_env())


async def test_fleet_survives_junk_and_shows_broker_text_without_obeying_it(broker: Mosquitto) -> None:
    await publish(broker,
                  (device_topic("junk", "state"), b"[" * 100_000 + b"]" * 100_000, True),
                  (device_topic("deep", "info"), b'{"name": ' + b"[" * 500 + b"]" * 500 + b"}", True),
                  (device_topic("good", "info"), b'{"name": "good\\u001b[2J\\u001b]0;owned\\u0007", "kind": "xyz"}',
                   True),
                  (agent_topic("0", "status"), b"online", True), (claim_topic("good", "0"), b"1", True))
    done = await asyncio.to_thread(fleet, broker)
    assert done.returncode == 0, done.stderr
    assert "good\\x1b[2J\\x1b]0;owned\\x07" in done.stdout
    assert "\x1b" not in done.stdout
    listed = await asyncio.to_thread(fleet, broker, "--json")
    rows = {row["device"]: row for row in json.loads(listed.stdout)["devices"]}
    assert rows["good"]["agent_online"] is False  # the phantom claimant never heartbeats
    assert set(rows) == {"good"}  # what is only junk is left out


async def test_fleet_shows_a_live_agent_as_online(broker: Mosquitto) -> None:
    async with bridged(FakeAgent([printer()]), broker):
        done = await asyncio.to_thread(fleet, broker, "--json")
    rows = json.loads(done.stdout)["devices"]
    assert [(r["agent"], r["agent_online"]) for r in rows] == [("bench-a", True)]


PASSWORDS = st.text(alphabet=st.characters(blacklist_categories=("Cs", "Cc")), min_size=4, max_size=20).filter(
    lambda p: not any(c in p for c in "@/?#") and p.strip() == p)


@given(PASSWORDS, st.sampled_from([":99999", ":1/x", ":port", "/path", ":1?q=1", ":-1", ""]),
       st.sampled_from(["mqtt://", "mqtts://", "", "http://"]))
def test_no_error_about_a_broker_url_shows_its_password(password: str, tail: str, scheme: str) -> None:
    url = f"{scheme}fab:{password}@127.0.0.1{tail}"
    with contextlib.suppress(InputError):
        parse_broker(url)
        return
    with pytest.raises(InputError) as caught:
        parse_broker(url)
    assert password not in str(caught.value)
    assert password not in redact_password(url)


@pytest.mark.parametrize("command", ["fleet", "serve"])
def test_a_broker_url_that_cannot_work_is_a_usage_error(command: str, tmp_path: Any) -> None:
    extra = ["--listen", "127.0.0.1:0", "--state-dir", str(tmp_path)] if command == "serve" else []
    done = subprocess.run([sys.executable, "-m", "fabwire", command, *extra, "--mqtt", "mqtt://fab:s3cretPW@h:99999"],
                          capture_output=True, text=True, timeout=60, env=cli_env())
    assert done.returncode == 2
    assert "Port out of range" in done.stderr
    assert "s3cretPW" not in done.stdout + done.stderr
    assert "listening" not in done.stdout  # refused before anything started


# ------------------------------------------------------------------------------------------ bounded JSON


@pytest.mark.parametrize(("text", "said"), [
    ("[" * 100_000, "nests deeper"), ("[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1), "nests deeper"),
    ('{"a": ', "not valid JSON"), (b"\xc3", "UTF-8")])
def test_parse_json_says_what_is_wrong(text: str | bytes, said: str) -> None:
    with pytest.raises(InputError, match=said):
        parse_json(text, what="the body")


def test_parse_json_takes_the_deepest_allowed_and_refuses_big_input() -> None:
    deepest = "[" * MAX_DEPTH + "]" * MAX_DEPTH
    assert parse_json(deepest) is not None
    with pytest.raises(InputError, match="larger than 10 bytes"):
        parse_json("[" + "1," * 10 + "1]", max_bytes=10)


@given(st.recursive(st.none() | st.booleans() | st.integers() | st.text(max_size=5),
                    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=3), inner,
                                                                                max_size=3), max_leaves=40))
def test_parse_json_returns_what_json_reads_within_the_depth(value: Any) -> None:
    text = json.dumps(value)
    assert parse_json(text) == json.loads(text)


def test_command_parsing_uses_the_same_bounds() -> None:
    with pytest.raises(InputError, match="nests deeper"):
        parse_command(b"{" + b'"a":{' * 100 + b"}" * 101)


@given(st.text())
def test_visible_text_has_no_control_characters(text: str) -> None:
    shown = visible(text)
    assert not any((ord(c) < 32 and c not in "\t\n") or 0x7F <= ord(c) <= 0x9F for c in shown)


def incoming(topic: str) -> aiomqtt.Message:
    return aiomqtt.Message(topic, b"x", qos=0, retain=False, mid=0, properties=None)


async def test_the_incoming_queue_keeps_a_bounded_share_per_device() -> None:
    queue = bridge_module.FairIncoming()
    taken = 0
    for _ in range(1000):
        with contextlib.suppress(asyncio.QueueFull):
            queue.put_nowait(incoming(device_topic("flooded", "command")))
            taken += 1
    assert taken == bridge_module.COMMAND_QUEUE
    queue.put_nowait(incoming(device_topic("other", "command")))  # another device still gets through
    queue.put_nowait(incoming(agent_topic("b", "status")))
    assert queue.get_nowait().topic.value == device_topic("flooded", "command")
    queue.put_nowait(incoming(device_topic("flooded", "command")))  # one taken out: one more fits
    with pytest.raises(asyncio.QueueFull):
        queue.put_nowait(incoming(device_topic("flooded", "command")))


@pytest.mark.parametrize("response_topic", [
    "fabwire/device/mmu-x/command", "fabwire/agent/bench-a/status", "homeassistant/device/x/config", "a/+/b"])
async def test_a_response_topic_cannot_aim_a_reply_at_fabwires_own_topics(broker: Mosquitto,
                                                                          response_topic: str) -> None:
    """A reply published on another device's command topic would run there: such a response topic is ignored,
    and the reply goes to the device's own reply topic only."""
    from paho.mqtt.packettypes import PacketTypes
    from paho.mqtt.properties import Properties

    arm, other = lineus(), printer()
    agent = FakeAgent([arm, other])
    async with bridged(agent, broker), observing(broker, "#") as seen:
        async with aiomqtt.Client("127.0.0.1", broker.port, protocol=aiomqtt.ProtocolVersion.V5) as client:
            props = Properties(PacketTypes.PUBLISH)  # type: ignore[no-untyped-call]
            props.ResponseTopic = response_topic.replace("mmu-x", other.id)
            await client.publish(device_topic(arm.id, "command"), '{"action": "home", "id": 1}', qos=1,
                                 properties=props)
        await seen.wait_for(lambda o: o.count(device_topic(arm.id, "reply")) == 1)
        replies = await ask(broker, arm.id, [b'{"action": "home", "id": 2}'], 1)  # later than any stray reply
    assert replies[0]["id"] == 2
    assert [c[:2] for c in agent.calls] == [(arm.id, "home"), (arm.id, "home")]  # nothing ran on the other device
    assert not [p for t, p, _ in seen.log if t == props.ResponseTopic and b'"action"' in p]  # no reply went there


async def test_a_broker_full_of_junk_claims_does_not_take_the_agent_off(broker: Mosquitto) -> None:
    junk = [(claim_topic(f"d{i}", f"a{i}"), b"1", True) for i in range(15_000)]
    junk += [(agent_topic(f"a{i}", "status"), b"online", True) for i in range(15_000)]
    await publish(broker, *junk)
    arm = lineus()
    agent = FakeAgent([arm])
    async with bridged(agent, broker) as bridge:
        assert arm.id in bridge.owned
        replies = await ask(broker, arm.id, [b'{"action": "home", "id": "h"}'], 1)
        assert replies[0]["ok"]
        assert len(bridge.view.devices) <= bridge_module.FOREIGN_DEVICES + 1
