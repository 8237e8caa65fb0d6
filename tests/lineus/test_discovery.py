"""mDNS on loopback: the simulator's advertisement is found by fabwire's browser."""

from __future__ import annotations

import asyncio

from fabwire.lineus.discovery import Advertiser, Found, discover


async def test_advertised_simulator_is_discovered() -> None:
    advertiser = Advertiser("disc-bot", "127.0.0.1", 41337)
    await advertiser.start()
    try:
        found = await asyncio.wait_for(discover(1.0, interfaces=["127.0.0.1"]), 20)
    finally:
        await advertiser.stop()
    assert Found("disc-bot", "disc-bot.local.", "127.0.0.1", 41337) in found
    assert Found("disc-bot", "disc-bot.local.", "127.0.0.1", 41337).endpoint == "127.0.0.1:41337"


async def test_nothing_advertised_gives_an_empty_list() -> None:
    """A name nobody advertises is not found (another test's name may linger in mDNS caches for a while)."""
    found = await asyncio.wait_for(discover(0.3, interfaces=["127.0.0.1"]), 20)
    assert isinstance(found, list)
    assert all(f.name != "never-advertised-bot" for f in found)
