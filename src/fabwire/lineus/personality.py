"""Firmware personalities of the simulated Line-us: the hello it sends and how each firmware generation behaves.

Firmware 3 (3.2.0, Nov 2019) answers with two-decimal coordinates, buffers a few commands and keeps the pen out of
the body notch (x >= 700 below y = 0). Firmware 1.0.1 (Feb 2018) answers in integers, must be sent one command at
a time, and lets the arm go to x >= 500 below y = 0 too, where the pen screw can hit the body (Line-us-Programming
README, "CAUTION"); the simulator follows it there and records the collision.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Literal

from fabwire.errors import excerpt
from fabwire.lineus import kinematics as kin
from fabwire.lineus import protocol as p

VERSIONS = {
    "1": "1.0.1 Feb 11 2018 15:47:35",
    "3": "3.2.0 Nov 17 2019 17:54:57",
}
DEFAULT_NAME = "line-us"
DEFAULT_SERIAL = "123456"

ReplyPolicy = Literal["complete", "accept"]


RELEASED = ((1, 0, 0), (3, 2, 0))
"""The firmware releases known to exist: 1.0.x (2018) to 3.2.0 (Nov 2019), the last before the company closed."""
_VERSION = re.compile(r"^(\d{1,3})\.(\d{1,3})\.(\d{1,3})(?=$|[ A-Za-z])")


def resolve_version(text: str) -> str:
    """`1`, `1.0.1`, `3`, `3.x`, `3.2.0` → a full version string; another release from 1.0.0 to 3.2.0 (such as
    `2.0.2Beta6 Sep 14 2018`) as given. ValueError for anything else, a version never released included."""
    short = text.strip()
    if short in ("1", "1.x", "1.0.1"):
        return VERSIONS["1"]
    if short in ("3", "3.x", "3.2.0"):
        return VERSIONS["3"]
    match = _VERSION.match(short)
    if match is None or '"' in short or not short.isascii() or not short.isprintable():
        raise ValueError(f"a firmware version starts with its number (1.0.1, 3.2.0 …), got {excerpt(text, 40)}")
    number = tuple(int(part) for part in match.groups())
    if not RELEASED[0] <= number <= RELEASED[1]:
        raise ValueError(f"Line-us firmware {match.group(0)} was never released: the releases run from 1.0.0 to "
                         "3.2.0 (give 1.0.1 or 3.x)")
    return short


def check_name(text: str) -> str:
    """`text` if it is a machine name the firmware takes (M550: 1-32 of A-Z a-z 0-9 -); ValueError otherwise."""
    if not p.NAME_RE.fullmatch(text):
        raise ValueError(f"a machine name is 1-32 of A-Z a-z 0-9 -, got {excerpt(text, 40)}")
    return text


MAX_SERIAL = 32
"""The longest serial the simulator says in its hello (real machines have 6 digits)."""


def check_serial(text: str) -> str:
    """`text` if it fits the hello's `SERIAL:"…"` field: 1-32 printable ASCII characters, no space or quote."""
    if not (text.isascii() and text.isprintable() and 0 < len(text) <= MAX_SERIAL) or any(c in text for c in ' "'):
        raise ValueError(f"a serial is 1-{MAX_SERIAL} ASCII characters without spaces or quotes, "
                         f"got {excerpt(text, 20)}")
    return text


def guards_body(firmware: tuple[int, ...]) -> bool:
    """False for firmware 1.0.1 and older, which let the pen into the body notch (README "CAUTION")."""
    return not firmware or firmware > (1, 0, 1)


@dataclass
class SimOptions:
    version: str = VERSIONS["3"]
    name: str = DEFAULT_NAME
    serial: str = DEFAULT_SERIAL
    speed: float = 1.0
    """Speed-up factor for motion; inf (or 0) runs moves with no delay."""
    reply: ReplyPolicy = "complete"
    step_time: float = 0.010
    pen_time: float = 0.1
    lookahead: bool | None = None
    """Accept the next command while a move runs (firmware 3); None = from the version."""
    decimals: bool | None = None
    """Two-decimal coordinates in replies (firmware 3); None = from the version."""

    def __post_init__(self) -> None:
        if self.speed == 0:
            self.speed = math.inf
        if not self.speed > 0:
            raise ValueError(f"speed factor must be positive (or 0/inf for no delay), got {self.speed}")
        if self.reply not in ("complete", "accept"):
            raise ValueError("reply policy is 'complete' or 'accept'")
        check_name(self.name)
        check_serial(self.serial)

    @property
    def firmware(self) -> tuple[int, ...]:
        return p.Hello(self.version, self.name, self.serial).firmware

    @property
    def major(self) -> int:
        return self.firmware[0] if self.firmware else 0

    @property
    def guards_body(self) -> bool:
        return guards_body(self.firmware)

    @property
    def x_min_lower(self) -> float:
        """Body clearance below y = 0 that this firmware enforces."""
        return kin.X_MIN_LOWER if self.guards_body else kin.X_MIN_LOWER_FW1
