"""Under `/printers/NAME/…` a name no machine has is 404 on every route of every door, even the ones whose answer
does not depend on the machine (`/api/version`, which a slicer's "Test" button checks, `/server/info`): a typo in
a slicer's host URL fails its test instead of passing it and failing the first print."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from starlette.testclient import TestClient, WebSocketDenialResponse
from starlette.websockets import WebSocketDisconnect

from fabwire.agent.api import create_app
from fabwire.agent.core import Agent

from .test_boundary import OWN, route_table

APP = create_app(Agent(), max_upload_bytes=1024)
PER_MACHINE = [(m, p, t) for m, p, t in route_table(APP) if t.startswith("/printers/{machine}")]


@pytest.fixture(scope="module")
def client() -> Iterator[TestClient]:
    with TestClient(APP, base_url=OWN) as made:
        yield made


def test_the_walk_covers_both_doors() -> None:
    templates = {t for _, _, t in PER_MACHINE}
    assert {"/printers/{machine}/api/version", "/printers/{machine}/api/files/local",
            "/printers/{machine}/server/info", "/printers/{machine}/printer/objects/query",
            "/printers/{machine}/websocket"} <= templates


@pytest.mark.parametrize(("method", "path", "template"), [r for r in PER_MACHINE if r[0] != "WEBSOCKET"],
                         ids=[f"{m} {t}" for m, _, t in PER_MACHINE if m != "WEBSOCKET"])
def test_an_unknown_machine_is_404_on_every_route(client: TestClient, method: str, path: str,
                                                  template: str) -> None:
    unknown = path.replace("/printers/x/", "/printers/nosuch/", 1)
    if method == "POST" and template.endswith(("/api/files/local", "/server/files/upload")):
        answer = client.request(method, unknown, files={"file": ("a.gcode", b"G28\n")})  # the form slicers send
    elif method == "POST":
        answer = client.request(method, unknown, content=b"{}", headers={"content-type": "application/json"})
    else:
        answer = client.request(method, unknown)
    assert answer.status_code == 404, (unknown, answer.status_code, answer.text)
    assert "nosuch" in answer.text


def test_an_unknown_machine_is_refused_on_the_websocket(client: TestClient) -> None:
    with (pytest.raises((WebSocketDenialResponse, WebSocketDisconnect)),
          client.websocket_connect("/printers/nosuch/websocket", headers={"host": "127.0.0.1:8765"}) as ws):
        ws.receive_text()
