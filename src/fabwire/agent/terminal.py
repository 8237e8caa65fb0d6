"""What `fabwire serve` says on its terminal while it runs: one `fabwire: …` line on stderr when something the
owner must know about changes, never once per retry. Lines go through a writer thread (`fabwire.logsink`), so a
stderr nobody reads never stalls the agent."""

from __future__ import annotations

import logging
import sys
from typing import Any

TERMINAL_LINES: tuple[tuple[str, str, str, str], ...] = (
    ("machine-offline", "a machine's first attempt fails, its link is lost, or its failure turns into another "
     "kind (another exit code: unreachable, silent, not this kind of machine …)",
     "fabwire: NAME: REASON", "the agent's `offline` event (`fabwire.agent.core`)"),
    ("machine-online", "a machine answers again after a machine-offline line", "fabwire: NAME: online again",
     "the agent's `online` event"),
    ("broker-failed", "the MQTT broker cannot be reached or drops the connection, the first time or in other words "
     "than the last line", "fabwire: MQTT broker URL: REASON; retrying in S s", "`Bridge.on_trouble`"),
    ("broker-connected", "the MQTT broker takes the connection (on stdout, as where the agent listens)",
     "fabwire agent publishing to URL as agent ID", "`Bridge.on_connected`"),
)
"""Every line `serve` prints while it runs: (kind, when, line, source). Start-up lines (where it listens, the token,
machines it cannot monitor) come before these."""


def terminal_log() -> logging.Logger:
    """The logger whose records are the `fabwire: …` lines (on stderr, through a writer thread), made once."""
    say = logging.getLogger("fabwire.terminal")
    if not say.handlers:
        from fabwire.logsink import non_blocking_handler

        say.addHandler(non_blocking_handler(sys.stderr, logging.Formatter("fabwire: %(message)s")))
        say.propagate = False
        say.setLevel(logging.INFO)
    return say


class Terminal:
    """Turns the agent's events and the MQTT bridge's troubles into `TERMINAL_LINES`."""

    def __init__(self, say: logging.Logger | None = None) -> None:
        self.say = say or terminal_log()
        self._machines: dict[str, int] = {}
        """Machines said to be offline: device id → the exit code of the failure said."""
        self._broker: str | None = None

    def event(self, event: dict[str, Any], name: str) -> None:
        """One agent event about the machine `name`."""
        device = str(event.get("device"))
        if event.get("type") == "offline":
            code = event.get("exit_code", 8)
            if self._machines.get(device) != code:
                self._machines[device] = code
                self.say.warning("%s: %s", name, event.get("reason") or "offline")
        elif event.get("type") == "online" and self._machines.pop(device, None) is not None:
            self.say.warning("%s: online again", name)

    def broker_trouble(self, failure: str, retry_in_s: float) -> None:
        """Why the MQTT bridge is not connected, said once per reason; `retry_in_s` below 0: it has given up."""
        if failure != self._broker:
            self._broker = failure
            if retry_in_s < 0:
                from fabwire.mqtt.topics import MQTT_OFF

                self.say.error("%s; %s", failure, MQTT_OFF)
            else:
                self.say.warning("%s; retrying in %.1f s", failure, retry_in_s)

    def broker_connected(self) -> None:
        self._broker = None

    async def run(self, agent: Any) -> None:
        """Follow `agent`'s events until cancelled."""
        subscription = agent.subscribe(None)
        try:
            async for event in subscription:
                if event.get("type") in ("offline", "online"):
                    try:
                        name = agent.session(event["device"]).spec.name
                    except Exception:  # removed meanwhile
                        name = event["device"]
                    self.event(event, name)
        finally:
            subscription.close()
