"""A G-code that extrudes beyond the connected da Vinci's build volume, sent to a real `fabwire serve` by every
route that keeps or starts a print: the refusal is the HTTP answer (400 with the reason, in words an API user can
act on), no job is recorded and the machine stays free."""

from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest

from .agenttools import RunningAgent, start_agent
from .doortools import multipart, prusaslicer_gcode, wait_idle

MINI = "p:xyz=sim://xyz?model=dv1MW0A000&speed=30"
"""A da Vinci mini w: 150 × 150 × 150 mm."""
WIDE = prusaslicer_gcode() + b"G1 X200 Y10 E5\n"
"""A print that reaches X 200 mm: beyond a mini w (its comments state every figure, so only its moves tell)."""


def _octoprint(client: httpx.Client, name: str, print_: bool) -> httpx.Response:
    body, ctype = multipart([("print", "true" if print_ else "false"), ("path", "")], name, WIDE)
    return client.post("/api/files/local", content=body, headers={"Content-Type": ctype})


ROUTES = {
    "octoprint-upload-print": lambda c, n: _octoprint(c, n, True),  # PrusaSlicer's "Upload and Print"
    "octoprint-upload": lambda c, n: _octoprint(c, n, False),  # PrusaSlicer's "Upload"
    "moonraker-upload-print": lambda c, n: c.post("/server/files/upload", content=(m := multipart(
        [("root", "gcodes"), ("print", "true")], n, WIDE))[0], headers={"Content-Type": m[1]}),
    "api-job": lambda c, n: c.post("/api/v1/devices/p/jobs", params={"filename": n}, content=WIDE,
                                   headers={"Content-Type": "application/octet-stream"}),
}
"""Every route that takes a print file for a printer: the OctoPrint and Moonraker uploads (Moonraker's root
`gcodes` with print, as the slicers' Moonraker hosts send it) and the agent's own job upload."""


@pytest.fixture(scope="module")
def mini(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningAgent]:
    agent = start_agent(tmp_path_factory.mktemp("volume") / "state", "--device", MINI)
    yield agent
    agent.stop()


def _refused(response: httpx.Response, client: httpx.Client, name: str) -> None:
    assert response.status_code == 400, response.text
    assert "moves beyond the da Vinci mini w's build volume" in response.text
    assert "slice it for this printer" in response.text
    assert "--force" not in response.text  # (a command-line flag an API user cannot give)
    assert client.get("/api/v1/jobs").json() == []  # no job recorded, none failed later
    assert name not in client.get("/api/files").text
    assert client.get("/api/v1/devices/p").json()["state"]["summary"]["state"] == "idle"


@pytest.mark.parametrize("route", ROUTES, ids=list(ROUTES))
def test_a_print_beyond_the_build_volume_is_refused_by_the_answer(mini: RunningAgent, route: str) -> None:
    name = f"wide_{route.replace('-', '_')}.gcode"
    with mini.client() as client:
        wait_idle(client, "p")
        _refused(ROUTES[route](client, name), client, name)



TURNING = prusaslicer_gcode() + b"G1 X75 Y40\n" + b"".join(b"G2 X75 Y40 I0 J35 P100 E0.5\n" for _ in range(400))
"""Within a mini w, but each arc asks for a hundred full turns: as segments, far more than the growth limit."""


def test_arcs_that_would_grow_a_print_too_much_are_refused_by_the_answer(mini: RunningAgent) -> None:
    """The conversion before printing would refuse it (`arcwork.GROWTH_ALLOWED`): the upload is refused instead,
    with the advice an API user can follow."""
    name = "turning.gcode"
    with mini.client() as client:
        wait_idle(client, "p")
        response = client.post("/api/v1/devices/p/jobs", params={"filename": name}, content=TURNING,
                               headers={"Content-Type": "application/octet-stream"})
        assert response.status_code == 400, response.text
        assert "its G2/G3 arcs as straight moves would make it more than 8 times its size" in response.text
        assert "slice it with arcs off and send it again" in response.text
        assert "--keep-arcs" not in response.text
        assert client.get("/api/v1/jobs").json() == []
        assert name not in client.get("/api/files").text
