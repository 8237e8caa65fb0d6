"""Notifications: each rule from events alone, the thumbnails slicers embed, and real deliveries through Apprise to
a JSON webhook on loopback from a running agent."""

from __future__ import annotations

import base64
import io
import json
import subprocess
import sys
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest
from PIL import Image

from clitools import cli_env
from fabwire.agent.notify import RULES, NoticeWatch, check_urls
from fabwire.errors import InputError
from fabwire.samples import SAMPLE_GCODE, sample_path

from .agenttools import device_of, summary, wait_for
from .conftest import Bench, start_bench, stop_bench
from .doortools import thumbnail_block

# ---------------------------------------------------------------------------------------------- events → notices

def _state(device: str, kind: str, state: str, *, job: dict[str, Any] | None = None, **extra: Any) -> dict[str, Any]:
    return {"device": device, "type": "state", "state": {"name": device, "kind": kind, "job": job,
                                                        "summary": {"state": state, **extra}}}


def _job(device: str, state: str, **extra: Any) -> dict[str, Any]:
    return {"device": device, "type": "job", "job": {"id": "j1", "device": device, "type": "print",
                                                    "filename": "cube.gcode", "state": state, **extra}}


RUNNING = {"id": "j1", "state": "running"}
SCENARIOS: dict[str, list[tuple[list[dict[str, Any]], str]]] = {
    # rule → (events, words the message must hold); every row of RULES has at least one
    "finished": [
        ([_state("p", "xyz", "idle"), _state("p", "xyz", "printing", job=RUNNING),
          _job("p", "done", message="print done after 20 s"), _state("p", "xyz", "printing"),
          _state("p", "xyz", "done")], "cube.gcode finished: print done after 20 s"),
        ([_state("p", "xyz", "idle"), _state("p", "xyz", "printing"), _state("p", "xyz", "done")],
         "The print finished"),  # started on the printer's panel
        ([_state("p", "xyz", "printing"), {"device": "p", "type": "offline", "reason": "gone"},
          _state("p", "xyz", "offline"), _state("p", "xyz", "done")], "The print finished"),  # ended while unseen
    ],
    "failed": [
        ([_state("p", "xyz", "printing", job=RUNNING), _job("p", "failed", message="the printer became idle")],
         "cube.gcode failed: the printer became idle"),
        ([_state("p", "xyz", "printing"), _state("p", "xyz", "error", error="extruder heater timeout")],
         "extruder heater timeout"),
    ],
    "cancelled": [
        ([_state("p", "xyz", "printing", job=RUNNING), _job("p", "cancelled", progress_percent=42.0)],
         "cube.gcode was cancelled at 42 %"),
        ([_state("p", "xyz", "printing"), _state("p", "xyz", "paused"), _state("p", "xyz", "idle")],
         "cancelled on the printer"),
    ],
    "mmu-error": [
        ([_state("m", "mmu", "idle"), _state("m", "mmu", "busy"),
          _state("m", "mmu", "error", state_text="FINDA didn't trigger", actions=["retry", "stop"])],
         "FINDA didn't trigger. The MMU waits for Retry or Stop"),
    ],
    "offline": [
        ([{"device": "p", "type": "online"}, _state("p", "xyz", "idle"),
          {"device": "p", "type": "offline", "reason": "connection refused"}], "connection refused"),
    ],
}


def test_every_rule_has_scenarios() -> None:
    assert set(SCENARIOS) == {r.name for r in RULES}


def _notices(events: list[dict[str, Any]], *, later: float = 0.0) -> list[Any]:
    watch = NoticeWatch(offline_after_s=30.0)
    out = [n for e in events for n in watch.feed(e, 0.0)]
    return out + watch.due(later)


@pytest.mark.parametrize(("rule", "events", "words"),
                         [(rule, events, words) for rule, rows in SCENARIOS.items() for events, words in rows])
def test_each_rule_is_announced_once_in_words(rule: str, events: list[dict[str, Any]], words: str) -> None:
    notices = _notices(events, later=31.0)
    assert [n.rule for n in notices] == [rule], notices
    assert words in notices[0].body
    assert notices[0].title.startswith(events[0]["device"])
    # the last event told again (a reconnect replays the last state) says nothing new
    watch = NoticeWatch(offline_after_s=30.0)
    told = [n for e in [*events, events[-1]] for n in watch.feed(e, 0.0)] + watch.due(31.0) + watch.due(62.0)
    assert len(told) == 1


