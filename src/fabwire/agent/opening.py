"""The one place the agent opens device clients: through `X.open`, as the CLI and the library do, with the
device's settings (`fabwire.config`) passed as options."""

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
    """`speed` (a simulator's speed-up) scales the heartbeat and timeouts; `auto_retries=0` leaves every error
    to the person at the dashboard."""
    return await MMU.open(address, **options)
