"""The MQTT bridge of `fabwire serve --mqtt URL`: publishes each device's state, availability, events and Home
Assistant discovery, and runs the commands sent to it (topic layout in `fabwire.mqtt.topics`).

Several agents may share a broker and even a device: each claims the devices it monitors, and only a device's
owner (see `fabwire.mqtt.fleet_view`) publishes it and runs its commands. Each agent proves it is alive with a
heartbeat (and answers a ping with one at once); the broker sets an agent's status to "offline" through the last
will when the agent dies. A lost broker is retried with backoff, and everything is republished on reconnection
and whenever Home Assistant announces itself online.

What arrives from the broker is outside input: commands wait in a bounded queue per device (a flood on one
device neither starves another nor grows memory), and payloads are read within size and nesting limits.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import secrets
import socket
import time
from collections.abc import Awaitable, Callable
from typing import Any, Protocol

import aiomqtt
from aiomqtt.exceptions import MqttConnectError

from fabwire import __version__
from fabwire.agent.core import is_demo_id, now_iso
from fabwire.agent.drivers.base import offline_summary
from fabwire.errors import FabwireError, LinkError, excerpt
from fabwire.mqtt.commands import CommandRunner
from fabwire.mqtt.discovery import DISCOVERY_MODES, discovery_messages, discovery_topics
from fabwire.mqtt.fleet_view import STALE_CLAIM_S, FleetView
from fabwire.mqtt.probe import SILENT
from fabwire.mqtt.topics import (
    BROKER_CHECK,
    DISCOVERY_PREFIX,
    HA_STATUS,
    HEARTBEAT,
    HEARTBEAT_S,
    INCOMING_QUEUE,
    MQTT_OFF,
    OFFLINE,
    ONLINE,
    OUTGOING_CALLS,
    PING,
    PREFIX,
    Broker,
    agent_topic,
    claim_topic,
    default_agent_id,
    device_topic,
    parse_broker,
    split_agent_topic,
    split_device_topic,
)

log = logging.getLogger("fabwire.mqtt")
BACKOFF = (0.5, 15.0)
SYNC_TIMEOUT = 3.0
"""Longest wait for the broker's retained claims before this agent decides what it owns."""
DEVICE_SCAN_S = 1.0
"""How often the agent's device list is compared with what was published (added and removed devices), and the
other agents' heartbeats with the clock."""
PING_SETTLE_S = 1.0
"""After the broker's retained topics, how long the other agents have to answer this agent's ping before it
decides what it owns."""
COMMAND_QUEUE = 32
"""Commands waiting per device; one more is answered "busy" at once instead of being kept."""
OVERFLOW_REPLIES = 64
""""Busy" answers waiting to be published; beyond that a flood's commands are dropped unanswered."""
FOREIGN_DEVICES = 10_000
"""Devices followed on the broker beyond this agent's own; past it, only this agent's own devices are."""
SWEEP_AGAIN_S = 60.0
"""How soon an agent empties again a topic a killed demo left, when the broker kept it (its ACL refused)."""
PONG_INTERVAL_S = 0.5
"""Pings are answered at most this often: a ping flood costs one heartbeat per interval."""


class _QueueFullNotice(logging.Filter):
    """Lets the MQTT client's "queue is full, discarding" warning through once a minute, not once per message."""

    def __init__(self) -> None:
        super().__init__()
        self._last = -60.0

    def filter(self, record: logging.LogRecord) -> bool:
        if "queue is full" not in record.getMessage():
            return True
        now = time.monotonic()
        if now - self._last < 60.0:
            return False
        self._last = now
        return True


CLIENT_LOG = logging.getLogger("fabwire.mqtt.client")
CLIENT_LOG.addFilter(_QueueFullNotice())


