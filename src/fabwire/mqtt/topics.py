"""The topic layout every fabwire agent shares on a broker, the broker address, and the MQTT client options.

    fabwire/agent/AGENT/status          "online" | "offline"  retained; the broker publishes "offline" (last will)
    fabwire/agent/AGENT/info            {"agent", "host", "version", "ts"}  retained
    fabwire/agent/AGENT/heartbeat       a counter, every HEARTBEAT_S seconds and in answer to a ping (not retained)
    fabwire/ping                        anyone asks every agent for a heartbeat now (not retained)
    fabwire/device/DEVICE/claim/AGENT   "1"  retained while AGENT monitors DEVICE (empty = released)
    fabwire/device/DEVICE/info          DeviceInfo + {"agent"}  retained, by the device's owner
    fabwire/device/DEVICE/state         the agent's state (`--json` schema, "ts", "online")  retained, by the owner
                                        (at its clean stop: the last state again, offline, "agent AGENT stopped")
    fabwire/device/DEVICE/availability  "online" | "offline"  retained, by the owner
    fabwire/device/DEVICE/event         each event, job and error as JSON (not retained)
    fabwire/device/DEVICE/command       {"action", "params", "id"} or a bare action name: run by the owner
    fabwire/device/DEVICE/reply         {"id", "action", "ok", "result" | "error", "exit_code", "agent"}
    homeassistant/device/fabwire_DEVICE/config   Home Assistant device discovery (retained; empty = removed)
    homeassistant/status                Home Assistant's own "online" announcement

DEVICE is the agent's device id (`{kind}-{serial}`, so the same machine has the same id on every agent).
"""

from __future__ import annotations

import hashlib
import re
import socket
import ssl
import urllib.parse
from dataclasses import dataclass
from typing import Any

from fabwire.errors import InputError, excerpt

PREFIX = "fabwire"
DISCOVERY_PREFIX = "homeassistant"
HA_STATUS = f"{DISCOVERY_PREFIX}/status"
ONLINE = "online"
OFFLINE = "offline"
DEFAULT_PORT = 1883
DEFAULT_TLS_PORT = 8883
OUTGOING_CALLS = 128
HEARTBEAT = "heartbeat"
HEARTBEAT_S = 5.0
"""Seconds between an agent's heartbeats: what proves a claimant alive (see `fabwire.mqtt.fleet_view`)."""
PING = f"{PREFIX}/ping"
MAX_COMMAND_BYTES = 64 * 1024
"""Largest command payload run: a command is an action name and a few parameters."""
MAX_RETAINED_BYTES = 1024 * 1024
"""Largest retained info or state payload read from the broker (fabwire's own states are a few kilobytes)."""
INCOMING_QUEUE = 8192
"""Messages the bridge's MQTT client holds for its reader; a flood beyond it is dropped, not kept."""


DEMO_GONE = "a demo's DEVICE (`fabwire.agent.core.is_demo_id`)"
RETAINED_TOPICS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("fabwire/agent/AGENT/status", "AGENT (online); the broker, AGENT's last will (offline)",
     ("AGENT at its clean stop, when it is a demo with no state directory (a new id each run)",
      "any agent, once AGENT (such a demo, its info says `passing`) is offline: it was killed")),
    ("fabwire/agent/AGENT/info", "AGENT",
     ("AGENT at its clean stop, when it is a demo with no state directory (a new id each run)",
      "any agent, once AGENT (such a demo, its info says `passing`) is offline: it was killed")),
    ("fabwire/device/DEVICE/claim/AGENT", "AGENT, while it monitors DEVICE",
     ("AGENT when it stops monitoring DEVICE",
      f"AGENT at its clean stop, for {DEMO_GONE}",
      "DEVICE's owner, once AGENT has not been alive for `fleet_view.STALE_CLAIM_S`",
      f"any agent, for {DEMO_GONE}, once AGENT's status is offline or gone")),
    ("fabwire/device/DEVICE/info, state, availability", "DEVICE's owner",
     ("the owner when it stops monitoring DEVICE, unless another live agent claims it",
      f"the owner at its clean stop, for {DEMO_GONE}, unless another live agent claims it",
      f"any agent, for {DEMO_GONE} that no agent claims any more")),
    ("homeassistant/device/fabwire_DEVICE/config (or one per entity)", "DEVICE's owner",
     ("the owner when it stops monitoring DEVICE, unless another live agent claims it",
      f"the owner at its clean stop, for {DEMO_GONE}, unless another live agent claims it",
      f"any agent, for {DEMO_GONE} that no agent claims any more")),
)
"""Every retained topic an agent publishes: (topic, who publishes it, who empties it and when). A demo's machines
and a demo agent with no state directory exist for one run, so their records go with it, even when it was killed;
everything else stays (offline) until its own agent removes it."""


