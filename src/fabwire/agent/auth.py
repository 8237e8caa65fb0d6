"""The access token: generated on first use, kept in the state directory (mode 0600); the boundary
(`fabwire.agent.boundary`) checks it on every request.

Clients send `Authorization: Bearer TOKEN` or `X-Api-Key: TOKEN`. Browsers cannot set headers on a WebSocket, so
the dashboard offers the token as a second WebSocket subprotocol, `fabwire.token.TOKEN` (`Sec-WebSocket-Protocol`).
"""

from __future__ import annotations

import os
import secrets
from pathlib import Path

from fabwire.agent.boundary import SUBPROTOCOL, TOKEN_FILE, TOKEN_PREFIX, is_loopback
from fabwire.agent.core import private_dir
from fabwire.errors import ConfigError

__all__ = ["SUBPROTOCOL", "TOKEN_FILE", "TOKEN_PREFIX", "is_loopback", "load_or_create_token"]


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
        private_dir(state_dir)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w", encoding="ascii") as fh:
            fh.write(token + "\n")
    except OSError as exc:
        raise ConfigError(f"cannot write the access token {path}: {exc.strerror or exc}") from None
    return token, True
