"""JSON from outside (an HTTP body, an MQTT payload, a broker's retained message), parsed within bounds.

The standard parser recurses once per nesting level, so a payload of 100,000 `[` raises RecursionError from deep
inside, and a depth just under the interpreter's limit parses but then breaks whatever walks the value. Every
reader of outside JSON goes through `parse_json`, which answers either a value or one InputError that says what
is wrong, in words.
"""

from __future__ import annotations

import json
import math
from typing import Any

from fabwire.errors import InputError

MAX_DEPTH = 32
"""Deepest nesting accepted: fabwire's own documents nest at most 4 levels; 32 leaves room for any client."""


def parse_json(data: str | bytes, *, what: str = "the JSON", max_bytes: int | None = None,
               max_depth: int = MAX_DEPTH) -> Any:
    """`data` (UTF-8 bytes or text) as a JSON value.

    Raises InputError naming `what` when the text is longer than `max_bytes`, is not UTF-8, is not JSON (NaN and
    Infinity included: RFC 8259 §6 has no such numbers, though Python's parser takes them), or nests arrays and
    objects deeper than `max_depth` levels."""
    if max_bytes is not None and len(data) > max_bytes:
        raise InputError(f"{what} is larger than {max_bytes} bytes")
    try:
        text = data.decode("utf-8") if isinstance(data, bytes) else data
    except UnicodeDecodeError:
        raise InputError(f"{what} must be UTF-8 text") from None
    try:
        value = json.loads(text, parse_constant=_no_constant, parse_float=_finite_float)
    except RecursionError:
        raise InputError(f"{what} nests deeper than {max_depth} levels") from None
    except ValueError as exc:
        raise InputError(f"{what} is not valid JSON ({exc})") from None
    if depth_exceeds(value, max_depth):
        raise InputError(f"{what} nests deeper than {max_depth} levels")
    return value


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number (RFC 8259 §6)")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"{text[:40]} is beyond the largest number a double holds")
    return value


def depth_exceeds(value: Any, limit: int) -> bool:
    """Whether `value` nests lists and dicts more than `limit` levels deep (iteratively: no recursion)."""
    stack: list[tuple[Any, int]] = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            children: Any = item.values()
        elif isinstance(item, list):
            children = item
        else:
            continue
        if depth > limit:
            return True
        stack.extend((child, depth + 1) for child in children if isinstance(child, dict | list))
    return False
