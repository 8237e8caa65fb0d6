"""Work the agent hands to a thread stops when nobody waits for it: in-process, stage by stage; and a real
`fabwire serve` whose uploader disconnects while its drawing is checked, or which is stopped with SIGTERM then."""

from __future__ import annotations

import asyncio
import random
import signal
import socket
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from clitools import start_simulator
from fabwire.agent import offload
from fabwire.agent.offload import WorkCancelled, check_cancelled, in_thread
from fabwire.errors import InputError

from .agenttools import RunningAgent, start_agent, wait_for
from .doortools import multipart

SMALL = b'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100"><path d="M10 10 L90 90" stroke="black"/></svg>'


def _slow_svg(uses: int) -> bytes:
    """A small file that takes the drawing check long: one path of 1,000 lines, drawn `uses` times with <use>
    (12 s for 400 on an idle 2-core machine; at most 1,000 stay within the 2,000,000 points a drawing may have)."""
    rng = random.Random(1)
    d = " ".join(f"M{rng.uniform(0, 10):.2f} {rng.uniform(0, 10):.2f} L{rng.uniform(0, 10):.2f} "
                 f"{rng.uniform(0, 10):.2f}" for _ in range(1000))
    uses_text = "".join(f'<use href="#p" x="{(i % 20) * 4}" y="{(i // 20) * 4 % 90}"/>' for i in range(uses))
    return (f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100"><defs><path id="p" d="{d}" '
            f'stroke="black" fill="none"/></defs>{uses_text}</svg>').encode()


# ---------------------------------------------------------------------------------------------- in-process

class Stages:
    """Work in two stages; the first waits for the test to let it go, so the test knows where it stands."""

    def __init__(self) -> None:
        self.ran: list[str] = []
        self.started = threading.Event()
        self.go_on = threading.Event()
        self.thread: threading.Thread | None = None

    def __call__(self, value: int) -> int:
        self.thread = threading.current_thread()
        self.ran.append("first")
        self.started.set()
        self.go_on.wait(60)
        try:
            check_cancelled()
        except WorkCancelled:
            self.ran.append("cancelled")
            raise
        self.ran.append("second")
        return value * 2


async def _started(stages: Stages) -> None:
    assert await asyncio.to_thread(stages.started.wait, 60)


async def test_work_returns_its_result_from_a_daemon_thread() -> None:
    stages = Stages()
    stages.go_on.set()
    assert await in_thread(stages, 21) == 42
    assert stages.ran == ["first", "second"]
    assert stages.thread is not None
    assert stages.thread.daemon  # a stopping agent does not wait for it
    assert stages.thread is not threading.main_thread()


async def test_an_error_of_the_work_is_raised_to_the_caller() -> None:
    def fails() -> None:
        raise ValueError("not a drawing")

    with pytest.raises(ValueError, match="not a drawing"):
        await in_thread(fails)


async def test_a_cancelled_wait_stops_the_work_before_its_next_stage() -> None:
    stages = Stages()
    waiting = asyncio.ensure_future(in_thread(stages, 1))
    await _started(stages)
    waiting.cancel()
    with pytest.raises(asyncio.CancelledError):
        await waiting
    stages.go_on.set()
    assert stages.thread is not None
    await asyncio.to_thread(stages.thread.join, 60)
    assert stages.ran == ["first", "cancelled"]


async def test_a_cancel_flag_set_by_its_owner_stops_the_work() -> None:
    """As a cancelled job stops its planning: the driver sets the flag, the awaiting call gets WorkCancelled."""
    stages = Stages()
    flag = threading.Event()
    waiting = asyncio.ensure_future(in_thread(stages, 1, cancel=flag))
    await _started(stages)
    flag.set()
    stages.go_on.set()
    with pytest.raises(WorkCancelled):
        await waiting
    assert stages.ran == ["first", "cancelled"]


