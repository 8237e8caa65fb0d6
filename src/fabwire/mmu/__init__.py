"""Prusa MMU3: the serial protocol (both roles), the printer-side host logic, a client and a simulator."""

from fabwire.mmu.client import MMU, SyncMMU
from fabwire.mmu.host import HostLogic, Status
from fabwire.mmu.sim import MMUSimulator

__all__ = ["MMU", "HostLogic", "MMUSimulator", "Status", "SyncMMU"]