class FairIncoming(asyncio.Queue[aiomqtt.Message]):
    """The MQTT client's incoming queue, bounded per sender's target: at most COMMAND_QUEUE commands per device
    and INCOMING_QUEUE messages in all wait for the reader. The client reads a burst off the socket before the
    reader runs, so without this a flood at one device would push out another device's command, or grow
    memory with everything the flood sent. The client drops (and logs) what does not fit."""

    def __init__(self, maxsize: int = 0) -> None:
        super().__init__(maxsize)
        self._commands: dict[str, int] = {}
        self._others = 0

    @staticmethod
    def _device_of_command(message: aiomqtt.Message) -> str | None:
        parts = split_device_topic(message.topic.value)
        return parts[0] if parts is not None and parts[1] == "command" else None

    def put_nowait(self, item: aiomqtt.Message) -> None:
        device = self._device_of_command(item)
        if device is not None and self._commands.get(device, 0) >= COMMAND_QUEUE:
            raise asyncio.QueueFull
        if device is None and self._others >= INCOMING_QUEUE:
            raise asyncio.QueueFull
        super().put_nowait(item)

    def _put(self, item: aiomqtt.Message) -> None:
        device = self._device_of_command(item)
        if device is None:
            self._others += 1
        else:
            self._commands[device] = self._commands.get(device, 0) + 1
        super()._put(item)

    def _get(self) -> aiomqtt.Message:
        item: aiomqtt.Message = super()._get()
        device = self._device_of_command(item)
        if device is None:
            self._others -= 1
        elif self._commands[device] > 1:
            self._commands[device] -= 1
        else:
            del self._commands[device]
        return item


class AgentLike(Protocol):
    """What the bridge uses of `fabwire.agent.core.Agent`."""

    @property
    def state_dir(self) -> Any: ...

    def devices(self) -> list[Any]: ...

    def state(self, device_id: str) -> dict[str, Any]: ...

    def subscribe(self, device_id: str | None = None) -> Any: ...

    async def act(self, device_id: str, action: str, params: dict[str, Any]) -> dict[str, Any]: ...


def _dump(value: Any) -> bytes:
    return json.dumps(value, separators=(",", ":"), default=str).encode()


