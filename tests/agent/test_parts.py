"""The agent's parts in-process: ids, parameter checks, history, uploads, subscriptions and the token guard."""

from __future__ import annotations

import asyncio
import os
import re
import stat
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fabwire.agent.auth import is_loopback, load_or_create_token
from fabwire.agent.boundary import Boundary, Policy
from fabwire.agent.core import SUBSCRIBER_QUEUE, Agent, device_id, make_event
from fabwire.agent.drivers.base import SUMMARY_KEYS, Action, Param, checked_params, summary
from fabwire.agent.drivers.lineus import LineUsDriver
from fabwire.agent.drivers.mmu import MMUDriver
from fabwire.agent.drivers.xyz import XYZDriver, printer_summary
from fabwire.agent.history import History
from fabwire.agent.jobs import JobStore, UploadTooLarge, new_job_id
from fabwire.errors import InputError
from fabwire.xyz.status import Status

URL_SAFE = re.compile(r"^[a-z0-9][a-z0-9-]*$")


@given(kind=st.sampled_from(["xyz", "lineus", "mmu"]), serial=st.none() | st.text(max_size=30),
       address=st.text(min_size=1, max_size=60))
def test_device_ids_are_url_safe_and_deterministic(kind: str, serial: str | None, address: str) -> None:
    made = device_id(kind, serial, address, host="bench-pc")
    assert URL_SAFE.match(made), made
    assert made.startswith(f"{kind}-")
    assert made == device_id(kind, serial, address, host="bench-pc")


def test_local_addresses_are_qualified_by_host_and_serials_win() -> None:
    assert device_id("mmu", None, "/dev/ttyACM0", host="pi") != device_id("mmu", None, "/dev/ttyACM0", host="pc")
    assert device_id("xyz", None, "tcp://127.0.0.1:9100", host="pi") == "xyz-pi-tcp-127-0-0-1-9100"
    assert device_id("xyz", None, "192.168.1.50", host="pi") == device_id("xyz", None, "192.168.1.50", host="pc")
    assert device_id("xyz", "3FM1WPUS5SIM000688", "/dev/ttyACM0", host="pi") == "xyz-3fm1wpus5sim000688"
    assert device_id("xyz", "  ", "10.0.0.2", host="pi") == "xyz-10-0-0-2"


JOG = Action("jog", "Move one axis.", (Param("axis", "str", "x, y or z", choices=("x", "y", "z")),
                                       Param("distance_mm", "float", "mm", -200, 200, nonzero=True)))


def test_parameters_are_checked_by_type_range_and_name() -> None:
    assert checked_params(JOG, {"axis": "x", "distance_mm": 5}) == {"axis": "x", "distance_mm": 5.0}
    for bad, words in (({"axis": "w", "distance_mm": 1}, "one of x, y, z"),
                       ({"axis": "x", "distance_mm": 500}, "from -200 to 200"),
                       ({"axis": "x", "distance_mm": True}, "number"),
                       ({"axis": "x", "distance_mm": "1"}, "number"),
                       ({"axis": "x", "distance_mm": float("nan")}, "finite number"),
                       ({"axis": "x", "distance_mm": float("-inf")}, "finite number"),
                       ({"axis": "x", "distance_mm": 0}, "must not be 0"),
                       ({"axis": "x"}, "needs the parameter 'distance_mm'"),
                       ({"axis": "x", "distance_mm": 1, "speed": 3}, "no parameter 'speed'")):
        with pytest.raises(InputError, match=re.escape(words)):
            checked_params(JOG, bad)


@pytest.mark.parametrize("action", [a for d in (XYZDriver, LineUsDriver, MMUDriver) for a in d.actions if a.confirm],
                         ids=lambda a: a.name)
def test_an_unconfirmed_step_says_in_words_what_confirming_does(action: Action) -> None:
    with pytest.raises(InputError) as refused:
        checked_params(action, {p.name: p.low if p.low is not None else "x" for p in action.params})
    what = action.doc.split(". ")[0].rstrip(".")  # its first sentence, as a clause: "to cancel the print"
    assert str(refused.value) == (f'{action.name} cannot be undone: send "confirm": true to '
                                  f"{what[:1].lower()}{what[1:]}")


def test_destructive_actions_need_confirm_true() -> None:
    reset = Action("reset", "Restart the MMU.", confirm=True)
    with pytest.raises(InputError, match="confirm"):
        checked_params(reset, {})
    with pytest.raises(InputError, match="confirm"):
        checked_params(reset, {"confirm": "yes"})
    assert checked_params(reset, {"confirm": True}) == {}


