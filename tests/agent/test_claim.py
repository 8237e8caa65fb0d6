"""One job per machine: the claim is taken before a byte of the upload is read, atomically, and every job record
ends in the state the machine is really in. In-process, on in-process simulators (`sim://`)."""

from __future__ import annotations

import asyncio
import os
import random
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fabwire.agent.core import Agent, DeviceSpec
from fabwire.agent.jobs import UploadTooLarge
from fabwire.errors import DeviceBusy, InputError

GCODE = b"G28\n" + b"".join(b"G1 X%d Y%d E%d F600\n" % (i % 100, (i * 7) % 100, i) for i in range(3000))


async def started_agent(tmp_path: Path, max_upload: int = 10 * 1024 * 1024) -> tuple[Agent, str]:
    agent = Agent(state_dir=tmp_path / "state", max_upload_bytes=max_upload)
    await agent.start()
    info = await agent.add_device(DeviceSpec("p", "xyz", "sim://xyz?speed=30"))
    for _ in range(200):
        if agent.state(info.id)["online"] and agent.state(info.id)["summary"]["state"] == "idle":
            break
        await asyncio.sleep(0.05)
    return agent, info.id


async def chunks(data: bytes, size: int, pauses: list[float]) -> AsyncIterator[bytes]:
    """The upload as a client sends it: in pieces, with pauses between (where other requests interleave)."""
    for n, start in enumerate(range(0, len(data), size)):
        yield data[start:start + size]
        await asyncio.sleep(pauses[n % len(pauses)])


def uploads(agent: Agent) -> list[str]:
    assert agent.state_dir is not None
    where = agent.state_dir / "uploads"
    return sorted(os.listdir(where)) if where.exists() else []


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(count=st.integers(2, 12), seed=st.integers(0, 2**16))
def test_of_simultaneous_uploads_exactly_one_runs(tmp_path_factory: pytest.TempPathFactory, count: int,
                                                  seed: int) -> None:
    tmp_path = tmp_path_factory.mktemp("claim")

    async def run() -> None:
        agent, device = await started_agent(tmp_path)
        shuffle = random.Random(seed)
        try:
            results = await asyncio.gather(*(
                agent.upload_job(device, f"p{n}.gcode",
                                 chunks(GCODE, shuffle.randint(1000, 20000), [shuffle.random() / 100]))
                for n in range(count)), return_exceptions=True)
            accepted = [r for r in results if isinstance(r, dict)]
            refused = [r for r in results if not isinstance(r, dict)]
            assert len(accepted) == 1, results
            assert all(isinstance(r, DeviceBusy) for r in refused), refused
            assert all("busy with job" in str(r) or "taking another job" in str(r) for r in refused)
            jobs = await agent.jobs.list()
            assert [j["id"] for j in jobs] == [accepted[0]["id"]]  # no record for a refused upload
            assert agent.state(device)["job"]["id"] == accepted[0]["id"]  # the machine's job is the record's
            assert uploads(agent) == [accepted[0]["stored"]]  # no file for a refused upload
        finally:
            await agent.stop()

    asyncio.run(run())


async def test_the_job_that_prints_is_the_one_on_record_and_cancels(tmp_path: Path) -> None:
    agent, device = await started_agent(tmp_path)
    try:
        results = await asyncio.gather(*(agent.upload_job(device, f"p{n}.gcode", chunks(GCODE, 8192, [0.001]))
                                         for n in range(8)), return_exceptions=True)
        [job] = [r for r in results if isinstance(r, dict)]
        for _ in range(600):
            if agent.state(device)["summary"]["state"] == "printing":
                break
            await asyncio.sleep(0.05)
        record = await agent.jobs.get(job["id"])
        assert (agent.state(device)["job"] or {}).get("id") == job["id"], (record, agent.state(device)["summary"])
        assert record["state"] == "running"
        done = await agent.cancel_job(job["id"], confirm=True)
        assert done["state"] == "cancelled"
        assert agent.state(device)["job"] is None
        again = await agent.upload_job(device, "next.gcode", chunks(GCODE, 50_000, [0]))
        assert again["state"] in ("queued", "running")
    finally:
        await agent.stop()


async def test_an_abandoned_upload_frees_the_machine_and_leaves_no_file(tmp_path: Path) -> None:
    agent, device = await started_agent(tmp_path)
    try:
        async def gone() -> AsyncIterator[bytes]:
            yield GCODE[:10_000]
            raise ConnectionResetError("the client went away")

        first = asyncio.create_task(agent.upload_job(device, "a.gcode", gone()))
        with pytest.raises(ConnectionResetError):
            await first
        assert uploads(agent) == []
        job = await agent.upload_job(device, "b.gcode", chunks(GCODE, 10_000, [0]))
        assert [j["id"] for j in await agent.jobs.list()] == [job["id"]]
    finally:
        await agent.stop()


async def test_a_claim_blocks_job_actions_and_uploads_until_released(tmp_path: Path) -> None:
    agent, device = await started_agent(tmp_path)
    try:
        claim = agent.claim_job(device, "a.gcode")
        with pytest.raises(DeviceBusy, match=r"taking another job \(upload of 'a.gcode'\)"):
            agent.claim_job(device, "b.gcode")
        with pytest.raises(DeviceBusy):
            await agent.start_job(device, "c.gcode", GCODE)
        claim.release()
        job = await agent.start_job(device, "c.gcode", GCODE)
        with pytest.raises(DeviceBusy, match=f"busy with job {job['id']}"):
            agent.claim_job(device, "d.gcode")
    finally:
        await agent.stop()


@pytest.mark.parametrize(("name", "data", "error", "words"), [
    ("big.gcode", GCODE * 50, UploadTooLarge, "limit"),
    ("empty.gcode", b"", InputError, "empty"),
    ("image.gcode", b"\x89PNG\r\n\x1a\n" + bytes(2000), InputError, "image.gcode"),
    ("model.stl", b"solid x\n", InputError, "takes"),
])
async def test_a_refused_upload_releases_the_machine(tmp_path: Path, name: str, data: bytes,
                                                     error: type[Exception], words: str) -> None:
    agent, device = await started_agent(tmp_path, max_upload=len(GCODE) * 2)
    try:
        with pytest.raises(error, match=words):
            await agent.upload_job(device, name, chunks(data, 4096, [0]))
        assert uploads(agent) == []
        assert await agent.jobs.list() == []
        job = await agent.upload_job(device, "fine.gcode", chunks(GCODE, 4096, [0]))
        assert job["size_bytes"] == len(GCODE)
    finally:
        await agent.stop()
