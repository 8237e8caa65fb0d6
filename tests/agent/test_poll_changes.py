"""Poll after poll on a simulated printer: a reply that did not change publishes no state event, a changed one
does, and the views made from the previous poll equal views made from scratch."""

from __future__ import annotations

import asyncio
import socket
import threading
from collections.abc import AsyncIterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import httpx
import pytest

from fabwire.agent import session as session_module
from fabwire.agent.boundary import Boundary, Policy
from fabwire.agent.core import Agent, DeviceSpec
from fabwire.agent.drivers.xyz import XYZDriver, printer_summary
from fabwire.agent.linkthread import LinkThread
from fabwire.agent.session import RequestsFirst


async def _collect(subscription: AsyncIterator[dict[str, Any]], events: list[dict[str, Any]]) -> None:
    async for event in subscription:
        events.append(event)


async def test_an_unchanged_reply_publishes_no_state_and_a_changed_byte_does(tmp_path: Path) -> None:
    async with Agent(state_dir=tmp_path / "state") as agent:
        info = await agent.add_device(DeviceSpec("p", "xyz", "sim://xyz?speed=1"))
        subscription = agent.subscribe(info.id)
        events: list[dict[str, Any]] = []
        collector = asyncio.create_task(_collect(subscription, events))
        for _ in range(400):
            if agent.state(info.id)["online"] and agent.state(info.id)["status"] is not None:
                break
            await asyncio.sleep(0.05)
        await asyncio.sleep(0)
        events.clear()
        first = agent.health()["polls"]
        seen_ts = {agent.state(info.id)["ts"]}
        while agent.health()["polls"] < first + 4:
            await asyncio.sleep(0.05)
            seen_ts.add(agent.state(info.id)["ts"])
        states = [e["state"] for e in events if e["type"] == "state"]
        # at one poll a second an idle printer answers the same bytes (its minute counter may tick once)
        assert len(states) <= 1
        assert len(seen_ts) >= 4  # the state's time still follows each poll
        before = agent.state(info.id)
        assert before["status"]["zoffset_mm"] != 0.37

        await agent.act(info.id, "zoffset", {"mm": 0.37})
        for _ in range(200):
            if any(e["type"] == "state" and e["state"]["status"]["zoffset_mm"] == 0.37 for e in events):
                break
            await asyncio.sleep(0.05)
        changed = [e["state"] for e in events if e["type"] == "state" and e["state"]["status"]["zoffset_mm"] == 0.37]
        assert changed, "a changed `z:` line published no state"
        assert changed[0]["status"]["raw"]["z"] == "37"
        assert {k: v for k, v in changed[0]["status"].items() if k not in ("zoffset_mm", "raw")} == \
            {k: v for k, v in before["status"].items() if k not in ("zoffset_mm", "raw")}
        await subscription.aclose()
        collector.cancel()


async def test_each_poll_equals_views_made_from_scratch() -> None:
    """At 1,000× the printer's counters move every poll; actions change other lines between polls."""
    driver = XYZDriver(DeviceSpec("p", "xyz", "sim://xyz?speed=1000"), lambda event: None)
    await driver.connect()
    assert driver.printer is not None
    try:
        steps: list[tuple[str, dict[str, Any]]] = [
            ("zoffset", {"mm": 0.12}), ("zoffset_step", {"direction": "up"}), ("jog", {"axis": "x", "distance_mm": 5}),
            ("zoffset", {"mm": -0.3}), ("home", {}), ("zoffset_step", {"direction": "down"})]
        for action, params in [("", {}), *steps, ("", {})]:
            if action:
                await driver.act(action, params)
            for _ in range(3):
                status, summary = await driver.poll()
                last = driver.printer.last_status
                assert status == last.to_dict()
                assert list(status) == list(last.to_dict())
                assert summary == printer_summary(last)
    finally:
        await driver.close()


async def _polls_reach(agent: Agent, count: int) -> None:
    for _ in range(1200):
        if agent.health()["polls"] >= count:
            return
        await asyncio.sleep(0.05)
    raise AssertionError(f"the agent did not reach {count} polls in a minute")


def _lag_figures(agent: Agent) -> tuple[float | None, float | None]:
    lags = sorted(lag for session in agent.sessions() for lag in session.stats.lags)
    return (lags[int(0.99 * (len(lags) - 1))], lags[-1]) if lags else (None, None)


async def test_health_lags_are_those_of_the_machines_monitored(tmp_path: Path) -> None:
    async with Agent(state_dir=tmp_path / "state") as agent:
        infos = [await agent.add_device(DeviceSpec(f"p{n}", "xyz", f"sim://xyz?speed=30&serial=LAG{n}"))
                 for n in range(3)]
        await _polls_reach(agent, 9)
        health = agent.health()
        assert (health["poll_lag_p99_s"], health["poll_lag_max_s"]) == _lag_figures(agent)
        await agent.remove_device(infos[1].id)
        await _polls_reach(agent, agent.health()["polls"] + 4)
        health = agent.health()
        assert (health["poll_lag_p99_s"], health["poll_lag_max_s"]) == _lag_figures(agent)
        for info in (infos[0], infos[2]):
            await agent.remove_device(info.id)
        assert (agent.health()["poll_lag_p99_s"], agent.health()["poll_lag_max_s"]) == (None, None)