def test_summaries_carry_every_key_for_every_kind() -> None:
    assert list(summary()) == list(SUMMARY_KEYS)
    with pytest.raises(KeyError):
        summary(temperature=3)
    status = Status.parse(["j:9511,0", "t:1,200,210", "b:60", "d:42,12,30"])
    printed = printer_summary(status)
    assert list(printed) == list(SUMMARY_KEYS)
    assert printed["extruder_temp_c"] == 200
    assert printed["extruder_target_c"] == 210
    assert printed["bed_temp_c"] == 60
    assert printed["state"] == "idle"
    printing = printer_summary(Status.parse(["j:9505,0", "d:42,12,30"]))
    assert printing["state"] == "printing"
    assert printing["progress_percent"] == 42
    assert printing["time_left_s"] == 30 * 60
    assert printing["actions"] == ["pause", "cancel"]


@pytest.mark.parametrize(("lines", "state", "percent", "time_left_s"), [
    (["j:9505,0", "d:42,12,30"], "printing", 42, 30 * 60),
    (["j:9509,0", "d:0,0,0"], "done", 100, 0),  # "print finished": the printer zeroes d:
    (["j:9509,0", "d:0,0,0", "e:525"], "error", 0, 0),  # ended on an error: not finished
    (["j:9511,0", "d:0,0,0"], "idle", 0, 0),
])
def test_the_printer_summary_progress_follows_the_print_to_its_end(lines: list[str], state: str, percent: int,
                                                                   time_left_s: int) -> None:
    printed = printer_summary(Status.parse(lines))
    assert (printed["state"], printed["progress_percent"], printed["time_left_s"]) == (state, percent, time_left_s)


async def test_history_keeps_changes_drops_repeats_and_expires_old_rows(tmp_path: Path) -> None:
    history = History(tmp_path / "h.sqlite3", retention_s=3600)
    await history.open()
    now = time.time()
    base = summary(state="idle", extruder_temp_c=20)
    history.record_sample("d", now - 7200, base)  # older than the retention
    history.record_sample("d", now - 10, base)
    history.record_sample("d", now - 9, base)  # the same numbers a second later: not kept
    history.record_sample("d", now - 8, summary(state="idle", extruder_temp_c=21))
    history.record_sample("other", now - 8, base)
    await history.close()
    history = History(tmp_path / "h.sqlite3", retention_s=3600)
    await history.open()  # opening prunes what the retention no longer covers
    rows = await history.samples("d", now - 100_000, now, 100)
    assert [r["extruder_temp_c"] for r in rows] == [20, 21]
    assert [r["ts"] for r in rows] == [pytest.approx(now - 10), pytest.approx(now - 8)]
    assert len(await history.samples("d", now - 100_000, now, 1)) == 1
    await history.close()


async def stored_upload(store: JobStore, name: str, data: bytes) -> dict[str, Any]:
    """An upload written as the agent writes one (in chunks), then put on record."""
    job_id = new_job_id()
    writer = store.writer(job_id, name)
    for i in range(0, len(data), 3):
        await writer.write(data[i:i + 3])
    await writer.finish()
    return await store.create("d", "print", name, writer, {}, job_id=job_id)


async def test_uploads_get_generated_names_whatever_they_are_called(tmp_path: Path) -> None:
    history = History(None, retention_s=60)
    await history.open()
    store = JobStore(history, tmp_path / "uploads", max_upload_bytes=100)
    names = ["../../etc/passwd.gcode", "/abs/x.SVG", "a\x00b.3w", "con.gcode", "..svg"]
    made = [await stored_upload(store, name, b"G28\n") for name in names]
    with pytest.raises(InputError, match="cannot tell what"):
        await stored_upload(store, "x.gcode;rm -rf", b"G28\n")
    for job in made:
        assert re.fullmatch(r"[0-9a-f]{16}\.(gcode|svg|3w)", job["stored"]), job
        path = store.path_of(job)
        assert path is not None
        assert path.parent == tmp_path / "uploads"
        assert path.read_bytes() == b"G28\n"
        assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert stat.S_IMODE((tmp_path / "uploads").stat().st_mode) == 0o700
    assert sorted(p.name for p in (tmp_path / "uploads").iterdir()) == sorted(j["stored"] for j in made)
    with pytest.raises(UploadTooLarge):
        await stored_upload(store, "x.gcode", b"x" * 101)
    with pytest.raises(InputError, match="empty"):
        await stored_upload(store, "x.gcode", b"")
    assert sorted(p.name for p in (tmp_path / "uploads").iterdir()) == sorted(j["stored"] for j in made)
    await history.close()


