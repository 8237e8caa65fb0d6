"""Upload names through every door of a real `fabwire serve`: a name holding a character that hides or changes
what it shows (rule `file-hidden` of `fabwire.checks.RULES`) is refused with 400 and the rule's words before the
machine is claimed, whichever door it came in by; names in any script are taken as written."""

from __future__ import annotations

import json
from collections.abc import Iterator

import httpx
import pytest

from fabwire.checks import RULES

from .agenttools import RunningAgent, start_agent, wait_for
from .doortools import multipart

PRINTER = "p:xyz=sim://xyz?speed=30"
GCODE = b"G28\nG1 X10 Y10 Z0.2 F1200\nG1 X20 Y10 E1\nM84\n"
HIDDEN = ["part\u202e.gcode", "\u2067part.gcode", "part\u200b.gcode", "\ufeffpart.gcode", "part\u2028.gcode",
          "a\x1b[31mred\x07.gcode", "fake\x08\x0bline.gcode", "tag\U000e0041.gcode", "filler\u3164.gcode"]
"""Right-to-left override, right-to-left isolate, zero-width space, byte order mark, line separator, a terminal's
escape sequence and bell, a backspace and a vertical tab, a tag character, a Hangul filler."""
DOORS = ["native", "octoprint", "moonraker"]


@pytest.fixture(scope="module")
def agent(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningAgent]:
    running = start_agent(tmp_path_factory.mktemp("names") / "state", "--device", PRINTER)
    yield running
    _, stderr = running.stop()
    assert "Traceback" not in stderr


def device_of(agent: RunningAgent) -> str:
    with agent.client() as client:
        return str(wait_for(lambda: next((d["id"] for d in client.get("/api/v1/devices").json()
                                          if d["state"]["online"]), None), "the printer online"))


def upload(client: httpx.Client, door: str, device: str, name: str) -> httpx.Response:
    """An upload of GCODE named `name` without printing it (the native door always starts: its job is cancelled)."""
    if door == "native":
        return client.post(f"/api/v1/devices/{device}/jobs", params={"filename": name}, content=GCODE,
                           headers={"content-type": "application/octet-stream"})
    fields = [("path", "")] if door == "octoprint" else [("root", "gcodes")]
    body, ctype = multipart(fields, name, GCODE)
    path = "/api/files/local" if door == "octoprint" else "/server/files/upload"
    return client.post(path, content=body, headers={"content-type": ctype})


def words(response: httpx.Response) -> str:
    """The answer's text with JSON escapes read (each door has its own error shape)."""
    return json.dumps(response.json(), ensure_ascii=False)


@pytest.mark.parametrize("name", HIDDEN)
@pytest.mark.parametrize("door", DOORS)
def test_a_name_that_hides_what_it_shows_is_refused_at_every_door(agent: RunningAgent, door: str, name: str) -> None:
    device = device_of(agent)
    with agent.client() as client:
        refused = upload(client, door, device, name)
        assert refused.status_code == 400, refused.text
        assert "which hides or changes what the name shows" in words(refused)
        assert RULES["file-hidden"].why.split("{char}")[1].strip() in words(refused)
        listed = client.get("/api/files/local").json()
        assert all(name not in str(entry) for entry in listed.get("files", [])), listed
        assert not [job for job in client.get("/api/v1/jobs").json() if job.get("filename") == name]


@pytest.mark.parametrize("door", ["octoprint", "moonraker"])
def test_names_in_any_script_are_kept_as_written(agent: RunningAgent, door: str) -> None:
    device = device_of(agent)
    name = f"\u0645\u06cc\u200c\u062e\u0648\u0627\u0647\u0645-{door}.gcode"  # Persian: a zero-width non-joiner
    with agent.client() as client:
        taken = upload(client, door, device, name)
        assert taken.status_code in (200, 201), taken.text
        names = [entry["name"] for entry in client.get("/api/files/local").json()["files"]]
        assert name in names, names


@pytest.mark.parametrize("door", ["octoprint", "moonraker"])
def test_composed_and_decomposed_accents_name_one_file(agent: RunningAgent, door: str) -> None:
    device = device_of(agent)
    composed = f"caf\u00e9-{door}.gcode"
    decomposed = f"cafe\u0301-{door}.gcode"  # as macOS file names and copies from PDFs spell it
    with agent.client() as client:
        for name in (decomposed, composed):
            taken = upload(client, door, device, name)
            assert taken.status_code in (200, 201), taken.text
        names = [entry["name"] for entry in client.get("/api/files/local").json()["files"]]
        assert names.count(composed) == 1, names
        assert decomposed not in names, names