def _counts(agent: Agent) -> dict[str, int]:
    sessions = agent.sessions()
    return {"devices": len(sessions), "online": sum(s.online for s in sessions),
            "polls": sum(s.stats.polls for s in sessions), "late_polls": sum(s.stats.late for s in sessions)}


async def test_health_counts_are_those_of_the_machines_monitored(tmp_path: Path) -> None:
    """Health reads running counts: they equal the sums over the sessions through a link that never comes up, a
    link lost, and machines removed."""
    refused = socket.socket()
    refused.bind(("127.0.0.1", 0))  # bound, never listening: every connection is refused
    async with Agent(state_dir=tmp_path / "state", backoff=(0.05, 0.1)) as agent:
        infos = [await agent.add_device(DeviceSpec(f"p{n}", "xyz", f"sim://xyz?speed=30&serial=TALLY{n}"))
                 for n in range(3)]
        down = await agent.add_device(DeviceSpec("gone", "xyz", f"tcp://127.0.0.1:{refused.getsockname()[1]}"))
        await _polls_reach(agent, 9)
        health = agent.health()
        assert {k: health[k] for k in _counts(agent)} == _counts(agent)
        assert health["online"] == 3
        await agent.remove_device(infos[1].id)
        await agent.remove_device(down.id)
        await _polls_reach(agent, agent.health()["polls"] + 4)
        health = agent.health()
        assert {k: health[k] for k in _counts(agent)} == _counts(agent)
        assert health["online"] == 2
        session = agent.session(infos[0].id)
        subscription = agent.subscribe(infos[0].id)
        await session.link.close()  # the link is lost under the session
        for wanted, online in (("offline", 1), ("online", 2)):
            async with asyncio.timeout(30):
                async for event in subscription:
                    if event["type"] == wanted:
                        break
            health = agent.health()
            assert {k: health[k] for k in _counts(agent)} == _counts(agent)
            assert health["online"] == online
        await subscription.aclose()
    refused.close()


async def test_delivered_results_arrive_on_the_agents_loop_in_order() -> None:
    home = asyncio.get_running_loop()
    links = LinkThread()
    got: list[tuple[int, int]] = []
    errors: list[dict[str, Any]] = []
    home.set_exception_handler(lambda loop, context: errors.append(context))

    def record(n: int) -> None:
        if n == 50:
            raise ValueError("one result that fails")
        got.append((n, threading.get_ident()))

    def send(first: int) -> None:
        for n in range(first, first + 100):
            links.deliver(record, n)

    try:
        links.loop.call_soon_threadsafe(send, 0)
        await asyncio.sleep(0.2)
        links.loop.call_soon_threadsafe(send, 100)
        for _ in range(200):
            if len(got) == 199:
                break
            await asyncio.sleep(0.01)
    finally:
        links.close()
        home.set_exception_handler(None)
    assert [n for n, _ in got] == [n for n in range(200) if n != 50]
    assert {thread for _, thread in got} == {threading.get_ident()}
    assert [str(e["exception"]) for e in errors] == ["one result that fails"]



def test_the_links_thread_steps_aside_while_a_request_is_answered(monkeypatch: pytest.MonkeyPatch) -> None:
    """A poll waits for the requests in flight and goes on when the last is answered; an idle API costs no wait."""
    monkeypatch.setattr(session_module, "STEP_ASIDE_S", 600.0)
    first = RequestsFirst()
    first.step_aside()  # no request in flight: no wait
    first.begin()
    first.begin()
    links = threading.Thread(target=first.step_aside)
    links.start()
    links.join(0.2)
    assert links.is_alive()  # held while requests are in flight
    first.end()
    links.join(0.2)
    assert links.is_alive()  # one is still being answered
    first.end()
    links.join(30)
    assert not links.is_alive()


def test_the_links_thread_steps_aside_for_a_bounded_time(monkeypatch: pytest.MonkeyPatch) -> None:
    """A request that lasts (a slow reader) holds the polls STEP_ASIDE_S at most, and not again for as long after."""
    monkeypatch.setattr(session_module, "STEP_ASIDE_S", 0.01)
    first = RequestsFirst()
    first.begin()
    first.step_aside()  # returns though the request is still in flight
    monkeypatch.setattr(session_module, "STEP_ASIDE_S", 600.0)  # a second wait now would never end
    first.step_aside()  # within the first wait's STEP_ASIDE_S after it: no wait
    first.end()


@pytest.mark.parametrize(("method", "held"), [("GET", True), ("HEAD", True), ("OPTIONS", True), ("POST", False),
                                              ("PUT", False), ("DELETE", False)])
async def test_a_reading_request_holds_the_polls_while_it_is_answered(method: str, held: bool) -> None:
    first = RequestsFirst()
    seen: list[bool] = []

    async def app(scope: dict[str, object], receive: object, send: object) -> None:
        seen.append(not first._idle.is_set())
        await send({"type": "http.response.start", "status": 200, "headers": []})  # type: ignore[operator]
        await send({"type": "http.response.body", "body": b"ok"})  # type: ignore[operator]

    guarded = Boundary(app, policy=Policy(), router=SimpleNamespace(routes=[]), requests_first=first)
    async with httpx.AsyncClient(transport=httpx.ASGITransport(app=guarded), base_url="http://localhost") as client:
        response = await client.request(method, "/api/v1/agent", headers={"content-type": "application/json"})
    assert response.status_code == 200
    assert seen == [held]
    assert first._idle.is_set()  # answered: the polls go on
