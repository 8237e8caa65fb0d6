"""Application keys: a slicer or Home Assistant asks for the access token, the owner approves it on the dashboard.

The flow is OctoPrint's Application Keys plugin (docs.octoprint.org, "Application Keys plugin"): the app asks
(`POST …/plugin/appkeys/request {"app": NAME}`, answered 201 with an `app_token` and a `Location` to poll), polls
(`GET …/plugin/appkeys/request/APP_TOKEN`: 202 while undecided, 200 `{"api_key"}` once approved, 404 when denied
or expired) while the owner sees the request on the dashboard and approves or denies it. The key handed out is
the agent's access token (the one `X-Api-Key` and `Authorization: Bearer` carry).
"""

from __future__ import annotations

import secrets
import time
from dataclasses import dataclass, field
from pathlib import Path

from fabwire.agent.auth import load_or_create_token
from fabwire.errors import InputError, excerpt

PENDING_MAX = 20
"""Undecided requests kept at most (the oldest goes first): asking costs an attacker nothing."""
EXPIRES_S = 600.0
"""An undecided request lapses after ten minutes; a decision can be fetched for as long again."""
APP_NAME_MAX = 80


def _shown(text: str) -> str:
    """An app's own name for itself, printable and short, as the dashboard shows it."""
    return "".join(c for c in text.strip() if c.isprintable())[:APP_NAME_MAX] or "?"


class UnknownRequest(InputError):
    """No pending application-key request with that token (HTTP 404)."""


@dataclass
class KeyRequest:
    token: str
    app: str
    user: str | None
    remote: str
    created: float = field(default_factory=time.monotonic)
    created_wall: float = field(default_factory=time.time)
    decision: bool | None = None
    decided: float = 0.0

    def to_dict(self) -> dict[str, object]:
        return {"id": self.token, "app": self.app, "user": self.user, "remote": self.remote,
                "requested": self.created_wall,
                "state": {None: "pending", True: "approved", False: "denied"}[self.decision]}


class AppKeys:
    def __init__(self, state_dir: Path | None) -> None:
        self.state_dir = state_dir
        self._requests: dict[str, KeyRequest] = {}
        self._fallback = secrets.token_urlsafe(32)
        """The key handed out by an agent without a state directory (a test's), which checks no token."""

    def request(self, app: object, user: object, remote: str) -> KeyRequest:
        if not isinstance(app, str) or not app.strip():
            raise InputError('send {"app": "the application\'s name"} as JSON')
        self._expire()
        while len(self._requests) >= PENDING_MAX:
            del self._requests[min(self._requests, key=lambda t: self._requests[t].created)]
        request = KeyRequest(secrets.token_urlsafe(16), _shown(app), _shown(user) if isinstance(user, str) else None,
                             remote)
        self._requests[request.token] = request
        return request

    def poll(self, token: str) -> tuple[int, dict[str, str]]:
        """(HTTP status, body) for an app polling its request."""
        self._expire()
        request = self._requests.get(token)
        if request is None or request.decision is False:
            return 404, {"message": "no such request, or it was denied or has expired"}
        if request.decision is None:
            return 202, {"message": "awaiting the owner's decision on the dashboard"}
        return 200, {"api_key": self.key()}

    def pending(self) -> list[dict[str, object]]:
        self._expire()
        return [r.to_dict() for r in self._requests.values() if r.decision is None]

    def decide(self, token: str, approve: bool) -> dict[str, object]:
        self._expire()
        request = self._requests.get(token)
        if request is None or request.decision is not None:
            raise UnknownRequest(f"no pending key request {excerpt(token, 40)}")
        request.decision = approve
        request.decided = time.monotonic()
        return request.to_dict()

    def key(self) -> str:
        if self.state_dir is None:
            return self._fallback
        return load_or_create_token(self.state_dir)[0]

    def _expire(self) -> None:
        now = time.monotonic()
        for token, request in list(self._requests.items()):
            since = request.decided if request.decision is not None else request.created
            if now - since > EXPIRES_S:
                del self._requests[token]