@pytest.mark.parametrize(("events", "expected"), [
    ([_state("p", "xyz", "idle"), _state("p", "xyz", "busy"), _state("p", "xyz", "idle")], []),  # homing
    ([{"device": "p", "type": "offline", "reason": "never there"}], []),  # never online: nothing was lost
    ([{"device": "p", "type": "online"}, {"device": "p", "type": "offline", "reason": "blip"},
      {"device": "p", "type": "online"}], []),  # back before the delay
    ([_state("m", "mmu", "error", state_text="x", actions=["stop"]), _state("m", "mmu", "offline"),
      _state("m", "mmu", "error", state_text="x", actions=["stop"])], ["mmu-error"]),  # one error, a link drop
    ([_state("p", "xyz", "printing", job=RUNNING), _state("p", "xyz", "done", job=RUNNING),
      _job("p", "done"), _job("p", "done")], ["finished"]),  # the job's end told twice
    ([_state("m", "mmu", "idle"), _state("m", "mmu", "error", state_text="x", actions=["retry", "stop"]),
      _state("m", "mmu", "busy")], []),  # retried (by the host) before anyone had to come
], ids=["busy", "never-online", "blip", "same-error", "job-twice", "mmu-healed"])
def test_what_is_not_news_is_not_announced(events: list[dict[str, Any]], expected: list[str]) -> None:
    assert [n.rule for n in _notices(events, later=31.0)] == expected


def test_offline_waits_for_the_delay() -> None:
    events = SCENARIOS["offline"][0][0]
    assert _notices(events, later=29.0) == []
    watch = NoticeWatch(offline_after_s=30.0)
    for event in events:
        watch.feed(event, 100.0)
    assert [n.rule for n in watch.due(130.0)] == ["offline"]
    assert watch.due(200.0) == []  # once per outage


@pytest.mark.parametrize("url", ["bogus://x", "not a url", "mailto://", "json:/x"])
def test_a_url_apprise_cannot_use_is_an_input_error(url: str) -> None:
    with pytest.raises(InputError, match="Apprise cannot send to"):
        check_urls([url])


def test_a_bad_url_stops_serve_with_one_line(tmp_path: Path) -> None:
    secret = "pover://SECRETTOKEN"  # Pushover needs a user key and a token: this is half a URL
    run = subprocess.run([sys.executable, "-m", "fabwire", "serve", "--state-dir", str(tmp_path), "--listen",
                          "127.0.0.1:0", "--notify", "json://127.0.0.1:9/ok", "--notify", secret],
                         capture_output=True, text=True, timeout=60, env=cli_env(tmp_path))
    assert run.returncode == 4, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1, run.stderr
    assert "--notify" in lines[0]
    assert "pover://" in lines[0]
    assert "SECRET" not in run.stderr
    assert not list(tmp_path.iterdir())  # nothing started, not even a token


# ---------------------------------------------------------------------------------------------- thumbnails

def with_thumbnails(*blocks: str) -> bytes:
    """The sample print with these preview blocks in its leading comments (the blocks are read by
    `fabwire.thumbnails`, tested in tests/test_thumbnails.py)."""
    return (b"; generated by PrusaSlicer 2.8.1\n;\n" + "".join(blocks).encode()
            + sample_path(SAMPLE_GCODE).read_bytes())


# ---------------------------------------------------------------------------------------------- real deliveries

class Receiver:
    """A JSON webhook on loopback: every POST body it was sent, in order."""

    def __init__(self) -> None:
        received: list[dict[str, Any]] = []
        self.received = received

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                length = int(self.headers.get("content-length", "0"))
                received.append({"path": self.path, **json.loads(self.rfile.read(length))})
                self.send_response(200)
                self.end_headers()

            def log_message(self, *args: Any) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.port = self.server.server_address[1]
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def titled(self, words: str) -> list[dict[str, Any]]:
        return [r for r in self.received if words in r["title"]]

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture(scope="module")
def receiver() -> Iterator[Receiver]:
    running = Receiver()
    yield running
    running.close()


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory, receiver: Receiver) -> Iterator[Bench]:
    running = start_bench(Path(tmp_path_factory.mktemp("notify")) / "state",
                          "--notify", f"json://127.0.0.1:{receiver.port}/hook", "--notify-offline-after", "1")
    yield running
    stop_bench(running)


