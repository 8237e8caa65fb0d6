"""Prusa MMU3: the serial protocol (both roles), the printer-side host logic, a client and a simulator."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from fabwire.mmu.client import MMU
    from fabwire.mmu.host import HostLogic, Status
    from fabwire.mmu.sim import MMUSimulator
    from fabwire.mmu.sync import SyncMMU

__all__ = ["MMU", "HostLogic", "MMUSimulator", "Status", "SyncMMU"]

_HOMES = {"MMU": "client", "HostLogic": "host", "Status": "host", "MMUSimulator": "sim", "SyncMMU": "sync"}
"""Where each name lives: loaded on first use, so `fabwire mmu status` does not load the simulator."""


def __getattr__(name: str) -> object:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{home}"), name)
