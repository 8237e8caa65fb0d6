"""The one place the agent opens device clients, with the per-device options of the config applied."""

from __future__ import annotations

from collections.abc import Mapping

from fabwire.lineus.client import LineUs
from fabwire.mmu.client import MMU
from fabwire.xyz.client import XYZPrinter

Options = Mapping[str, str | int | float | bool]


def _number(options: Options, key: str, default: float) -> float:
    value = options.get(key, default)
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else default


async def open_xyz(address: str, options: Options) -> XYZPrinter:
    return await XYZPrinter.connect(address, timeout=_number(options, "timeout", 5.0))


async def open_lineus(address: str, options: Options) -> LineUs:
    return await LineUs.open(address, connect_timeout=_number(options, "timeout", 5.0))


async def open_mmu(address: str, options: Options) -> MMU:
    """The MMU's heartbeat and timeouts follow `speed` (a simulator's speed-up), as `fabwire mmu --speed` does."""
    from fabwire.devices import MMU as MMU_KIND
    from fabwire.transport import open_transport

    speed = _number(options, "speed", 1.0)
    transport = await open_transport(address, MMU_KIND, connect_timeout=_number(options, "timeout", 5.0))
    mmu = MMU(transport, time_scale=speed, auto_retries=0, connect_timeout=max(5.0, 30.0 / speed))
    try:
        await mmu.connect()
    except BaseException:
        await transport.close()
        raise
    return mmu
