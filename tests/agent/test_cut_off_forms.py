"""A multipart upload that was cut off (its form ends before the closing boundary) sent to a real `fabwire serve`
through every door that reads forms: 400 with the reason, nothing kept, no job, the machine free."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from .agenttools import RunningAgent, start_agent
from .doortools import XYZ, multipart, prusaslicer_gcode, wait_idle

CUT_OFF: dict[str, tuple[str, Callable[[bytes, bytes], bytes]]] = {
    "no-close-delimiter": ("RFC 2046 §5.1.1: a body ends with the close-delimiter CRLF '--' boundary '--'; a form "
                           "that stops after the file's CRLF (curl --data-binary of a hand-made form) has none",
                           lambda body, b: body[:body.rindex(b"--" + b)]),
    "cut-in-the-file": ("a connection dropped mid-file (by a proxy, a client that then sends what it had, with a "
                        "Content-Length that matches)", lambda body, b: body[:body.rindex(b"--" + b) - 2000]),
    "cut-in-the-delimiter": ("RFC 2046 §5.1.1: the body stops inside the close-delimiter",
                             lambda body, b: body[:body.rindex(b"--" + b) + 2 + len(b) // 2]),
    "delimiter-without-close": ("RFC 2046 §5.1.1: '--' boundary without the final '--' is no close-delimiter",
                                lambda body, b: body[:body.rindex(b"--" + b) + 2 + len(b)]),
    "another-part-opened": ("RFC 2046 §5.1.1: '--' boundary CRLF opens another body part, which never comes",
                            lambda body, b: body[:body.rindex(b"--" + b) + 2 + len(b)] + b"\r\n"),
}
"""How a form may end before its closing boundary, each with its source: the whole form and its boundary → the
bytes sent (with a Content-Length that matches them)."""

DOORS: dict[str, tuple[str, list[tuple[str, str]]]] = {
    "octoprint": ("/api/files/local", [("print", "true"), ("path", "")]),  # PrusaSlicer's OctoPrint upload
    "octoprint-by-name": (f"/printers/{XYZ}/api/files/local", [("select", "true"), ("print", "false")]),  # Cura
    "moonraker": ("/server/files/upload", [("root", "gcodes"), ("print", "true")]),  # the slicers' Moonraker hosts
    "moonraker-keep": ("/server/files/upload", [("root", "gcodes")]),
}
"""Every route that reads a multipart form, with the fields a slicer sends before the file (print=true claims the
machine before the file is read)."""


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningAgent]:
    agent = start_agent(tmp_path_factory.mktemp("cutoff") / "state", "--demo", "--speed", "30")
    yield agent
    agent.stop()


@pytest.mark.parametrize("door", DOORS, ids=list(DOORS))
@pytest.mark.parametrize("shape", CUT_OFF, ids=list(CUT_OFF))
def test_a_form_cut_off_before_its_closing_boundary_is_400_and_nothing_is_kept(demo: RunningAgent, door: str,
                                                                              shape: str) -> None:
    path, fields = DOORS[door]
    name = f"cut_{door}_{shape}.gcode".replace("-", "_")
    body, ctype = multipart(fields, name, prusaslicer_gcode())
    with demo.client() as client:
        wait_idle(client)
        before = client.get("/api/v1/jobs").json()
        sent = CUT_OFF[shape][1](body, ctype.rpartition("=")[2].encode())
        response = client.post(path, content=sent, headers={"Content-Type": ctype})
        assert response.status_code == 400, response.text
        assert "ends before its closing boundary" in response.text
        assert name not in client.get("/api/files").text
        assert name not in client.get("/server/files/list", params={"root": "gcodes"}).text
        assert client.get("/api/v1/jobs").json() == before  # no job, none started
        # the machine is free: the same form, whole, is taken and kept
        whole = client.post(path, content=body, headers={"Content-Type": ctype})
        assert whole.status_code == 201, whole.text
        assert name in client.get("/api/files").text
        wait_idle(client)  # (a print started by the whole form is a short one)

