"""The one check of a simulator's speed-up factor, shared by every simulator."""

from __future__ import annotations

import math

from fabwire.errors import InputError

SLOWEST = 0.01
FASTEST = 10_000.0
"""A simulator runs from 100× slower to 10 000× faster than the machine: beyond that its timers (heartbeats,
heating, moves) either never fire within a session or all fire at once, and nan or inf would poison its clock."""


def checked_speed(speed: float) -> float:
    """`speed` if it is a finite factor in SLOWEST..FASTEST; an InputError saying the range otherwise."""
    if not (isinstance(speed, int | float) and math.isfinite(speed) and SLOWEST <= speed <= FASTEST):
        raise InputError(f"speed must be a number from {SLOWEST:g} to {FASTEST:g}, not {speed}")
    return float(speed)
