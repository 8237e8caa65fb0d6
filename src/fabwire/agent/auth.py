"""The access token: generated on first use, kept in the state directory (mode 0600), checked on every API call.

Clients send `Authorization: Bearer TOKEN`. Browsers cannot set headers on a WebSocket, so the dashboard offers
the token as a second WebSocket subprotocol, `fabwire.token.TOKEN` (the `Sec-WebSocket-Protocol` header).
"""

from __future__ import annotations

import hmac
import ipaddress
import json
import os
import secrets
from pathlib import Path
from typing import Any

from fabwire.errors import ConfigError

TOKEN_FILE = "access-token"
SUBPROTOCOL = "fabwire"
TOKEN_PREFIX = "fabwire.token."
Scope = dict[str, Any]
ASGIApp = Any


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def load_or_create_token(state_dir: Path) -> tuple[str, bool]:
    """(the token, whether it was created now — the only time it is shown)."""
    path = state_dir / TOKEN_FILE
    try:
        token = path.read_text(encoding="ascii").strip()
        if token:
            return token, False
    except FileNotFoundError:
        pass
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read the access token {path}: {exc}") from None
    token = secrets.token_urlsafe(32)
    try:
        state_dir.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w", encoding="ascii") as fh:
            fh.write(token + "\n")
    except OSError as exc:
        raise ConfigError(f"cannot write the access token {path}: {exc.strerror or exc}") from None
    return token, True


def _header(scope: Scope, name: bytes) -> str:
    for key, value in scope.get("headers", []):
        if key == name:
            return bytes(value).decode("latin-1")
    return ""


def presented_token(scope: Scope) -> str:
    auth = _header(scope, b"authorization")
    if auth.lower().startswith("bearer "):
        return auth[7:].strip()
    for proto in _header(scope, b"sec-websocket-protocol").split(","):
        proto = proto.strip()
        if proto.startswith(TOKEN_PREFIX):
            return proto[len(TOKEN_PREFIX):]
    return ""


class TokenGuard:
    """ASGI middleware: every /api/ request and WebSocket must carry the token; the page itself is public
    (it holds no data and asks for the token)."""

    def __init__(self, app: ASGIApp, token: str) -> None:
        self.app = app
        self.token = token.encode()

    async def __call__(self, scope: Scope, receive: Any, send: Any) -> None:
        presented = presented_token(scope) if scope["type"] in ("http", "websocket") else ""
        if scope["type"] in ("http", "websocket") and scope["path"].startswith("/api/") and \
                not hmac.compare_digest(presented.encode(), self.token):
            problem = ("the access token sent is not this agent's" if presented
                       else "this agent needs its access token")
            body = json.dumps({"message": f"{problem}: send the header 'Authorization: Bearer TOKEN' (the token is "
                                          f"in the agent's state directory, file {TOKEN_FILE})",
                               "exit_code": 3, "error": "AccessDenied"}).encode()
            headers = [(b"content-type", b"application/json"), (b"www-authenticate", b"Bearer")]
            if scope["type"] == "http":
                prefix = "http"
            elif "websocket.http.response" in scope.get("extensions", {}):
                prefix = "websocket.http"
            else:  # a server without the denial-response extension: close the handshake (HTTP 403)
                await send({"type": "websocket.close", "code": 4401, "reason": "access token required"})
                return
            await send({"type": f"{prefix}.response.start", "status": 401, "headers": headers})
            await send({"type": f"{prefix}.response.body", "body": body})
            return
        await self.app(scope, receive, send)
