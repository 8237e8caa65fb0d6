"""`fabwire demo`: the showcase a newcomer runs first, on simulators started as real processes."""

from fabwire.demo.command import demo

__all__ = ["demo"]