def test_a_finished_print_arrives_with_its_thumbnail(bench: Bench, receiver: Receiver) -> None:
    data = with_thumbnails(thumbnail_block(16, 16, "png"), thumbnail_block(64, 48, "png"))
    with bench.agent.client() as client:
        printer = device_of(client, "xyz")
        wait_for(lambda: summary(client, printer["id"])["state"] == "idle", "the printer idle")
        job = client.post(f"/api/v1/devices/{printer['id']}/jobs", params={"filename": "cube.gcode"}, content=data)
        assert job.status_code == 201, job.text
        message = wait_for(lambda: receiver.titled("print finished"), "the finished message", timeout=120)[0]
        assert message["path"] == "/hook"
        assert message["title"] == "printer: print finished"
        assert message["message"].startswith("cube.gcode finished")
        assert message["type"] == "success"
        [attachment] = message["attachments"]
        assert attachment["mimetype"] == "image/png"
        with Image.open(io.BytesIO(base64.b64decode(attachment["base64"]))) as image:
            assert image.size == (64, 48)  # the largest thumbnail the slicer embedded
        finished = wait_for(lambda: (s := summary(client, printer["id"]))["state"] == "done" and s,
                            "the printer showing print finished")  # until it is acknowledged
        assert (finished["state"], finished["progress_percent"], finished["time_left_s"]) == ("done", 100, 0)
        assert client.post(f"/api/v1/devices/{printer['id']}/actions/acknowledge", json={}).status_code == 200
        wait_for(lambda: summary(client, printer["id"])["state"] == "idle", "the printer idle again")
    assert len(receiver.titled("print finished")) == 1  # the job's end and the printer's done screen: one message


def test_a_cancelled_drawing_arrives_with_the_drawing(bench: Bench, receiver: Receiver) -> None:
    with bench.agent.client() as client:
        arm = device_of(client, "lineus")
        wait_for(lambda: summary(client, arm["id"])["state"] == "idle", "the Line-us idle")
        job = client.post(f"/api/v1/devices/{arm['id']}/actions/text", json={"text": "a long line to stop"}).json()
        wait_for(lambda: client.get(f"/api/v1/devices/{arm['id']}/drawing").json()["ink"], "ink on the paper")
        assert client.post(f"/api/v1/jobs/{job['job']['id']}/cancel", json={"confirm": True}).status_code == 200
        message = wait_for(lambda: receiver.titled("drawing cancelled"), "the cancelled message")[0]
    assert message["title"] == "arm: drawing cancelled"
    assert message["type"] == "warning"
    [attachment] = message["attachments"]
    assert base64.b64decode(attachment["base64"]).startswith(b"\x89PNG")


def test_an_mmu_error_waiting_arrives(bench: Bench, receiver: Receiver) -> None:
    with bench.agent.client() as client:
        mmu = device_of(client, "mmu")
        wait_for(lambda: summary(client, mmu["id"])["state"] == "idle", "the MMU idle")
        client.post(f"/api/v1/devices/{mmu['id']}/actions/tool_change", json={"slot": 0})
        wait_for(lambda: "T0 finished" in summary(client, mmu["id"])["state_text"], "T0 finished")
        client.post(f"/api/v1/devices/{mmu['id']}/actions/tool_change", json={"slot": 1})  # its feed fails
        wait_for(lambda: summary(client, mmu["id"])["state"] == "error", "the MMU waiting on its error")
        message = wait_for(lambda: receiver.titled("MMU error"), "the MMU error message", timeout=90)[0]
        assert message["title"] == "mmu: MMU error waiting"
        assert "FINDA" in message["message"]
        assert "Retry" in message["message"]
        client.post(f"/api/v1/devices/{mmu['id']}/actions/retry", json={})


def test_a_failed_print_arrives(bench: Bench, receiver: Receiver, simulator: Any) -> None:
    refusing = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "30", "--fault", "file-rejected")
    with bench.agent.client() as client:
        added = client.post("/api/v1/devices", json={"name": "fussy", "kind": "xyz", "address": refusing.url}).json()
        wait_for(lambda: summary(client, added["id"])["state"] == "idle", "the second printer idle")
        client.post(f"/api/v1/devices/{added['id']}/jobs", params={"filename": "cube.gcode"},
                    content=sample_path(SAMPLE_GCODE).read_bytes())
        message = wait_for(lambda: receiver.titled("fussy: print failed"), "the failed message", timeout=90)[0]
        assert message["type"] == "failure"
        assert message["message"].startswith("cube.gcode failed: ")
        assert client.delete(f"/api/v1/devices/{added['id']}").status_code == 204


def test_a_machine_gone_offline_arrives(bench: Bench, receiver: Receiver) -> None:
    with bench.agent.client() as client:
        printer = device_of(client, "xyz")
        wait_for(lambda: summary(client, printer["id"])["state"] != "offline", "the printer online")
        bench.xyz.stop()
        message = wait_for(lambda: receiver.titled("printer is offline"), "the offline message", timeout=60)[0]
    assert "has not answered for" in message["message"]
    assert len(receiver.titled("printer is offline")) == 1
