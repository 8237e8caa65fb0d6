"""The device links in a child process: it ends with the agent however the agent ends, a driver's exception reaches
the agent as the same class with the same message, and a child that dies takes its machines offline saying why
until a new one has connected them again."""

from __future__ import annotations

import asyncio
import os
import signal
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from clitools import RunningSimulator, cli_env, start_simulator
from fabwire.agent.core import Agent, DeviceSpec
from fabwire.agent.linkprocess import ProcessLink
from fabwire.agent.links import LINK_PROCESS_FROM, wants_process
from fabwire.agent.linkwire import pack_error, unpack_error
from fabwire.errors import DeviceError, InputError, LinkError, LinkTimeout

from .agenttools import start_agent, wait_for


@pytest.fixture
def printer() -> Iterator[RunningSimulator]:
    sim = start_simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "30")
    yield sim
    sim.stop()


def _children(pid: int) -> list[int]:
    return [int(p) for p in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]


def _ended(pid: int) -> bool:
    """Gone, or a zombie waiting for whoever adopted it to reap it."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_the_links_process_ends_with_the_agent(tmp_path: Path, printer: RunningSimulator,
                                               sig: signal.Signals) -> None:
    config = tmp_path / "devices.toml"
    config.write_text(f'[devices.printer]\nkind = "xyz"\nurl = "{printer.url}"\n', encoding="utf-8")
    agent = start_agent(tmp_path / "state", "--config", str(config),
                        env={**cli_env(tmp_path), "FABWIRE_LINKS": "process"})
    try:
        with agent.client() as client:
            wait_for(lambda: client.get("/api/v1/agent").json()["online"] == 1, "the printer online")
        (child,) = _children(agent.process.pid)
        assert b"fabwire.agent.linkworker" in Path(f"/proc/{child}/cmdline").read_bytes()
        agent.process.send_signal(sig)
        agent.process.wait(30)
        wait_for(lambda: _ended(child), "the links' process ended")
    finally:
        agent.stop()


@pytest.mark.parametrize("exc", [
    InputError("no step is waiting for an answer"),
    DeviceError(23, "the bed is too hot", action="let it cool"),
    LinkTimeout("no answer in 5 s"),
    ConnectionRefusedError(111, "Connection refused"),
])
def test_an_exception_crosses_as_its_class_and_message(exc: BaseException) -> None:
    crossed = unpack_error(pack_error(exc))
    assert type(crossed) is type(exc)
    assert str(crossed) == str(exc)
    assert crossed.args == exc.args
    if isinstance(exc, DeviceError):
        assert isinstance(crossed, DeviceError)
        assert (crossed.code, crossed.meaning, crossed.action) == (23, "the bed is too hot", "let it cool")


def test_an_exception_of_a_class_not_here_becomes_a_link_error() -> None:
    crossed = unpack_error(("no.such.module", "Oops", ("x",), {}, "it broke"))
    assert type(crossed) is LinkError
    assert str(crossed) == "it broke"


async def _event(subscription: Any, wanted: str) -> dict[str, Any]:
    async with asyncio.timeout(60):
        async for event in subscription:
            if event["type"] == wanted:
                return dict(event)
    raise AssertionError(f"no {wanted} event")


async def test_a_drivers_exception_reaches_the_agent(tmp_path: Path, printer: RunningSimulator) -> None:
    async with Agent(state_dir=tmp_path, links="process") as agent:
        info = await agent.add_device(DeviceSpec("printer", "xyz", printer.url))
        session = agent.session(info.id)
        assert isinstance(session.link, ProcessLink)
        with pytest.raises(InputError) as raised:
            await session.link.act("confirm", {})  # the driver raises it, in the child
        assert type(raised.value) is InputError
        assert str(raised.value) == "no step is waiting for an answer"


async def test_a_killed_links_process_takes_the_machines_offline_and_comes_back(
        tmp_path: Path, printer: RunningSimulator) -> None:
    async with Agent(state_dir=tmp_path, links="process", backoff=(0.1, 0.5)) as agent:
        info = await agent.add_device(DeviceSpec("printer", "xyz", printer.url))
        link = agent.session(info.id).link
        assert isinstance(link, ProcessLink)
        subscription = agent.subscribe(info.id)
        if not agent.session(info.id).online:
            await _event(subscription, "online")
        first = link.process.pid
        assert first is not None
        os.kill(first, signal.SIGKILL)
        offline = await _event(subscription, "offline")
        assert offline["reason"].startswith("the links' process ended (killed by SIGKILL)")
        assert offline["exit_code"] == 8
        state = agent.state(info.id)
        assert not state["online"]
        assert "the links' process ended (killed by SIGKILL)" in state["summary"]["state_text"]
        await _event(subscription, "online")
        assert agent.state(info.id)["online"] or agent.session(info.id).online
        second = link.process.pid
        assert second not in (None, first)
        await subscription.aclose()
    assert _ended(first)
    assert second is not None
    await asyncio.to_thread(wait_for, lambda: _ended(second), "the new links' process ended with the agent")


async def test_a_few_machines_stay_on_the_thread(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("FABWIRE_LINKS", raising=False)
    async with Agent(state_dir=tmp_path) as agent:
        tcp = DeviceSpec("p", "xyz", "tcp://192.0.2.1:9100")
        assert not wants_process(agent, tcp, 0)
        assert wants_process(agent, tcp, LINK_PROCESS_FROM - 1)
        agent.expected_devices = LINK_PROCESS_FROM
        assert wants_process(agent, tcp, 0)
        assert not wants_process(agent, DeviceSpec("s", "xyz", "sim://xyz"), LINK_PROCESS_FROM * 2)


async def test_an_upload_is_checked_against_the_machine_the_child_polls(tmp_path: Path,
                                                                       printer: RunningSimulator) -> None:
    from .doortools import prusaslicer_gcode

    wide = prusaslicer_gcode() + b"G1 X200 Y10 E5\n"  # beyond the simulated da Vinci mini w's 150 mm
    async with Agent(state_dir=tmp_path, links="process") as agent:
        info = await agent.add_device(DeviceSpec("printer", "xyz", printer.url))
        subscription = agent.subscribe(info.id)
        while agent.state(info.id).get("status") is None:  # the model is known from a poll on
            await _event(subscription, "state")
        await subscription.aclose()
        with pytest.raises(InputError, match="moves beyond the da Vinci mini w's build volume"):
            await agent.start_job(info.id, "wide.gcode", wide)
        assert await agent.jobs.list() == []  # refused as the answer: no job recorded
