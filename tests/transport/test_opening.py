"""`X.open` / `X.open_sync`: one way to open every client, by address, configured name or transport."""

from __future__ import annotations

import asyncio
import inspect
from pathlib import Path
from typing import Any

import pytest

from fabwire.errors import ConfigError, InputError
from fabwire.lineus.client import LineUs
from fabwire.lineus.sync import LineUsSync
from fabwire.mmu.client import MMU
from fabwire.mmu.sync import SyncMMU
from fabwire.transport import open_transport, serve_tcp
from fabwire.transport.tap import read_trace
from fabwire.xyz.client import XYZPrinter
from fabwire.xyz.protocol import Link
from fabwire.xyz.sim import XYZSimulator
from fabwire.xyz.sync import SyncXYZPrinter

LIMIT = 30


def config(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "devices.toml"
    path.write_text(text)
    return path


async def test_a_configured_name_opens_with_its_settings(tmp_path: Path) -> None:
    path = config(tmp_path, """
[devices.fast]
kind = "mmu"
url = "sim://mmu?speed=50"
speed = 50
auto_retries = 0
accept = ["3.0.4"]
""")
    async with asyncio.timeout(LIMIT), MMU.open("fast", config=path) as mmu:
        assert mmu.logic.heartbeat < 1  # 50 times faster than the printer's heartbeat
        assert mmu.logic.auto_retries == 0
        assert str(await mmu.version()).startswith("3.0.4")
    assert mmu.transport.closed


async def test_explicit_options_win_over_the_configured_ones(tmp_path: Path) -> None:
    path = config(tmp_path, '[devices.plus]\nkind = "xyz"\nurl = "sim://xyz"\nlink = "serial"\nreply_timeout = 7\n')
    printer = await XYZPrinter.open("plus", config=path, link="wifi")
    try:
        assert printer.link is Link.WIFI
        assert printer.timeout == 7
        assert printer.settings.link == "wifi"
    finally:
        await printer.close()


async def test_the_default_device_of_a_kind_opens_without_a_target(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FABWIRE_CONFIG", str(config(tmp_path, '[devices.arm]\nkind="lineus"\nurl="sim://lineus"\n')))
    async with asyncio.timeout(LIMIT), LineUs.open() as arm:
        assert arm.hello.name == "line-us"


async def test_an_open_transport_is_taken_over() -> None:
    transport = await open_transport("sim://lineus?speed=inf")
    async with asyncio.timeout(LIMIT), LineUs.open(transport, reply_timeout=3) as arm:
        assert arm.reply_timeout == 3
        assert (await arm.position()).x == 1000
    assert transport.closed


@pytest.mark.parametrize(("client", "option", "hint"), [
    (MMU, "sped", "speed"), (XYZPrinter, "reply_timout", "reply_timeout"), (LineUs, "look_ahead", "lookahead")])
async def test_an_unknown_option_names_the_closest_one(client: Any, option: str, hint: str) -> None:
    with pytest.raises(InputError, match=f"unknown option '{option}' \\(did you mean '{hint}'\\?\\)"):
        await client.open("sim://", **{option: 1})


async def test_a_misspelt_name_is_a_config_error(tmp_path: Path) -> None:
    path = config(tmp_path, '[devices.office]\nkind = "xyz"\nurl = "sim://xyz"\n')
    with pytest.raises(ConfigError, match=r"no device named 'offfice' \(did you mean 'office'\?\)"):
        await XYZPrinter.open("offfice", config=path)


async def test_a_printer_that_hangs_up_is_reconnected_through_one_trace(tmp_path: Path) -> None:
    sim = XYZSimulator("1.1 Plus", speed=1000)
    server = await serve_tcp(sim.serve, "127.0.0.1", 0)
    trace = tmp_path / "plus.jsonl"
    try:
        async with asyncio.timeout(LIMIT), XYZPrinter.open(
                f"127.0.0.1:{server.sockets[0].getsockname()[1]}", trace=trace) as printer:
            for _ in range(3):
                assert (await printer.status("j")).state == (10, None)
    finally:
        server.close()
    records = list(read_trace(trace))
    sent = [r.data for r in records if r.direction == ">"]
    assert sent.count(b"XYZv3/query=j\r\n") >= 3
    assert sum(1 for r in records if r.event == "close") >= 3  # one connection per command, one capture


def _operations(cls: type) -> set[str]:
    return {name for name, member in inspect.getmembers(cls)
            if not name.startswith("_") and (inspect.iscoroutinefunction(member) or inspect.isasyncgenfunction(member))
            and name not in ("close", "connect", "detach", "events", "wait_idle")}


@pytest.mark.parametrize(("client", "facade"), [(XYZPrinter, SyncXYZPrinter), (LineUs, LineUsSync), (MMU, SyncMMU)])
def test_sync_facades_are_typed_classes(client: type, facade: type) -> None:
    assert "__getattr__" not in vars(facade)
    spelled_out = {name for name in vars(facade) if not name.startswith("_")}
    assert _operations(client) <= spelled_out  # every operation, with its own signature
    for name in _operations(client):
        ours = inspect.signature(getattr(facade, name)).parameters
        theirs = inspect.signature(getattr(client, name)).parameters
        assert list(ours) == list(theirs), name
        assert [q.default for q in ours.values()] == [q.default for q in theirs.values()], name


def test_open_sync_runs_the_same_client() -> None:
    with XYZPrinter.open_sync("sim://xyz?speed=1000", reply_timeout=3) as printer:
        assert isinstance(printer, SyncXYZPrinter)
        assert printer.status().idle
        assert printer.client.timeout == 3
    with MMU.open_sync("sim://mmu?speed=50", speed=50) as mmu:
        assert mmu.read_register("bowden_length") > 0
    assert mmu.client.transport.closed
