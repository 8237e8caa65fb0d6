"""The API writes what the agent holds as JSON directly; the bytes decode to what the framework's own conversion
gives, for JSON values and for the values only that conversion knows."""

from __future__ import annotations

import dataclasses
import enum
import json
from datetime import UTC, datetime
from pathlib import PurePosixPath
from typing import Any

import pytest
from fastapi.encoders import jsonable_encoder

from fabwire.agent.api import published


class Colour(enum.Enum):
    RED = "red"


@dataclasses.dataclass
class Point:
    x: float
    y: float


VALUES: list[Any] = [
    {"ts": "2026-12-03T13:00:00Z", "online": True, "summary": {"state": "idle", "actions": ["home"]}, "job": None},
    {"strokes": [[(0.0, 1.5), (2.0, 3.25)]], "ink": []},
    [{"id": "xyz-1", "state": {"status": {"raw": {"n": "mini w          ", "j": "9511,0"}}}}],
    {"name": "Drucker ü €", "values": (1, 2, 3), "big": 2**70, "neg": -0.0},
    {"when": datetime(2026, 12, 3, 13, 0, tzinfo=UTC), "path": PurePosixPath("/a/b"), "colour": Colour.RED},
    {"point": Point(1.0, 2.5), "set": {3}},
]


@pytest.mark.parametrize("value", VALUES)
def test_published_json_equals_the_frameworks(value: Any) -> None:
    response = published(value)
    assert response.media_type == "application/json"
    assert json.loads(response.body) == jsonable_encoder(value)


def test_a_value_json_cannot_write_is_still_an_error() -> None:
    with pytest.raises(ValueError, match="JSON"):
        published({"bed": float("nan")})