def agent_topic(agent: str, leaf: str) -> str:
    return f"{PREFIX}/agent/{agent}/{leaf}"


def device_topic(device: str, leaf: str) -> str:
    return f"{PREFIX}/device/{device}/{leaf}"


def claim_topic(device: str, agent: str) -> str:
    return f"{PREFIX}/device/{device}/claim/{agent}"


def discovery_topic(device: str) -> str:
    return f"{DISCOVERY_PREFIX}/device/{object_id(device)}/config"


def object_id(device: str) -> str:
    """Home Assistant's node/object ids allow letters, digits, '_' and '-' only."""
    return "fabwire_" + re.sub(r"[^A-Za-z0-9_-]", "_", device)


def split_device_topic(topic: str) -> tuple[str, str] | None:
    """`fabwire/device/DEVICE/LEAF…` → (DEVICE, "LEAF…"), else None."""
    parts = topic.split("/", 3)
    if len(parts) == 4 and parts[0] == PREFIX and parts[1] == "device" and parts[2]:
        return parts[2], parts[3]
    return None


def split_agent_topic(topic: str) -> tuple[str, str] | None:
    parts = topic.split("/", 3)
    if len(parts) == 4 and parts[0] == PREFIX and parts[1] == "agent" and parts[2]:
        return parts[2], parts[3]
    return None


def slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "agent"


def default_agent_id(state_dir: object | None = None) -> str:
    """The host name, plus a short digest of the agent's state directory so two agents on one computer differ;
    the same agent keeps its id across restarts."""
    host = slug(socket.gethostname())
    if state_dir is None:
        return host
    return f"{host}-{hashlib.sha256(str(state_dir).encode()).hexdigest()[:6]}"


CONNECT_TIMEOUT_S = 10.0
"""How long a broker has to answer a connection."""
BROKER_CHECK = "that an MQTT broker listens there (port 1883, 8883 with TLS) on this network"
MQTT_OFF = "the MQTT bridge is off until `fabwire serve` is started again with a broker's address"
"""Said once when the broker's address answers as another kind of server: asking it again would not mend that."""
"""What to check when a broker's address answers nothing a broker says (nothing at all, or another protocol)."""


