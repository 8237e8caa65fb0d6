"""Prusa MMU3: the serial protocol (both roles), the printer-side host logic, a client and a simulator."""

from fabwire.mmu.client import MMU
from fabwire.mmu.host import HostLogic, Status
from fabwire.mmu.sim import MMUSimulator
from fabwire.mmu.sync import SyncMMU

__all__ = ["MMU", "HostLogic", "MMUSimulator", "Status", "SyncMMU"]