class Bridge:
    def __init__(self, agent: AgentLike, broker: Broker, agent_id: str, *,
                 backoff: tuple[float, float] = BACKOFF) -> None:
        self.agent = agent
        self.broker = broker
        self.agent_id = agent_id
        self.backoff = backoff
        self.view = FleetView()
        self.known: dict[str, dict[str, Any]] = {}
        self.dashboard_url: str | None = None
        """The agent's dashboard, Home Assistant's link to each device (`configuration_url`)."""
        self.discovery_mode = "device"
        """`fabwire.mqtt.discovery.DISCOVERY_MODES`: one message per device, or per entity (older Home Assistant)."""
        """Devices this agent monitors and has claimed: id → DeviceInfo as a dict."""
        self.owned: set[str] = set()
        self.runner = CommandRunner(agent.act, agent_id)
        self.states_published = 0
        self.connected = asyncio.Event()
        self._client: aiomqtt.Client | None = None
        self._pending: dict[str, dict[str, Any]] = {}
        self._availability: dict[str, str] = {}
        self._newest: dict[str, str] = {}
        self._last_state: dict[str, dict[str, Any]] = {}
        """Per device: the newest state published, which a clean stop publishes again as offline."""
        """Per device: the time (`ts`, ISO 8601 UTC with milliseconds) of the newest state published, or link event
        followed; an older one that comes after it (an event queued before a snapshot of the state) is dropped."""
        """What this connection last published on each device's availability topic."""
        self._dirty: asyncio.Queue[str] = asyncio.Queue()
        """Devices whose newest state waits in `_pending`, oldest first (each at most once)."""
        self._synced = asyncio.Event()
        self._sync_token = ""
        self._tasks: set[asyncio.Task[Any]] = set()
        self._commands: dict[str, asyncio.Queue[tuple[bytes, Any]]] = {}
        """Per device: commands waiting for its worker (bounded by COMMAND_QUEUE)."""
        self._overflow: asyncio.Queue[tuple[str, bytes, Any]] = asyncio.Queue(OVERFLOW_REPLIES)
        self._beats = 0
        self._last_pong = -PONG_INTERVAL_S
        self._reasserted: dict[str, float] = {}
        self._living: frozenset[str] = frozenset()
        self.commands_refused = 0
        """Commands answered "busy" or dropped because their device's queue was full."""
        self.passing: frozenset[str] = frozenset()
        """Devices that exist only while this agent runs (the demo's simulators): a clean stop takes them off the
        broker, discovery included, instead of leaving them offline for good."""
        self.passing_agent = False
        """This agent itself exists for one run (a demo with no state directory: a new id each time): a clean stop
        takes its own status and info off the broker too."""
        self.on_connected: Callable[[str], None] | None = None
        """Told each time the broker takes the connection ("publishing to mqtt://… as agent …"): `fabwire serve`
        prints it, as it prints where it listens, since a failed attempt is already shown."""
        self._swept: dict[str, float] = {}
        """Topics a killed demo left that this agent emptied, and when (see `_sweep`)."""
        self.on_trouble: Callable[[str, float], None] | None = None
        """Told why the connection failed or was lost, and in how many seconds it is tried again: `fabwire serve`
        says it on the terminal (`fabwire.agent.terminal`); without it, it is logged as a warning."""

    # ------------------------------------------------------------------------------------------ connection

    async def run(self) -> None:
        """Stay connected until cancelled; raises LinkError when the broker refuses the login."""
        events = self.agent.subscribe(None)
        delay = self.backoff[0]
        try:
            while True:
                try:
                    foreign = await self.broker.foreign_peer()
                    if foreign is not None and foreign != SILENT:  # another machine: asking again would not mend it
                        self._give_up(f"MQTT broker {self.broker.url}: {foreign}; check {BROKER_CHECK}")
                        return
                    wrong = await self.broker.not_a_broker() if foreign == SILENT else None
                    if wrong is not None:
                        self._trouble(wrong, delay)
                        await asyncio.sleep(delay)
                        delay = min(delay * 2, self.backoff[1])
                        continue
                    will = aiomqtt.Will(agent_topic(self.agent_id, "status"), OFFLINE, qos=1, retain=True)
                    async with aiomqtt.Client(**self.broker.client_options(), identifier=f"fabwire-{self.agent_id}",
                                              logger=CLIENT_LOG, will=will, queue_type=FairIncoming) as client:
                        client.pending_calls_threshold = 10 * OUTGOING_CALLS  # its warning is for leaks
                        delay = self.backoff[0]
                        log.info("MQTT connected to %s as agent %s", self.broker.url, self.agent_id)
                        if self.on_connected is not None:
                            self.on_connected(f"publishing to {self.broker.url} as agent {self.agent_id}")
                        await self._connected(client, events)
                except MqttConnectError as exc:
                    raise LinkError(f"MQTT broker {self.broker.url} refused the connection: {exc}") from None
                except aiomqtt.MqttError as exc:
                    self._trouble(self.broker.failure(exc), delay)
                except FabwireError as exc:  # the agent changed under us (a device went away mid-publish)
                    self._trouble(f"MQTT bridge: {exc}", delay)
                finally:
                    self._client = None
                    self.connected.clear()
                await asyncio.sleep(delay)
                delay = min(delay * 2, self.backoff[1])
        finally:
            events.close()

    def _give_up(self, failure: str) -> None:
        """The bridge gives up for good (the address names another kind of server): said once, as an error; the agent
        goes on serving its machines."""
        if self.on_trouble is None:
            log.error("%s; %s", failure, MQTT_OFF)
            return
        self.on_trouble(failure, -1.0)

    def _trouble(self, failure: str, retry_in_s: float) -> None:
        if self.on_trouble is None:
            log.warning("%s; retrying in %.1f s", failure, retry_in_s)
            return
        log.info("%s; retrying in %.1f s", failure, retry_in_s)
        self.on_trouble(failure, retry_in_s)

    async def _connected(self, client: aiomqtt.Client, events: Any) -> None:
        self._client = client
        self._synced.clear()
        self.view = FleetView()
        self.owned.clear()
        self.known.clear()
        self._availability.clear()
        self._pending.clear()
        self._dirty = asyncio.Queue()
        me = self.agent_id
        for topic in (f"{PREFIX}/agent/+/status", f"{PREFIX}/agent/+/info", f"{PREFIX}/agent/+/{HEARTBEAT}",
                      f"{PREFIX}/device/+/claim/+",
                      f"{PREFIX}/device/+/info", f"{PREFIX}/device/+/command", HA_STATUS, PING,
                      agent_topic(me, "sync")):
            await client.subscribe(topic, qos=1)
        await client.publish(agent_topic(me, "status"), ONLINE, qos=1, retain=True)
        await self._heartbeat()
        await client.publish(PING, me, qos=1)  # every live agent answers with a heartbeat before we decide
        info: dict[str, Any] = {"agent": me, "host": socket.gethostname(), "version": __version__}
        if self.passing_agent:
            info["passing"] = True  # another agent may clear this agent's records if it is killed
        await client.publish(agent_topic(me, "info"), _dump(info), qos=1, retain=True)
        self.known = self._current_devices()
        for device in sorted(self.known):
            await client.publish(claim_topic(device, me), b"1", qos=1, retain=True)
        # Everything retained on the topics subscribed above reaches us before this echo: then ownership is known.
        self._sync_token = secrets.token_hex(8)
        await client.publish(agent_topic(me, "sync"), self._sync_token, qos=1)
        self._commands.clear()
        self._overflow = asyncio.Queue(OVERFLOW_REPLIES)
        workers = [asyncio.create_task(self._read(client)), asyncio.create_task(self._pump(events)),
                   *(asyncio.create_task(self._publisher()) for _ in range(OUTGOING_CALLS)),
                   asyncio.create_task(self._scan()), asyncio.create_task(self._heartbeats()),
                   asyncio.create_task(self._refuse_overflow())]
        try:
            done, _ = await asyncio.wait(workers, return_when=asyncio.FIRST_EXCEPTION)
            for task in done:
                task.result()
        except asyncio.CancelledError:
            # Nothing publishes any more before the goodbye empties topics: a state published after the
            # emptying would stay retained, online, for a machine that is gone.
            await _stop(workers + self._command_workers())
            await self._goodbye(client)
            raise
        finally:
            await _stop(workers + self._command_workers())

    async def _goodbye(self, client: aiomqtt.Client) -> None:
        """A clean stop: the devices and the agent show offline (a clean disconnect sends no last will)."""
        # The devices first: another agent takes them over when it sees this agent's status go offline, and its
        # "online" must not be overtaken by this agent's "offline". Each step has its own time limit, so the
        # status (which alone makes every device unavailable in Home Assistant) goes out in any case.
        stopping = sorted(self.owned - self.passing)
        with contextlib.suppress(Exception):
            async with asyncio.timeout(2.0):
                await asyncio.gather(*(client.publish(device_topic(device, "availability"), OFFLINE, qos=1,
                                                      retain=True) for device in stopping))
        # The retained state says so too, for whoever reads the state alone: no machine stays "online" there.
        with contextlib.suppress(Exception):
            async with asyncio.timeout(2.0):
                await asyncio.gather(*(client.publish(device_topic(device, "state"), _dump(self._stopped(device)),
                                                      qos=1, retain=True)
                                       for device in stopping if device in self._last_state))
        with contextlib.suppress(Exception):
            async with asyncio.timeout(2.0):
                await asyncio.gather(*(client.publish(topic, b"", qos=1, retain=True)
                                       for topic in self._passing_topics()))
        with contextlib.suppress(Exception):
            async with asyncio.timeout(2.0):
                await client.publish(agent_topic(self.agent_id, "status"), OFFLINE, qos=1, retain=True)
        if self.passing_agent:
            with contextlib.suppress(Exception):
                async with asyncio.timeout(2.0):
                    await asyncio.gather(*(client.publish(agent_topic(self.agent_id, leaf), b"", qos=1, retain=True)
                                           for leaf in ("status", "info")))

    def _stopped(self, device: str) -> dict[str, Any]:
        """The device's newest state as this agent leaves it: offline, saying why, now."""
        return {**self._last_state[device], "ts": now_iso(), "online": False,
                "summary": offline_summary(f"agent {self.agent_id} stopped")}

    def _passing_topics(self) -> list[str]:
        """What a clean stop empties of the devices that exist only while this agent runs (`RETAINED_TOPICS`):
        this agent's claim on each, even one it only stood by for, and the device's own topics where this agent
        published them and no other live agent claims the device (that agent then takes it over)."""
        topics = []
        for device in sorted(set(self.known) & self.passing):
            if device in self.owned and not self._claimed_by_others(device):
                topics += self._retained_topics(device)
            topics.append(claim_topic(device, self.agent_id))
        return topics

    async def _publish(self, topic: str, payload: str | bytes, *, retain: bool = True, qos: int = 1,
                       properties: Any = None) -> None:
        if self._client is None:
            return
        await self._client.publish(topic, payload, qos=qos, retain=retain, properties=properties)
        # Python 3.11's wait_for (under aiomqtt's publish) can swallow a cancellation that lands as the broker
        # acknowledges: honour it here, or a stopping bridge would wait for the next message forever.
        task = asyncio.current_task()
        if task is not None and task.cancelling():
            raise asyncio.CancelledError

    # ------------------------------------------------------------------------------------------ incoming

    async def _read(self, client: aiomqtt.Client) -> None:
        async for message in client.messages:
            topic = message.topic.value
            payload = message.payload if isinstance(message.payload, bytes) else str(message.payload or "").encode()
            if topic == PING:
                if not message.retain:
                    await self._pong()
                continue
            if topic == HA_STATUS:
                if payload.strip() == ONLINE.encode():
                    for device in sorted(self.owned):
                        await self._publish_discovery(device)
                continue
            if topic == agent_topic(self.agent_id, "sync"):
                if payload.decode("utf-8", "replace") == self._sync_token and not self._synced.is_set():
                    self._synced.set()
                    self._spawn(self._settle())
                continue
            parts = split_device_topic(topic)
            if parts is not None and parts[1] == "command":
                if parts[0] in self.known and not message.retain:  # a retained command would rerun on every start
                    self._queue_command(parts[0], payload, message.properties)
                continue
            if (parts is not None and parts[0] not in self.known and not self._mine(parts[1])
                    and len(self.view.devices) >= FOREIGN_DEVICES):
                continue  # a broker full of other devices (or junk): only this agent's own are followed now
            concerned = self.view.take(topic, payload, now=time.monotonic(), retained=message.retain)
            if not self._synced.is_set():
                continue
            if concerned is not None:
                await self._reconcile(concerned)
            elif split_agent_topic(topic) is not None:
                await self._reconcile_mine()  # an agent came or went: this agent's own devices may change hands

    def _queue_command(self, device: str, payload: bytes, properties: Any) -> None:
        """Into the device's bounded queue (its worker starts with the first command); a full queue's command is
        answered "busy" through the bounded overflow queue, or dropped when that is full too."""
        queue = self._commands.get(device)
        if queue is None:
            queue = self._commands[device] = asyncio.Queue(COMMAND_QUEUE)
            self._spawn(self._run_commands(device, queue))
        try:
            queue.put_nowait((payload, properties))
        except asyncio.QueueFull:
            self.commands_refused += 1
            with contextlib.suppress(asyncio.QueueFull):
                self._overflow.put_nowait((device, payload, properties))

    def _command_workers(self) -> list[asyncio.Task[Any]]:
        return [task for task in self._tasks if not task.done()]

    async def _run_commands(self, device: str, queue: asyncio.Queue[tuple[bytes, Any]]) -> None:
        """One device's commands, one at a time in their order (long actions return once started)."""
        while True:
            payload, properties = await queue.get()
            try:
                await self._command(device, payload, properties)
            except aiomqtt.MqttError:
                raise  # the connection is going: the bridge reconnects and starts new workers
            except Exception as exc:  # one command's failure must not leave the device's queue without a worker
                log.error("MQTT: a command for %s failed: %s", device, str(exc) or type(exc).__name__)

    async def _refuse_overflow(self) -> None:
        while True:
            device, payload, properties = await self._overflow.get()
            await self.connected.wait()
            if device in self.owned:
                reply = self.runner.refuse(device, payload, f"busy: {COMMAND_QUEUE} commands for {device} are "
                                                            "already waiting; send it again later")
                await self._answer(device, reply, properties)

    async def _command(self, device: str, payload: bytes, properties: Any) -> None:
        await self.connected.wait()  # a command that comes while ownership is being settled waits for it
        if device not in self.owned:
            return
        reply = await self.runner.handle(device, payload)
        if reply is None:
            return
        await self._answer(device, reply, properties)

    async def _answer(self, device: str, reply: dict[str, Any], properties: Any) -> None:
        body = _dump(reply)
        await self._publish(device_topic(device, "reply"), body, retain=False)
        response_topic = getattr(properties, "ResponseTopic", None) if properties is not None else None
        if response_topic and not _answerable(str(response_topic)):
            log.warning("MQTT: not answering on %s: a response topic may not be one of fabwire's or Home "
                        "Assistant's own topics", excerpt(str(response_topic), 60))
            response_topic = None
        if response_topic:
            from paho.mqtt.packettypes import PacketTypes
            from paho.mqtt.properties import Properties

            answer = Properties(PacketTypes.PUBLISH)  # type: ignore[no-untyped-call]
            correlation = getattr(properties, "CorrelationData", None)
            if correlation:
                answer.CorrelationData = correlation
            await self._publish(str(response_topic), body, retain=False, properties=answer)

    def _spawn(self, coro: Awaitable[None]) -> None:
        task: asyncio.Task[None] = asyncio.ensure_future(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _settle(self) -> None:
        """Decide ownership once the other agents had time to answer the ping (the broker's retained topics
        are all in by now)."""
        await asyncio.sleep(PING_SETTLE_S)
        self._living = self.view.living(time.monotonic())
        await self._reconcile_all()
        self.connected.set()

    # ------------------------------------------------------------------------------------------ ownership

    def _mine(self, leaf: str) -> bool:
        """Whether a device topic's leaf is this agent's own claim (one left from before must be seen)."""
        return leaf == f"claim/{self.agent_id}"

    async def _reconcile_mine(self) -> None:
        await asyncio.gather(*(self._reconcile(device) for device in sorted(set(self.known) | self.owned)))

    async def _reconcile_all(self) -> None:
        # Concurrently: the client bounds the publishes in flight, and a farm's worth of devices one round trip
        # at a time would take seconds.
        await asyncio.gather(*(self._reconcile(device) for device in sorted(set(self.known) | self.owned)))
        await self._forget_stale_claims()

    async def _reconcile(self, device: str) -> None:
        """Take or hand over `device` as the ownership rule says."""
        now = time.monotonic()
        mine = device in self.known and self.view.owner(device, me=self.agent_id, now=now) == self.agent_id
        if mine and device not in self.owned:
            self.owned.add(device)
            await self._publish_device(device)
        elif not mine and device in self.owned:
            self.owned.discard(device)
            self._pending.pop(device, None)
            self._availability.pop(device, None)
            log.info("MQTT: %s is now published by agent %s", device, self.view.owner(device, now=now))
        elif mine and self._overwritten(device, now):
            # Another agent published the device while it could not see this one alive (a late heartbeat on a
            # loaded machine): the retained info is last-writer-wins, so the owner writes it again. At most once
            # per heartbeat period, so two agents that briefly both believe they own it cannot ping-pong.
            self._reasserted[device] = now
            await self._publish_device(device)

    def _overwritten(self, device: str, now: float) -> bool:
        """Whether the broker's retained info for an owned device names another agent."""
        view = self.view.devices.get(device)
        publisher = view.info.get("agent") if view is not None and view.info is not None else None
        return (publisher is not None and publisher != self.agent_id
                and now - self._reasserted.get(device, -HEARTBEAT_S) >= HEARTBEAT_S)

    async def _forget_stale_claims(self) -> None:
        """Claims this agent left on the broker for devices it no longer monitors (removed while it was away),
        and, on the devices it owns, claims nobody stands behind any more (see `FleetView.stale_claims`)."""
        now = time.monotonic()
        for device, view in list(self.view.devices.items()):
            if self.agent_id in view.claims and device not in self.known:
                await self._remove(device)
            elif device in self.owned:
                for agent in self.view.stale_claims(device, now):
                    log.info("MQTT: clearing agent %s's claim on %s: no heartbeat for %.0f s", agent, device,
                             STALE_CLAIM_S)
                    await self._publish(claim_topic(device, agent), b"")
        await self._sweep_killed_demos()

    async def _sweep_killed_demos(self) -> None:
        """What a killed demo left (`RETAINED_TOPICS`): its claims on the demo's machines once its status is
        offline (its last will) or gone, a demo machine's topics once nobody claims it, and the status and info
        of a killed demo agent that had no state directory (its id is never used again)."""
        now = time.monotonic()
        for device, view in list(self.view.devices.items()):
            if not is_demo_id(device) or device in self.known:
                continue
            dead = sorted(a for a in view.claims if not self.view.online(a))
            for agent in dead:
                if self._sweep(claim_topic(device, agent), now):
                    log.info("MQTT: clearing offline agent %s's claim on the demo machine %s", agent, device)
                    await self._publish(claim_topic(device, agent), b"")
            if (not view.claims - set(dead) and view.info is not None
                    and self._sweep(device_topic(device, "info"), now)):
                log.info("MQTT: clearing the demo machine %s that no agent claims", device)
                for topic in dict.fromkeys(self._retained_topics(device, every_mode=True)):
                    await self._publish(topic, b"")
        for agent, info in list(self.view.agent_info.items()):
            if (agent != self.agent_id and info.get("passing") is True and not self.view.online(agent)
                    and self._sweep(agent_topic(agent, "info"), now)):
                log.info("MQTT: clearing the records of demo agent %s, which was stopped without a goodbye", agent)
                for leaf in ("status", "info"):
                    await self._publish(agent_topic(agent, leaf), b"")

    def _sweep(self, topic: str, now: float) -> bool:
        """Whether to empty `topic` now: at most once per SWEEP_AGAIN_S (a broker whose ACL refuses the emptying
        leaves it there; this agent must not try again every second)."""
        if now - self._swept.get(topic, -SWEEP_AGAIN_S) < SWEEP_AGAIN_S:
            return False
        if len(self._swept) >= FOREIGN_DEVICES:
            self._swept.clear()
        self._swept[topic] = now
        return True

    # ------------------------------------------------------------------------------------------ liveness

    async def _heartbeat(self) -> None:
        self._beats += 1
        await self._publish(agent_topic(self.agent_id, HEARTBEAT), str(self._beats), retain=False)

    async def _heartbeats(self) -> None:
        while True:
            await asyncio.sleep(HEARTBEAT_S)
            await self._heartbeat()

    async def _pong(self) -> None:
        now = time.monotonic()
        if now - self._last_pong >= PONG_INTERVAL_S:
            self._last_pong = now
            await self._heartbeat()

    async def _check_liveness(self) -> None:
        """Hand over or take devices when another agent's heartbeat came or went; clear dead claims."""
        living = self.view.living(time.monotonic())
        if living != self._living:
            self._living = living
            await self._reconcile_all()
        else:
            await self._reconcile_mine()  # also re-asserts a device another agent wrote over meanwhile
            await self._forget_stale_claims()

    async def _publish_device(self, device: str) -> None:
        try:
            state = self.agent.state(device)
        except FabwireError:
            return  # removed from the agent meanwhile: the next scan cleans it up
        info = self.known[device]
        await self._publish(device_topic(device, "info"), _dump({**info, "agent": self.agent_id}))
        await self._publish_discovery(device)
        self._availability.pop(device, None)
        await self._publish_state(device, state)

    async def _publish_discovery(self, device: str) -> None:
        for topic, payload in discovery_messages(self.known[device], self.agent_id, self.dashboard_url,
                                                 self.discovery_mode):
            await self._publish(topic, _dump(payload))

    def _retained_topics(self, device: str, *, every_mode: bool = False) -> list[str]:
        """Every retained topic a device of this agent is published on, its discovery included (its claims aside);
        with `every_mode`, the discovery topics of every discovery mode (another agent's device)."""
        modes = DISCOVERY_MODES if every_mode else (self.discovery_mode,)
        return [*(topic for mode in modes for topic in discovery_topics(device, mode)),
                *(device_topic(device, leaf) for leaf in ("state", "info", "availability"))]

    def _claimed_by_others(self, device: str) -> bool:
        """Whether another live agent claims `device` too (it then keeps the device's topics)."""
        return any(a != self.agent_id and self.view.alive(a, time.monotonic())
                   for a in self.view.devices.get(device, _NO_VIEW).claims)

    async def _remove(self, device: str) -> None:
        """Clean up a device this agent stopped monitoring: its discovery and retained topics go unless another
        online agent still claims it (that agent then takes over); this agent's claim goes in any case."""
        if not self._claimed_by_others(device):
            for topic in self._retained_topics(device):
                await self._publish(topic, b"")
        self.owned.discard(device)
        self._pending.pop(device, None)
        self._availability.pop(device, None)
        self._newest.pop(device, None)
        self._last_state.pop(device, None)
        self.known.pop(device, None)
        await self._publish(claim_topic(device, self.agent_id), b"")

    # ------------------------------------------------------------------------------------------ outgoing

    async def _scan(self) -> None:
        """Claim new devices, clean up removed ones."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(SYNC_TIMEOUT):
                await self._synced.wait()
        if not self._synced.is_set():
            log.warning("MQTT: the broker did not echo this agent's sync message; deciding ownership anyway")
            self._synced.set()
            await self._settle()
        await self.connected.wait()
        while True:
            await self._check_liveness()
            current = self._current_devices()
            for device in sorted(set(self.known) - set(current)):
                await self._remove(device)
            for device, info in sorted(current.items()):
                if device not in self.known:
                    self.known[device] = info
                    await self._publish(claim_topic(device, self.agent_id), b"1")
                    await self._reconcile(device)
                elif info != self.known[device]:
                    self.known[device] = info
                    if device in self.owned:
                        await self._publish_device(device)
            await asyncio.sleep(DEVICE_SCAN_S)

    def _current_devices(self) -> dict[str, dict[str, Any]]:
        return {info.id: info.to_dict() if hasattr(info, "to_dict") else dict(vars(info))
                for info in self.agent.devices()}

    async def _pump(self, events: Any) -> None:
        """The agent's events → latest state per device (published by `_publisher`), availability, events."""
        async for event in events:
            device = event.get("device")
            if device not in self.owned:
                continue
            kind = event.get("type")
            if kind == "state":
                if device not in self._pending:
                    self._dirty.put_nowait(device)
                self._pending[device] = event["state"]
            elif kind in ("online", "offline"):
                if not self._newer(device, event.get("ts")):
                    continue  # older than a state already published: it would flip availability back
                pending = self._pending.get(device)
                if pending is not None and bool(pending.get("online")) != (kind == "online"):
                    del self._pending[device]  # older than this event: publishing it would flip availability back
                if kind == "online" and isinstance(event.get("info"), dict):
                    self.known[device] = event["info"]
                    await self._publish_device(device)
                await self._set_availability(device, kind == "online")
            else:
                await self._publish(device_topic(device, "event"), _dump(event), retain=False)

    async def _publisher(self) -> None:
        """One of a pool that publishes the newest state of each changed device, longest-waiting device first. A
        newer state replaces one still waiting, so a slow broker delays updates but never queues stale ones."""
        while True:
            device = await self._dirty.get()
            state = self._pending.pop(device, None)
            if state is not None and device in self.owned:
                await self._publish_state(device, state)

    def _newer(self, device: str, ts: Any) -> bool:
        """Whether what happened at `ts` is not older than what was published of `device`; it is then the newest."""
        if not isinstance(ts, str):
            return True
        if ts < self._newest.get(device, ""):
            return False
        self._newest[device] = ts
        return True

    async def _publish_state(self, device: str, state: dict[str, Any]) -> None:
        """The state, and the availability when the state's `online` flag changed it; never one older than a state
        already published."""
        if not self._newer(device, state.get("ts")):
            return
        await self._set_availability(device, bool(state.get("online")))
        self._last_state[device] = state
        # QoS 0: TCP delivers it while the connection lasts, a reconnection republishes every state, and a newer
        # state follows within a poll; waiting for an acknowledgement per state would halve a farm's throughput.
        await self._publish(device_topic(device, "state"), _dump(state), qos=0)
        self.states_published += 1

    async def _set_availability(self, device: str, online: bool) -> None:
        value = ONLINE if online else OFFLINE
        if self._availability.get(device) != value:
            self._availability[device] = value
            await self._publish(device_topic(device, "availability"), value)


def _answerable(topic: str) -> bool:
    """Whether a reply may go to an asker's response topic: never onto fabwire's or Home Assistant's own topics
    (a reply published on another device's command topic would run there), nor a topic with wildcards."""
    return not (topic.startswith((f"{PREFIX}/", f"{DISCOVERY_PREFIX}/")) or topic in (PREFIX, DISCOVERY_PREFIX)
                or any(c in topic for c in "+#\0"))


async def _stop(tasks: list[asyncio.Task[Any]]) -> None:
    """Cancel `tasks` and wait a little for them (one still waiting ends when the client disconnects)."""
    for task in tasks:
        if not task.done():
            task.cancel()
        task.add_done_callback(_retrieve)
    if tasks:
        await asyncio.wait(tasks, timeout=2.0)


def _retrieve(task: asyncio.Task[Any]) -> None:
    if not task.cancelled():
        task.exception()


class _NoView:
    claims: frozenset[str] = frozenset()


_NO_VIEW: Any = _NoView()


async def run_bridge(agent: AgentLike, url: str, *, username: str | None = None, password: str | None = None,
                     tls: bool = False, agent_id: str | None = None,
                     on_bridge: Callable[[Bridge], None] | None = None) -> None:
    """Bridge `agent` to the broker at `url` until cancelled. `agent_id` defaults to the host name plus a digest
    of the agent's state directory (stable across restarts). Raises InputError for a bad URL, LinkError when the
    broker refuses the login; a broker that is down or goes away is retried."""
    broker = parse_broker(url, username=username, password=password, tls=tls)
    bridge = Bridge(agent, broker, agent_id or default_agent_id(getattr(agent, "state_dir", None)))
    if on_bridge is not None:
        on_bridge(bridge)
    await bridge.run()
