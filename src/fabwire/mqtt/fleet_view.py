"""What the broker says about the fleet: which agents are online, which agents claim which device, and each
device's retained info, state and availability. Every agent builds the same view from the same retained topics,
so every agent agrees on who owns a device without talking to the others.

Ownership rule: of the agents that claim a device and are alive, the one whose id sorts first owns it. Alive means
provably so: the agent's retained status says "online" (the broker replaces it with "offline", the agent's last
will, when its connection dies) AND a heartbeat from it arrived live within `HEARTBEAT_TTL_S`. A retained
status and claim alone prove nothing (anyone with publish rights can leave them, and a crashed agent whose will
was lost leaves them too), so such a claimant never wins, and its claim is cleared once it has stayed silent for
`STALE_CLAIM_S`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from fabwire.errors import InputError
from fabwire.jsontext import parse_json
from fabwire.mqtt.topics import (
    HEARTBEAT,
    HEARTBEAT_S,
    MAX_RETAINED_BYTES,
    OFFLINE,
    ONLINE,
    split_agent_topic,
    split_device_topic,
)

HEARTBEAT_TTL_S = 3 * HEARTBEAT_S + 1.0
"""An agent whose last live heartbeat is older than this is not alive (three heartbeats missed, plus slack)."""
STALE_CLAIM_S = 600.0
"""A claimant not alive for this long has its retained claim cleared by the device's owner; a real agent
republishes its claims whenever it connects, so only a dead or phantom claim goes for good."""


@dataclass
class DeviceView:
    info: dict[str, Any] | None = None
    state: dict[str, Any] | None = None
    availability: str | None = None
    claims: set[str] = field(default_factory=set)


def _json(payload: bytes) -> dict[str, Any] | None:
    try:
        value = parse_json(payload, what="a retained payload", max_bytes=MAX_RETAINED_BYTES)
    except InputError:
        return None
    return value if isinstance(value, dict) else None


@dataclass
class FleetView:
    agents: dict[str, str] = field(default_factory=dict)
    """Agent id → "online" | "offline"."""
    agent_info: dict[str, dict[str, Any]] = field(default_factory=dict)
    devices: dict[str, DeviceView] = field(default_factory=dict)
    heartbeats: dict[str, float] = field(default_factory=dict)
    """Agent id → when (the caller's monotonic clock) its last live heartbeat arrived."""
    started: float | None = None
    """When this view began to listen: the start of every claimant's silence that it has not heard from."""

    def take(self, topic: str, payload: bytes, *, now: float = 0.0, retained: bool = False) -> str | None:
        """Fold one message in; returns the device id it concerned (None for agent topics or foreign ones).
        `now` is the caller's monotonic time and `retained` whether the broker replayed the message from its
        store (a replayed heartbeat proves nothing). Malformed payloads are ignored: the broker is shared, and
        anyone may publish nonsense on it."""
        if self.started is None:
            self.started = now
        agent_part = split_agent_topic(topic)
        if agent_part is not None:
            agent, leaf = agent_part
            if leaf == HEARTBEAT:
                if not retained and "/" not in agent:
                    self.heartbeats[agent] = now
            elif leaf == "status":
                text = payload.decode("utf-8", "replace").strip()
                if text in (ONLINE, OFFLINE):
                    self.agents[agent] = text
                elif not payload:
                    self.agents.pop(agent, None)
            elif leaf == "info":
                info = _json(payload)
                if info is not None:
                    self.agent_info[agent] = info
                else:
                    self.agent_info.pop(agent, None)
            return None
        device_part = split_device_topic(topic)
        if device_part is None:
            return None
        device, leaf = device_part
        view = self.devices.setdefault(device, DeviceView())
        if leaf.startswith("claim/"):
            agent = leaf.removeprefix("claim/")
            if payload and agent and "/" not in agent:
                view.claims.add(agent)
            else:
                view.claims.discard(agent)
        elif leaf == "info":
            view.info = _json(payload)
        elif leaf == "state":
            view.state = _json(payload)
        elif leaf == "availability":
            text = payload.decode("utf-8", "replace").strip()
            view.availability = text if text in (ONLINE, OFFLINE) else None
        if view.info is None and view.state is None and not view.claims and view.availability is None:
            del self.devices[device]
        return device

    def online(self, agent: str) -> bool:
        """What the agent's retained status says (its own word, or its last will)."""
        return self.agents.get(agent) == ONLINE

    def alive(self, agent: str, now: float) -> bool:
        """Online by its status and heard from live within `HEARTBEAT_TTL_S` of `now`."""
        beat = self.heartbeats.get(agent)
        return self.online(agent) and beat is not None and now - beat <= HEARTBEAT_TTL_S

    def living(self, now: float) -> frozenset[str]:
        """Every agent alive at `now` (compare two calls to see who came or went)."""
        return frozenset(agent for agent in self.agents if self.alive(agent, now))

    def stale_claims(self, device: str, now: float) -> list[str]:
        """Claimants of `device` not alive and silent for at least `STALE_CLAIM_S` (since their last heartbeat,
        or since this view began to listen if it never heard one): claims nobody stands behind."""
        view = self.devices.get(device)
        if view is None:
            return []
        stale = []
        for agent in sorted(view.claims):
            if self.alive(agent, now):
                continue
            since = self.heartbeats.get(agent, self.started if self.started is not None else now)
            if now - since >= STALE_CLAIM_S:
                stale.append(agent)
        return stale

    def owner(self, device: str, *, me: str | None = None, now: float | None = None) -> str | None:
        """The agent that publishes and commands `device`: the first, by id, of its alive claimants (`me`
        counts as alive, and as a claimant, whatever the broker has echoed so far). Without `now`, as a reader
        that heard no heartbeats judges: by the agents' status alone."""
        view = self.devices.get(device)
        claims = set(view.claims) if view else set()
        if me is not None:
            claims.add(me)
        live = sorted(a for a in claims if a == me or (self.online(a) if now is None else self.alive(a, now)))
        return live[0] if live else None

    def rows(self, now: float | None = None) -> list[dict[str, Any]]:
        """One row per device seen on the broker, for `fabwire fleet`; with `now`, agents count as online only
        while alive (see `alive`)."""
        def up(agent: str) -> bool:
            return self.online(agent) if now is None else self.alive(agent, now)

        out = []
        for device, view in sorted(self.devices.items()):
            info = view.info or {}
            state = view.state or {}
            summary = state.get("summary") if isinstance(state.get("summary"), dict) else {}
            owner = self.owner(device, now=now) or (info.get("agent") if isinstance(info.get("agent"), str) else None)
            out.append({
                "device": device, "name": info.get("name"), "kind": info.get("kind"), "model": info.get("model"),
                "serial": info.get("serial"), "agent": owner,
                "agent_online": bool(owner and up(owner)),
                "standby": sorted(a for a in view.claims if a != owner and up(a)),
                "availability": view.availability if owner and up(owner) else OFFLINE,
                "state": summary.get("state") if summary else None, "ts": state.get("ts"),
            })
        return out
