"""Commands arriving on `fabwire/device/DEVICE/command`: parsing, running them once, and the reply.

A command is a JSON object `{"action": NAME, "params": {...}, "id": ANY}` or a bare action name (what a Home
Assistant button sends). Commands arrive with QoS 1, which the broker may deliver more than once: a command with
an `id` runs once however often it arrives (a repeat gets the first reply again), and the reply echoes the `id`.
MQTT 5 askers may instead give a response topic and correlation data; the reply goes there too.
"""

from __future__ import annotations

import json
import re
from collections import OrderedDict
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from fabwire.errors import DeviceBusy, FabwireError, InputError, excerpt
from fabwire.jsontext import parse_json
from fabwire.mqtt.topics import MAX_COMMAND_BYTES

ACTION_NAME = re.compile(r"[a-z][a-z0-9_]{0,63}")
REMEMBERED = 4096
"""Command ids remembered per agent for de-duplication."""

Act = Callable[[str, str, dict[str, Any]], Awaitable[dict[str, Any]]]


@dataclass(frozen=True)
class Command:
    action: str
    params: dict[str, Any]
    id: Any = None


def parse_command(payload: bytes) -> Command:
    """The command in a payload of at most `MAX_COMMAND_BYTES`; InputError saying what is wrong with it."""
    if len(payload) > MAX_COMMAND_BYTES:
        raise InputError(f"a command is at most {MAX_COMMAND_BYTES} bytes, not {len(payload)}")
    try:
        text = payload.decode("utf-8").strip()
    except UnicodeDecodeError:
        raise InputError("a command must be UTF-8 text") from None
    if not text:
        raise InputError("empty command")
    if not text.startswith("{"):
        if not ACTION_NAME.fullmatch(text):
            raise InputError(f"a command is a JSON object or an action name, not {excerpt(text, 40)}")
        return Command(text, {})
    data = parse_json(text, what="a command")
    if not isinstance(data, dict):
        raise InputError("a command must be a JSON object")
    action, params = data.get("action"), data.get("params", {})
    if not isinstance(action, str) or not action:
        raise InputError('a command needs "action": the name of an action')
    if not isinstance(params, dict):
        raise InputError('"params" must be a JSON object')
    return Command(action, params, data.get("id"))


def _exit_code(exc: BaseException) -> int:
    from fabwire.agent.core import exit_code_of

    return exit_code_of(exc)


class CommandRunner:
    """Runs commands through `act`, each id once, and builds the replies."""

    def __init__(self, act: Act, agent_id: str) -> None:
        self._act = act
        self._agent_id = agent_id
        self._replies: OrderedDict[tuple[str, str], dict[str, Any] | None] = OrderedDict()
        self.executed = 0
        """Commands actually run (repeats of an id not counted)."""

    async def handle(self, device: str, payload: bytes) -> dict[str, Any] | None:
        """The reply to publish, or None for a repeat still running (its reply is on the way)."""
        try:
            command = parse_command(payload)
        except InputError as exc:
            return self._reply(device, None, None, error=exc)
        key = (device, json.dumps(command.id, sort_keys=True)) if command.id is not None else None
        if key is not None and key in self._replies:
            return self._replies[key]
        if key is not None:
            self._replies[key] = None  # running: a repeat arriving meanwhile is dropped
            while len(self._replies) > REMEMBERED:
                self._replies.popitem(last=False)
        self.executed += 1
        try:
            result = await self._act(device, command.action, command.params)
        except (FabwireError, TimeoutError, ConnectionError) as exc:
            reply = self._reply(device, command, None, error=exc)
        else:
            reply = self._reply(device, command, result)
        if key is not None:
            self._replies[key] = reply
        return reply

    def refuse(self, device: str, payload: bytes, reason: str) -> dict[str, Any]:
        """The reply to a command that is not run (its id and action echoed when the payload gives them)."""
        try:
            command: Command | None = parse_command(payload)
        except InputError:
            command = None
        return self._reply(device, command, None, error=DeviceBusy(reason))

    def _reply(self, device: str, command: Command | None, result: dict[str, Any] | None, *,
               error: BaseException | None = None) -> dict[str, Any]:
        reply: dict[str, Any] = {"device": device, "agent": self._agent_id,
                                 "id": command.id if command else None,
                                 "action": command.action if command else None, "ok": error is None}
        if error is None:
            reply["result"] = result
        else:
            reply["error"] = str(error) or type(error).__name__
            reply["exit_code"] = _exit_code(error)
        return reply
