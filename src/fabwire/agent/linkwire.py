"""The messages between the agent and its links' process (`fabwire.agent.linkprocess`): frames of a 4-byte
big-endian length and a pickle, and exceptions carried as their class, arguments and attributes, so that the agent
raises the very class and message a driver raised (the CLI's exit codes and the API's messages depend on both).

Only the agent and the child it started read these frames (over a socket pair of theirs): nothing else writes to
that socket, so unpickling what arrives on it trusts no one new.
"""

from __future__ import annotations

import importlib
import pickle
import struct
from collections.abc import Callable
from typing import Any

from fabwire.errors import LinkError

HEADER = struct.Struct(">I")
UNCHANGED = "="
"""Stands for a poll's status or summary that is the very object the previous poll of that machine gave."""


def frame(message: Any) -> bytes:
    """One message as bytes to write: its length, then its pickle."""
    body = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    return HEADER.pack(len(body)) + body


class Unframer:
    """Bytes as they arrive → whole messages, each given to `on_message` in order."""

    def __init__(self, on_message: Callable[[Any], None]) -> None:
        self._buffer = bytearray()
        self._on_message = on_message

    def feed(self, data: bytes) -> None:
        buffer = self._buffer
        buffer += data
        start = 0
        size = len(buffer)
        while size - start >= HEADER.size:
            (length,) = HEADER.unpack_from(buffer, start)
            end = start + HEADER.size + length
            if end > size:
                break
            message = pickle.loads(memoryview(buffer)[start + HEADER.size:end])
            start = end
            self._on_message(message)
        del buffer[:start]


def pack_error(exc: BaseException) -> tuple[str, str, tuple[Any, ...], dict[str, Any], str]:
    """(module, class name, args, attributes, message) of `exc`, for `unpack_error` on the other side."""
    cls = type(exc)
    attributes = dict(getattr(exc, "__dict__", {}))
    try:
        pickle.dumps((exc.args, attributes))
    except Exception:  # arguments that cannot travel: the message does
        return cls.__module__, cls.__qualname__, (str(exc),), {}, str(exc)
    return cls.__module__, cls.__qualname__, exc.args, attributes, str(exc)


def unpack_error(packed: tuple[str, str, tuple[Any, ...], dict[str, Any], str]) -> BaseException:
    """The exception `pack_error` described: its class (not its `__init__`: `args` and attributes are restored as
    they were), or a LinkError with its message when that class cannot be had here."""
    module, name, args, attributes, message = packed
    try:
        cls: Any = importlib.import_module(module)
        for part in name.split("."):
            cls = getattr(cls, part)
        if not (isinstance(cls, type) and issubclass(cls, BaseException)):
            raise TypeError(name)
        exc: BaseException = cls.__new__(cls, *args)
        exc.args = args
        exc.__dict__.update(attributes)
    except Exception:
        return LinkError(message or name)
    return exc
