"""The one place the agent opens device clients: the library's `X.open`, with the per-device options applied."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fabwire.lineus.client import LineUs
from fabwire.mmu.client import MMU
from fabwire.xyz.client import XYZPrinter

Options = Mapping[str, Any]


async def open_xyz(address: str, options: Options) -> XYZPrinter:
    return await XYZPrinter.open(address, **options)


async def open_lineus(address: str, options: Options) -> LineUs:
    return await LineUs.open(address, **options)


async def open_mmu(address: str, options: Options) -> MMU:
    """The MMU's heartbeat and timeouts follow `speed` (a simulator's speed-up), as `fabwire mmu --speed` does;
    the agent reports errors instead of retrying them on its own."""
    return await MMU.open(address, **{"auto_retries": 0, **options})
