"""What the broker says about the fleet: which agents are online, which agents claim which device, and each
device's retained info, state and availability. Every agent builds the same view from the same retained topics,
so every agent agrees on who owns a device without talking to the others.

Ownership rule: of the agents that claim a device and are online, the one whose id sorts first owns it. An agent
whose broker connection dies is marked offline by its last will, and the next claimant takes over.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from fabwire.mqtt.topics import OFFLINE, ONLINE, split_agent_topic, split_device_topic


@dataclass
class DeviceView:
    info: dict[str, Any] | None = None
    state: dict[str, Any] | None = None
    availability: str | None = None
    claims: set[str] = field(default_factory=set)


def _json(payload: bytes) -> dict[str, Any] | None:
    try:
        value = json.loads(payload)
    except (ValueError, UnicodeDecodeError):
        return None
    return value if isinstance(value, dict) else None


@dataclass
class FleetView:
    agents: dict[str, str] = field(default_factory=dict)
    """Agent id → "online" | "offline"."""
    agent_info: dict[str, dict[str, Any]] = field(default_factory=dict)
    devices: dict[str, DeviceView] = field(default_factory=dict)

    def take(self, topic: str, payload: bytes) -> str | None:
        """Fold one message in; returns the device id it concerned (None for agent topics or foreign ones).
        Malformed payloads are ignored: the broker is shared, and anyone may publish nonsense on it."""
        agent_part = split_agent_topic(topic)
        if agent_part is not None:
            agent, leaf = agent_part
            if leaf == "status":
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
        return self.agents.get(agent) == ONLINE

    def owner(self, device: str, *, me: str | None = None) -> str | None:
        """The agent that publishes and commands `device`: the first, by id, of its online claimants (`me`
        counts as online, and as a claimant, whatever the broker has echoed so far)."""
        view = self.devices.get(device)
        claims = set(view.claims) if view else set()
        if me is not None:
            claims.add(me)
        live = sorted(a for a in claims if a == me or self.online(a))
        return live[0] if live else None

    def rows(self) -> list[dict[str, Any]]:
        """One row per device seen on the broker, for `fabwire fleet`."""
        out = []
        for device, view in sorted(self.devices.items()):
            info = view.info or {}
            state = view.state or {}
            summary = state.get("summary") if isinstance(state.get("summary"), dict) else {}
            owner = self.owner(device) or (info.get("agent") if isinstance(info.get("agent"), str) else None)
            out.append({
                "device": device, "name": info.get("name"), "kind": info.get("kind"), "model": info.get("model"),
                "serial": info.get("serial"), "agent": owner,
                "agent_online": bool(owner and self.online(owner)),
                "standby": sorted(a for a in view.claims if a != owner and self.online(a)),
                "availability": view.availability if owner and self.online(owner) else OFFLINE,
                "state": summary.get("state") if summary else None, "ts": state.get("ts"),
            })
        return out