@dataclass(frozen=True)
class Broker:
    """Where the broker is and how to log in."""

    host: str
    port: int
    username: str | None = None
    password: str | None = None
    tls: bool = False

    @property
    def url(self) -> str:
        return f"{'mqtts' if self.tls else 'mqtt'}://{self.host}:{self.port}"

    def failure(self, exc: BaseException) -> str:
        """What went wrong with the broker, in words: a connection that failed says what to check, as for a
        device (`fabwire.transport.tcp.connect_failure`); any other MQTT error in the client's words."""
        cause = exc.__cause__ or exc.__context__
        if isinstance(cause, OSError):
            from fabwire.transport.tcp import connect_failure

            return f"MQTT broker {self.url}: {connect_failure(cause, self.host, self.port, peer=BROKER_CHECK)}"
        return f"MQTT broker {self.url}: {exc}"

    async def not_a_broker(self) -> str | None:
        """What answers at the broker's address when it is no MQTT broker, in words with what to check (see
        `fabwire.mqtt.probe`); None when a broker answers, or nothing does. Over TLS the handshake tells at once."""
        from fabwire.mqtt.probe import SILENT

        found = await self.foreign_peer()
        if found == SILENT:
            from fabwire.transport.tcp import connect_failure

            return f"MQTT broker {self.url}: {connect_failure(TimeoutError(), self.host, self.port, peer=BROKER_CHECK)}"
        return None if found is None else f"MQTT broker {self.url}: {found}; check {BROKER_CHECK}"

    async def foreign_peer(self) -> str | None:
        """Why the server at the broker's address is another kind of server (`fabwire.mqtt.probe.not_a_broker`);
        `fabwire.mqtt.probe.SILENT` when it said nothing; None when a broker answered or nothing was reached (or over
        TLS)."""
        if self.tls:
            return None
        from fabwire.mqtt.probe import not_a_broker

        return await not_a_broker(self.host, self.port, username=self.username, password=self.password,
                                  timeout_s=CONNECT_TIMEOUT_S)

    def client_options(self) -> dict[str, Any]:
        """Keyword arguments for `aiomqtt.Client` (MQTT 5: replies carry the asker's correlation data)."""
        import aiomqtt

        options: dict[str, Any] = {"hostname": self.host, "port": self.port, "username": self.username,
                                   "password": self.password, "protocol": aiomqtt.ProtocolVersion.V5,
                                   "timeout": CONNECT_TIMEOUT_S, "keepalive": 30,
                                   # aiomqtt scans its pending calls on every publish: bounding them keeps a
                                   # burst of states linear, while enough stay in flight per event-loop turn for
                                   # 500 states a second on a loaded machine (see bench_mqtt_fleet).
                                   "max_concurrent_outgoing_calls": OUTGOING_CALLS,
                                   "max_inflight_messages": OUTGOING_CALLS}
        if self.tls:
            options["tls_context"] = ssl.create_default_context()
        return options


_USERINFO = re.compile(r"^(?P<head>\s*(?:[A-Za-z][A-Za-z0-9+.-]*://)?[^@/?#:]*):[^/?#]*@")


def redact_password(url: str) -> str:
    """`url` with the password of its `user:password@` part shown as `***`, for messages and logs (a service's
    journal or a CI log must not keep it)."""
    return _USERINFO.sub(lambda m: f"{m.group('head')}:***@", url, count=1)


def parse_broker(url: str, *, username: str | None = None, password: str | None = None,
                 tls: bool = False) -> Broker:
    """`mqtt://host[:port]` (1883), `mqtts://host[:port]` (TLS, 8883) or a bare `host[:port]`; user and password
    may be in the URL. InputError for anything else."""
    text = url.strip()
    if "://" not in text:
        text = "mqtt://" + text
    shown = excerpt(redact_password(url), 80)
    try:
        parts = urllib.parse.urlsplit(text)
        port = parts.port
    except ValueError as exc:
        raise InputError(f"MQTT broker {shown}: {exc}") from None  # the parser's reason names the port, no more
    if parts.scheme not in ("mqtt", "mqtts", "tcp", "ssl") or not parts.hostname:
        raise InputError(f"MQTT broker must look like mqtt://host[:port] or mqtts://host[:port], not {shown}")
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise InputError(f"MQTT broker {shown}: a broker address has no path or query")
    secure = tls or parts.scheme in ("mqtts", "ssl")
    return Broker(parts.hostname, port or (DEFAULT_TLS_PORT if secure else DEFAULT_PORT),
                  username if username is not None else (urllib.parse.unquote(parts.username)
                                                         if parts.username else None),
                  password if password is not None else (urllib.parse.unquote(parts.password)
                                                         if parts.password else None),
                  secure)