async def test_uploads_go_with_their_job_records(tmp_path: Path) -> None:
    """The retention prunes a job record and its stored file with it; a `.part` nobody writes goes too, one
    being written stays."""
    history = History(tmp_path / "history.sqlite3", retention_s=3600)
    await history.open()
    store = JobStore(history, tmp_path / "uploads", max_upload_bytes=100)
    old = await stored_upload(store, "old.gcode", b"G28\n")
    new = await stored_upload(store, "new.gcode", b"G28\n")
    orphan = tmp_path / "uploads" / "0123456789abcdef.gcode"
    orphan.write_bytes(b"G28\n")
    stale = tmp_path / "uploads" / ".fedcba9876543210.part"
    stale.write_bytes(b"G2")
    receiving = store.writer(new_job_id(), "busy.gcode")
    await receiving.write(b"x" * 50)
    await receiving._flush()
    old["created"] = "2001-01-01T00:00:00.000Z"
    await history.save_job(old)
    await history._call(history._prune)
    left = sorted(p.name for p in (tmp_path / "uploads").iterdir())
    assert left == sorted([new["stored"], receiving.part])
    assert await history.job(old["id"]) is None
    receiving.discard()
    assert sorted(p.name for p in (tmp_path / "uploads").iterdir()) == [new["stored"]]
    await history.close()
    assert stat.S_IMODE((tmp_path / "history.sqlite3").stat().st_mode) == 0o600


@settings(max_examples=50, deadline=None)
@given(name=st.text(max_size=80))
def test_no_upload_name_reaches_the_file_system(name: str) -> None:
    async def run() -> None:
        history = History(None, retention_s=60)
        await history.open()
        import tempfile

        with tempfile.TemporaryDirectory() as where:
            store = JobStore(history, Path(where) / "uploads", max_upload_bytes=10)
            try:
                job = await stored_upload(store, name, b"M1\n")
            except InputError:
                pass
            else:
                assert re.fullmatch(r"[0-9a-f]{16}\.[a-z0-9]+", job["stored"])
                assert sorted(os.listdir(Path(where) / "uploads")) == [job["stored"]]
        await history.close()

    asyncio.run(run())


async def test_a_slow_subscriber_loses_the_oldest_events_not_the_agent() -> None:
    agent = Agent()
    await agent.start()
    try:
        slow = agent.subscribe()
        for i in range(SUBSCRIBER_QUEUE + 10):
            agent.publish(make_event("d", "event", event={"n": i}))
        assert slow.dropped == 10
        first = await anext(slow)
        assert first["event"]["n"] == 10
        slow.close()
        agent.publish(make_event("d", "event", event={"n": -1}))
        assert slow.dropped == 10
    finally:
        await agent.stop()


def test_token_is_made_once_and_kept_private(tmp_path: Path) -> None:
    token, created = load_or_create_token(tmp_path / "state")
    assert created
    assert len(token) >= 40
    assert load_or_create_token(tmp_path / "state") == (token, False)
    assert (tmp_path / "state" / "access-token").stat().st_mode & 0o077 == 0


@pytest.mark.parametrize(("host", "loopback"), [("127.0.0.1", True), ("::1", True), ("[::1]", True),
                                               ("localhost", True), ("0.0.0.0", False), ("192.168.1.2", False),
                                               ("example.org", False)])
def test_loopback_addresses(host: str, loopback: bool) -> None:
    assert is_loopback(host) is loopback


async def test_token_guard_covers_the_api_but_not_the_page() -> None:
    async def app(scope: dict[str, object], receive: object, send: object) -> None:
        await send({"type": "http.response.start", "status": 200, "headers": []})  # type: ignore[operator]
        await send({"type": "http.response.body", "body": b"ok"})  # type: ignore[operator]

    guarded = Boundary(app, policy=Policy(token="s3cret"), router=SimpleNamespace(routes=[]))
    async with httpx.AsyncClient(transport=httpx.ASGITransport(app=guarded), base_url="http://localhost") as client:
        missing = await client.get("/api/v1/devices")
        assert missing.status_code == 401
        assert missing.json()["message"].startswith("this agent needs its access token")
        wrong = await client.get("/api/v1/devices", headers={"Authorization": "Bearer s3cre"})
        assert wrong.status_code == 401
        assert wrong.json()["message"].startswith("the access token sent is not this agent's")
        assert (await client.get("/api/v1/devices", headers={"Authorization": "Bearer s3cret"})).text == "ok"
        assert (await client.get("/api/v1/devices", headers={"X-Api-Key": "s3cret"})).text == "ok"
        assert (await client.get("/")).text == "ok"
        assert (await client.get("/static/app.js")).text == "ok"
        assert (await client.get("/printer/info")).status_code == 401  # every other path needs it