async def test_at_most_workers_run_at_once_even_when_their_callers_leave(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(offload, "WORKERS", 2)
    works = [Stages() for _ in range(3)]
    waits = [asyncio.ensure_future(in_thread(work, 1)) for work in works]
    await _started(works[0])
    await _started(works[1])
    waits[0].cancel()  # its caller leaves; its thread is still in its first stage
    with pytest.raises(asyncio.CancelledError):
        await waits[0]
    await asyncio.sleep(0)
    assert not works[2].started.is_set()  # the place is still taken
    works[0].go_on.set()  # the first thread ends (cancelled): its place goes to the third
    await _started(works[2])
    for work in works[1:]:
        work.go_on.set()
    assert [await waits[1], await waits[2]] == [2, 2]
    assert works[0].ran == ["first", "cancelled"]


async def test_a_drawing_being_read_stops_between_its_elements_once_nobody_waits() -> None:
    """The reader itself checks the flag: a file whose reading is one long stage still stops part way."""
    from fabwire.lineus.plot import parse_svg

    flag = threading.Event()
    read: list[str] = []
    text = _slow_svg(1000).decode()

    def reading() -> None:
        read.append("started")
        flag.set()  # as if the uploader left at once: the reader stops at its next element
        parse_svg(text)
        read.append("finished")

    with pytest.raises(WorkCancelled):
        await in_thread(reading, cancel=flag)
    assert read == ["started"]


async def test_a_check_past_its_limit_is_refused_and_told_to_stop(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(offload, "CHECK_LIMIT_S", 0.05)
    stages = Stages()
    with pytest.raises(InputError, match=r"^art\.svg: checking it took longer than 0\.05 s; refusing it$"):
        await offload.check_within(stages, 1, name="art.svg")
    stages.go_on.set()
    assert stages.thread is not None
    await asyncio.to_thread(stages.thread.join, 60)
    assert stages.ran == ["first", "cancelled"]  # the work was told to stop, as when its caller leaves


def test_outside_the_agent_nothing_is_cancelled() -> None:
    check_cancelled()  # a CLI command planning a drawing: no flag, no effect


# ---------------------------------------------------------------------------------------------- a real agent

@pytest.fixture
def agent(tmp_path: Path) -> Iterator[RunningAgent]:
    """The agent with a Line-us simulator process of its own."""
    arm = start_simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "4")
    running = start_agent(tmp_path / "state", "--device", f"arm:lineus={arm.url}")
    yield running
    running.stop()
    arm.stop()


def _arm_online(agent: RunningAgent) -> str:
    with agent.client() as client:
        return str(wait_for(lambda: next((d["id"] for d in client.get("/api/v1/devices").json()
                                          if d["state"]["online"]), None), "the Line-us online"))


def _send_upload(agent: RunningAgent, device: str, name: str, data: bytes) -> socket.socket:
    """The whole upload over a plain socket, left open without reading the answer."""
    host, port = agent.url.removeprefix("http://").rstrip("/").rsplit(":", 1)
    sock = socket.create_connection((host, int(port)), timeout=60)
    sock.sendall(f"POST /api/v1/devices/{device}/jobs?filename={name} HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                 f"Content-Type: application/octet-stream\r\nContent-Length: {len(data)}\r\n\r\n".encode() + data)
    return sock


def _held_by(agent: RunningAgent, device: str, name: str) -> bool:
    with agent.client() as client:
        answer = client.post(f"/api/v1/devices/{device}/jobs", params={"filename": "probe.svg"}, content=b"x",
                             headers={"content-type": "application/octet-stream"})
        return answer.status_code == 409 and f"upload of {name!r}" in answer.json()["message"]


def test_an_upload_whose_client_disconnects_while_it_is_checked_is_dropped(agent: RunningAgent) -> None:
    """The file arrived whole; while the drawing is checked the uploader closes its socket: no job is made (the
    README: "the client went away …; nothing was kept"), and the Line-us takes the next upload at once."""
    device = _arm_online(agent)
    sock = _send_upload(agent, device, "slow.svg", _slow_svg(400))
    wait_for(lambda: _held_by(agent, device, "slow.svg"), "the upload being checked")
    sock.close()
    with agent.client() as client:
        created = wait_for(lambda: (r := client.post(f"/api/v1/devices/{device}/jobs", params={"filename": "s.svg"},
                                                     content=SMALL,
                                                     headers={"content-type": "application/octet-stream"})
                                    ).status_code == 201 and r.json(), "the Line-us free again")
        wait_for(lambda: client.get(f"/api/v1/jobs/{created['id']}").json()["state"] == "done", "s.svg drawn")
        assert [j["filename"] for j in client.get("/api/v1/jobs").json()] == ["s.svg"]
    code, stderr = agent.stop()
    assert code == 0
    assert "Traceback" not in stderr
    went = [line for line in stderr.splitlines() if "went away" in line]
    assert len(went) == 1, stderr
    assert f"/api/v1/devices/{device}/jobs" in went[0]
    assert f"while its request ({len(_slow_svg(400)):,} bytes) was handled, before the answer" in went[0]


def test_a_slicer_upload_that_hangs_up_while_it_is_checked_keeps_nothing(agent: RunningAgent) -> None:
    """The OctoPrint door (`print=true` first, as PrusaSlicer sends it): the slicer hangs up while the drawing is
    checked; the file is not kept, no job is made, the machine is free."""
    device = _arm_online(agent)
    body, content_type = multipart([("print", "true")], "slow.svg", _slow_svg(400))
    host, port = agent.url.removeprefix("http://").rstrip("/").rsplit(":", 1)
    sock = socket.create_connection((host, int(port)), timeout=60)
    sock.sendall(f"POST /printers/arm/api/files/local HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: {content_type}"
                 f"\r\nContent-Length: {len(body)}\r\n\r\n".encode() + body)
    wait_for(lambda: _held_by(agent, device, "slow.svg"), "the upload being checked")
    sock.close()
    with agent.client() as client:
        wait_for(lambda: client.post(f"/api/v1/devices/{device}/jobs", params={"filename": "s.svg"}, content=SMALL,
                                     headers={"content-type": "application/octet-stream"}).status_code == 201,
                 "the Line-us free again")
        assert [f["name"] for f in client.get("/printers/arm/api/files/local").json()["files"]] == []
        assert [j["filename"] for j in client.get("/api/v1/jobs").json()] == ["s.svg"]
    code, stderr = agent.stop()
    assert code == 0
    assert "Traceback" not in stderr
    assert "/printers/arm/api/files/local: the client went away" in stderr


def test_sigterm_while_a_drawing_is_checked_ends_the_agent_cleanly(agent: RunningAgent) -> None:
    """A check that would take minutes: SIGTERM still ends the agent, with exit code 0 and no traceback (the
    wait below is only the failure bound: the agent gives its requests 5 s to finish, then stops them)."""
    device = _arm_online(agent)
    sock = _send_upload(agent, device, "endless.svg", _slow_svg(990))
    try:
        wait_for(lambda: _held_by(agent, device, "endless.svg"), "the upload being checked")
        agent.process.send_signal(signal.SIGTERM)
        assert agent.process.wait(60) == 0
    finally:
        sock.close()
    _, stderr = agent.stop()
    assert "Traceback" not in stderr
    assert f"POST /api/v1/devices/{device}/jobs: the agent stopped before answering it" in stderr


def test_a_job_cancelled_while_its_drawing_is_planned_stops_before_drawing(agent: RunningAgent) -> None:
    device = _arm_online(agent)
    with agent.client() as client:
        position = client.get(f"/api/v1/devices/{device}/state").json()["status"]
        job = client.post(f"/api/v1/devices/{device}/jobs", params={"filename": "slow.svg"}, content=_slow_svg(400),
                          headers={"content-type": "application/octet-stream"}, timeout=300)
        assert job.status_code == 201, job.text
        assert client.get(f"/api/v1/jobs/{job.json()['id']}").json()["progress_percent"] == 0  # still planning
        cancelled = client.post(f"/api/v1/jobs/{job.json()['id']}/cancel", json={"confirm": True})
        assert cancelled.status_code == 200, cancelled.text
        assert cancelled.json()["state"] == "cancelled"
        assert client.get(f"/api/v1/devices/{device}/state").json()["status"] == position  # the arm never moved
