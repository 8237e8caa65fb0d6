"""The boundary in front of every route: the whole route table, walked with what a stranger's page can send.

In-process on the real application (`create_app`), with routes added after it was made (as the print-host doors
are) to show that a route added later is covered without doing anything.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi import APIRouter, Body, FastAPI, Request
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from starlette.routing import WebSocketRoute
from starlette.testclient import TestClient, WebSocketDenialResponse

from fabwire.agent.api import create_app
from fabwire.agent.boundary import (
    CORS_SIMPLE_TYPES,
    JSON_BODY_LIMIT,
    MAX_JSON_DEPTH,
    SAFE_METHODS,
    BadJSON,
    Policy,
    leaf_routes,
    parse_json,
    same_origin,
)
from fabwire.agent.core import Agent

OWN = "http://127.0.0.1:8765"
OWN_HOST = {"host": "127.0.0.1:8765"}
"""The test client's WebSockets say `Host: testserver` unless told."""
FOREIGN_HOSTS = ("evil.example", "evil.example:8765", "127.0.0.1.evil.example", "localhost.evil.example",
                 "printers.lan.evil.example", "", "a b", "[::1", "evil.example:99999")
"""DNS-rebinding names (an attacker's name resolving to 127.0.0.1) and malformed Host values."""
FOREIGN_ORIGINS = ("http://evil.example", "null", "http://127.0.0.2:8765", "http://localhost:8000",
                   "http://127.0.0.1:8766", "https://127.0.0.1", "file://", "http://127.0.0.1:8765.evil.example",
                   "chrome-extension://abcdef")
"""Pages that are not the agent's own: another site, a sandboxed frame or file: page (null), another loopback
address or port (another program on this computer), an extension."""
FAKE_DOOR = "/test-door"
"""Where the routes added for the test live: beside the agent's real OctoPrint and Moonraker doors, not over them."""
START, SCRIPT, FILES = (FAKE_DOOR + p for p in ("/printer/print/start", "/printer/gcode/script", "/api/files/local"))
REACHED: list[str] = []
"""What the routes added for the test were reached with: must stay empty for every refused request."""


def app_with_doors(policy: Policy | None = None) -> FastAPI:
    """The agent's app, plus routes added afterwards the way a print-host door adds them."""
    app = create_app(Agent(), max_upload_bytes=1024, policy=policy)
    door = APIRouter(prefix=FAKE_DOOR)

    @door.post("/api/files/local", openapi_extra={"requestBody": {"content": {"multipart/form-data": {}}}})
    async def files(request: Request) -> dict[str, bool]:
        REACHED.append(f"files {len(await request.body())}")
        return {"done": True}

    @door.post("/printer/print/start")
    async def start(body: dict[str, Any] = Body(...)) -> dict[str, bool]:  # noqa: B008 - FastAPI's idiom
        REACHED.append("start")
        return {"started": True}

    @door.post("/printer/gcode/script")
    async def script(request: Request) -> dict[str, bool]:  # declares no body
        REACHED.append("script")
        return {"sent": True}

    app.include_router(door)
    return app


def route_table(app: FastAPI) -> Iterator[tuple[str, str, str]]:
    """(method or "WEBSOCKET", a concrete path, the path template) for every route of the app."""
    for route in leaf_routes(app.router.routes):
        real = getattr(route, "starlette_route", None) or getattr(route, "original_route", None) or route
        template = getattr(route, "path", "") or real.path
        if getattr(route, "path_format", "") == "" and isinstance(real, WebSocketRoute):
            yield "WEBSOCKET", re.sub(r"\{[^}]+\}", "x", real.path), real.path
            continue
        path = re.sub(r"\{[^}]+\}", "x", template) + ("/app.js" if template == "/static" else "")
        for method in sorted(getattr(route, "methods", None) or {"GET"}):
            yield method, path, template


@pytest.fixture(scope="module")
def client() -> Iterator[TestClient]:
    with TestClient(app_with_doors(), base_url=OWN) as made:
        yield made


@pytest.fixture(autouse=True)
def nothing_reached() -> None:
    REACHED.clear()


TABLE = list(route_table(app_with_doors()))
WRITES = [(m, p, t) for m, p, t in TABLE if m not in SAFE_METHODS and m != "WEBSOCKET"]
SOCKETS = [(m, p, t) for m, p, t in TABLE if m == "WEBSOCKET"]


def test_the_walk_sees_every_route_including_later_ones() -> None:
    templates = {t for _, _, t in TABLE}
    assert {"/api/v1/devices/{device_id}/actions/{action}", "/api/v1/devices/{device_id}/jobs",
            "/api/v1/jobs/{job_id}/cancel", "/api/v1/devices", "/api/files/local", "/server/files/upload",
            "/printers/{machine}/api/files/local", f"{FAKE_DOOR}/api/files/local", f"{FAKE_DOOR}/printer/print/start",
            f"{FAKE_DOOR}/printer/gcode/script", "/", "/static"} <= templates
    assert SOCKETS == [("WEBSOCKET", "/api/v1/events", "/api/v1/events"), ("WEBSOCKET", "/websocket", "/websocket"),
                       ("WEBSOCKET", "/printers/x/websocket", "/printers/{machine}/websocket")]


@pytest.mark.parametrize("host", FOREIGN_HOSTS)
@pytest.mark.parametrize(("method", "path", "template"), TABLE)
def test_a_foreign_host_gets_nothing_from_any_route(client: TestClient, method: str, path: str, template: str,
                                                    host: str) -> None:
    if method == "WEBSOCKET":
        with pytest.raises(WebSocketDenialResponse) as denied, client.websocket_connect(path,
                                                                                       headers={"host": host}):
            pass
        assert denied.value.status_code == 403
        assert b"ForeignHost" in denied.value.content
        return
    response = client.request(method, path, headers={"host": host, "content-type": "application/json"},
                              content=b"{}" if method not in SAFE_METHODS else None)
    assert response.status_code == 403, (method, path, response.text)
    assert method == "HEAD" or response.json()["error"] == "ForeignHost"
    assert not REACHED


@pytest.mark.parametrize("origin", FOREIGN_ORIGINS)
@pytest.mark.parametrize(("method", "path", "template"), WRITES + SOCKETS)
def test_a_foreign_page_writes_nothing_and_opens_no_socket(client: TestClient, method: str, path: str,
                                                           template: str, origin: str) -> None:
    if method == "WEBSOCKET":
        with pytest.raises(WebSocketDenialResponse) as denied, client.websocket_connect(
                path, headers={**OWN_HOST, "origin": origin}):
            pass
        assert denied.value.status_code == 403
        assert b"CrossOrigin" in denied.value.content
        return
    response = client.request(method, path, headers={"origin": origin, "content-type": "application/json"},
                              content=b'{"confirm": true}')
    assert response.status_code == 403, (method, path, response.text)
    assert response.json()["error"] == "CrossOrigin"
    assert not REACHED


@pytest.mark.parametrize("site", ["cross-site", "same-site"])
@pytest.mark.parametrize(("method", "path", "template"), WRITES + SOCKETS)
def test_fetch_metadata_of_another_site_is_refused_without_an_origin(client: TestClient, method: str, path: str,
                                                                     template: str, site: str) -> None:
    headers = {"sec-fetch-site": site}
    if method == "WEBSOCKET":
        with pytest.raises(WebSocketDenialResponse) as denied, client.websocket_connect(
                path, headers={**OWN_HOST, **headers}):
            pass
        assert b"CrossOrigin" in denied.value.content
        return
    response = client.request(method, path, headers={**headers, "content-type": "application/json"},
                              content=b"{}")
    assert response.status_code == 403, (method, path, response.text)
    assert not REACHED


@pytest.mark.parametrize(("content_type", "source"), CORS_SIMPLE_TYPES)
@pytest.mark.parametrize(("method", "path", "template"), WRITES)
def test_no_route_reads_a_simple_content_type_it_did_not_declare(client: TestClient, method: str, path: str,
                                                                 template: str, content_type: str,
                                                                 source: str) -> None:
    """A page can send these cross-origin without a preflight (`source`); an old browser may omit Origin."""
    response = client.request(method, path, headers={"content-type": content_type}, content=b'{"confirm": true}')
    if template.endswith(("/api/files/local", "/server/files/upload")) and content_type == "multipart/form-data":
        assert response.status_code != 415  # the door declared it (and the Origin check covers browsers)
        return
    assert response.status_code == 415, (method, path, response.text)
    assert response.json()["error"] == "UnsupportedMediaType"
    assert not REACHED


def test_own_pages_and_programs_without_origin_pass(client: TestClient) -> None:
    for headers in ({}, {"origin": OWN, "sec-fetch-site": "same-origin"}, {"origin": "HTTP://LOCALHOST:8765",
                                                                          "host": "localhost:8765"}):
        response = client.post(START, json={"x": 1}, headers=headers)
        assert response.status_code == 200, (headers, response.text)
    assert REACHED == ["start"] * 3
    with client.websocket_connect("/api/v1/events", headers={**OWN_HOST, "origin": OWN}) as ws:
        ws.close()


def test_bodies_past_their_limit_are_refused_before_the_route(client: TestClient) -> None:
    big = b'{"text": "' + b"a" * JSON_BODY_LIMIT + b'"}'
    response = client.post(START, content=big, headers={"content-type": "application/json"})
    assert response.status_code == 413
    assert "limit" in response.json()["message"]

    def chunks() -> Iterator[bytes]:  # no declared length: counted as it arrives
        yield from (big[i:i + 4096] for i in range(0, len(big), 4096))

    response = client.post(START, content=chunks(), headers={"content-type": "application/json"})
    assert response.status_code == 413
    upload = client.post(FILES, content=b"x" * (1024 + 64 * 1024 + 1),
                         headers={"content-type": "multipart/form-data; boundary=x"})
    assert upload.status_code == 413
    refused = client.post(SCRIPT, content=b"G28", headers={"content-type": "application/json"})
    assert refused.status_code == 415
    assert "takes no body" in refused.json()["message"]
    assert not REACHED


@pytest.mark.parametrize("depth", [MAX_JSON_DEPTH + 1, 1000, 100_000])
def test_nested_json_is_a_400_with_a_message(client: TestClient, depth: int) -> None:
    for body in ("[" * depth + "]" * depth, '{"a":' * depth + "1" + "}" * depth):
        response = client.post(START, content=body.encode(),
                               headers={"content-type": "application/json"})
        assert response.status_code in (400, 413), response.text
        assert response.json()["error"] in ("BadJSON", "BodyTooLarge")
        if len(body) <= JSON_BODY_LIMIT:
            assert response.status_code == 400
            assert "nests deeper than" in response.json()["message"]
    assert not REACHED


def test_token_in_either_header() -> None:
    with TestClient(app_with_doors(Policy(token="t0ken")), base_url=OWN) as guarded:
        assert guarded.get("/api/v1/devices").status_code == 401
        assert guarded.get("/api/v1/devices", headers={"x-api-key": "wrong"}).status_code == 401
        assert guarded.get("/api/v1/devices", headers={"x-api-key": "t0ken"}).status_code == 200
        assert guarded.get("/api/v1/devices", headers={"authorization": "Bearer t0ken"}).status_code == 200
        assert guarded.post(START, json={}).status_code == 401  # a later route needs it too
        assert guarded.post(START, json={}, headers={"x-api-key": "t0ken"}).status_code == 200
        assert guarded.get("/").status_code == 200


def test_allow_host_and_a_wildcard_listen() -> None:
    named = Policy.for_listen("127.0.0.1", ["Printers.LAN."])
    assert [named.host_allowed(h) for h in ("printers.lan", "PRINTERS.lan.", "evil.example", "192.168.1.5")] == [
        True, True, False, False]
    wide = Policy.for_listen("0.0.0.0")
    assert [wide.host_allowed(h) for h in ("192.168.1.5", "::1", "[fe80::1]", "evil.example")] == [
        True, True, True, False]
    with TestClient(app_with_doors(named), base_url="http://printers.lan:8765") as client:
        assert client.get("/api/v1/devices").status_code == 200
        assert client.post(START, json={}, headers={"origin": "http://printers.lan:8765"}
                           ).status_code == 200


# ------------------------------------------------------------------------------------------------ hypothesis

LABEL = st.from_regex(r"[a-z0-9]([a-z0-9-]{0,10}[a-z0-9])?", fullmatch=True)
NAMES = st.lists(LABEL, min_size=1, max_size=4).map(".".join)


@settings(max_examples=200, suppress_health_check=[HealthCheck.function_scoped_fixture], deadline=None)
@given(name=NAMES, port=st.none() | st.integers(0, 65535))
def test_any_name_but_loopback_is_refused(client: TestClient, name: str, port: int | None) -> None:
    own = name == "localhost" or name.endswith(".localhost")
    host = name + (f":{port}" if port is not None else "")
    response = client.get("/api/v1/devices", headers={"host": host})
    assert response.status_code == (200 if own else 403), host


@settings(max_examples=200, suppress_health_check=[HealthCheck.function_scoped_fixture], deadline=None)
@given(scheme=st.sampled_from(["http", "https", "ws", "null", ""]), host=NAMES | st.just("127.0.0.1"),
       port=st.none() | st.integers(1, 65535))
def test_an_origin_is_accepted_only_when_it_is_the_agent(client: TestClient, scheme: str, host: str,
                                                         port: int | None) -> None:
    origin = f"{scheme}://{host}" + (f":{port}" if port is not None else "") if scheme != "null" else "null"
    ours = scheme in ("http", "https", "ws") and host == "127.0.0.1" and port == 8765  # (a TLS proxy: https)
    response = client.post(START, json={}, headers={"origin": origin})
    assert (response.status_code == 200) is ours, origin
    assert same_origin(origin, "127.0.0.1:8765") is ours


MEDIA = st.sampled_from(["application/json", "text/plain", "application/x-www-form-urlencoded",
                         "multipart/form-data", "application/octet-stream", "text/json", "application/jsonx",
                         "APPLICATION/JSON", "application/json-patch+json", ""])


@settings(max_examples=200, suppress_health_check=[HealthCheck.function_scoped_fixture], deadline=None)
@given(media=MEDIA, params=st.sampled_from(["", "; charset=utf-8", ";boundary=x", " ; charset=latin-1"]),
       body=st.sampled_from([b"", b"{}", b'{"confirm": true}', b"a=1", b"\x00\xff"]))
def test_json_routes_read_only_application_json(client: TestClient, media: str, params: str,
                                                body: bytes) -> None:
    REACHED.clear()
    headers = {"content-type": media + params} if media else {}
    response = client.post(START, content=body, headers=headers)
    if media.lower() == "application/json":
        assert response.status_code in (200, 400, 422), response.text
        assert (response.status_code == 200) == (body in (b"{}", b'{"confirm": true}'))
    elif media == "" and not body:
        assert response.status_code == 422  # nothing sent: the route's own "field required"
    else:
        assert response.status_code == 415, (headers, body)
        assert not REACHED


UPLOAD = "/api/v1/devices/x/jobs?filename=a.gcode"
"""The native upload: a file as it is, any media type but JSON and the CORS-simple ones (no device x: 404 after
the boundary)."""
CONTENT_TYPES: list[tuple[str, bool, str]] = [
    ("application/octet-stream", True, "RFC 2046 §4.5.1: arbitrary binary data"),
    ("application/octet-stream; charset=binary", True, "RFC 9110 §8.3.1: type/subtype with a parameter"),
    ("Application/Octet-Stream", True, "RFC 9110 §8.3.1: type and subtype are case-insensitive"),
    ("text/x-gcode", True, "what slicers and OctoPrint call G-code"),
    ("image/svg+xml", True, "RFC 6838 §4.2.8 structured suffix (IANA: image/svg+xml)"),
    ('application/octet-stream; name="a;b.gcode"', True, "RFC 9110 §5.6.4: a quoted parameter value holds ';'"),
    ("text/plain,application/octet-stream", False, "a list (Fetch: not a valid MIME type; attacker's value)"),
    ("application/octet-stream, text/plain", False, "a list the other way round"),
    ("application/octet-stream,application/octet-stream", False, "a list of one type twice"),
    ("application", False, "RFC 9110 §8.3.1: no subtype"),
    ("application/", False, "RFC 9110 §8.3.1: an empty subtype"),
    ("/octet-stream", False, "RFC 9110 §8.3.1: an empty type"),
    ("application/octet stream", False, "RFC 9110 §5.6.2: a space is no token character"),
    ("application/octet-stream/x", False, "two slashes"),
    ("application/octet-stream; charset", False, "RFC 9110 §5.6.6: a parameter without a value"),
    ("application/octet-stream (" + "(" * 300, False, "nested comments: the MIME parser recurses per level"),
    ("application/octet-stream" + "; a=b" * 60, False, "longer than MAX_CONTENT_TYPE"),
    (";0*", False, "RFC 2231 §3: a bare continuation marker (the MIME parser raises HeaderParseError)"),
    ("a/b;0*", False, "RFC 2231 §3: a parameter that is only a continuation marker"),
]
"""Content-Type values, accepted (the route is reached) or refused (415 before the route), each with its source."""


@pytest.mark.parametrize(("value", "accepted"), [(v, a) for v, a, _ in CONTENT_TYPES],
                         ids=[source for _, _, source in CONTENT_TYPES])
def test_a_content_type_is_one_media_type_or_refused(client: TestClient, value: str, accepted: bool) -> None:
    response = client.post(UPLOAD, content=b"G28\n", headers={"content-type": value})
    if accepted:
        assert response.status_code == 404, response.text  # past the boundary: no such device
        return
    assert response.status_code == 415, response.text
    message = response.json()["message"]
    assert message.endswith(" is not one media type such as application/octet-stream"), message


def test_a_content_type_given_twice_is_refused(client: TestClient) -> None:
    for second in ("application/octet-stream", "text/plain"):
        response = client.post(UPLOAD, content=b"G28\n", headers=[("content-type", "application/octet-stream"),
                                                                  ("content-type", second)])
        assert response.status_code == 415, response.text
        assert response.json()["message"] == "send one Content-Type header, not 2"


@settings(max_examples=300, suppress_health_check=[HealthCheck.function_scoped_fixture], deadline=None)
@given(value=st.text(st.characters(min_codepoint=0x20, max_codepoint=0x7E), max_size=300),
       path=st.sampled_from([UPLOAD, START]))
def test_any_content_type_is_accepted_or_a_415_never_an_error(client: TestClient, value: str, path: str) -> None:
    response = client.post(path, content=b"{}", headers={"content-type": value})
    assert response.status_code in (200, 404, 415, 422), (value, response.text)
    if response.status_code == 415:
        assert response.json()["message"]


@given(st.recursive(st.none() | st.booleans() | st.integers() | st.text(max_size=5),
                    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=3), inner,
                                                                                  max_size=3), max_leaves=40))
def test_parse_json_takes_what_json_takes(value: Any) -> None:
    import json

    assert parse_json(json.dumps(value)) == value


@given(st.integers(MAX_JSON_DEPTH + 1, 50_000), st.sampled_from(["[", '{"k":']))
def test_parse_json_never_recurses_out(depth: int, opener: str) -> None:
    closer = "]" if opener == "[" else "}"
    with pytest.raises(BadJSON, match="nests deeper"):
        parse_json(opener * depth + ("1" if opener != "[" else "") + closer * depth)


@pytest.mark.parametrize(("path", "content_type"), [(START, "application/json"),
                                                    (FILES, "multipart/form-data; boundary=x")])
async def test_a_body_that_stops_arriving_ends_the_request(monkeypatch: pytest.MonkeyPatch, path: str,
                                                           content_type: str) -> None:
    """A client that declares a body and sends one piece of it: 408 after the pause, whether the boundary reads
    the body (JSON) or the route streams it (an upload)."""
    import asyncio

    from fabwire.agent import boundary

    monkeypatch.setattr(boundary, "BODY_IDLE_S", 0.2)
    app = app_with_doors()
    sent: list[dict[str, Any]] = []
    pieces = [{"type": "http.request", "body": b"{", "more_body": True}]

    async def receive() -> dict[str, Any]:
        if pieces:
            return pieces.pop()
        await asyncio.sleep(3600)  # the rest never comes
        raise AssertionError("unreachable")

    async def send(message: dict[str, Any]) -> None:
        sent.append(message)

    raw_path, _, query = path.partition("?")
    headers = [(b"host", b"127.0.0.1:8765"), (b"content-length", b"100")]
    if content_type:
        headers.append((b"content-type", content_type.encode()))
    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "POST", "scheme": "http",
             "path": raw_path, "raw_path": raw_path.encode(), "query_string": query.encode(), "root_path": "",
             "headers": headers, "client": ("127.0.0.1", 1), "server": ("127.0.0.1", 8765)}
    await asyncio.wait_for(app(scope, receive, send), 30)
    assert sent[0]["status"] == 408, sent
    assert b"stopped arriving" in b"".join(m.get("body", b"") for m in sent)
    assert not REACHED


@given(grace=st.integers(1, 100), rate=st.integers(1, 1000),
       arrivals=st.lists(st.tuples(st.integers(0, 150), st.integers(0, 200_000)), max_size=40))
def test_a_body_is_too_slow_exactly_when_a_window_past_the_grace_brings_too_little(
        grace: int, rate: int, arrivals: list[tuple[int, int]]) -> None:
    """`BodyPace` against its definition: checked at each arrival's moment (seconds of waiting), the body is too
    slow exactly when some window [grace + k·grace, grace + (k+1)·grace) that has ended brought under rate × grace
    bytes; what came during the grace, or in an earlier window, counts for nothing later."""
    from fabwire.agent.boundary import BodyPace

    pace = BodyPace(float(grace), float(rate))
    seen: list[tuple[int, int]] = []
    now = 0
    for gap, size in arrivals:
        now += gap
        ended = range(grace, now - grace + 1, grace)  # the starts of the windows that have ended by now
        short = any(sum(n for t, n in seen if start <= t < start + grace) < rate * grace for start in ended)
        assert pace.too_slow(float(now)) == short
        if short:
            return
        pace.arrived(size, float(now))
        seen.append((now, size))


def test_a_burst_buys_no_time_for_the_windows_after_it() -> None:
    """However much came at first, a window that then brings under its share ends the body at its end."""
    from fabwire.agent.boundary import BodyPace

    pace = BodyPace(30.0, 1024.0)
    pace.arrived(63 * 1024 * 1024, 0.5)  # 63 MiB in the first half second
    pace.arrived(64 * 1024, 31.0)  # a full first window
    assert not pace.too_slow(60.0)
    pace.arrived(1, 70.0)
    assert not pace.too_slow(89.0)
    assert pace.too_slow(90.0)


async def test_a_body_that_trickles_ends_the_request(monkeypatch: pytest.MonkeyPatch) -> None:
    """A body that keeps coming, a byte at a time and never BODY_IDLE_S apart, but under BODY_MIN_RATE: 408 once
    the grace is over, whether the boundary reads the body or the route streams it."""
    import asyncio

    from fabwire.agent import boundary

    monkeypatch.setattr(boundary, "BODY_GRACE_S", 0.3)
    for path, content_type in ((START, "application/json"), (FILES, "multipart/form-data; boundary=x")):
        sent: list[dict[str, Any]] = []

        async def receive() -> dict[str, Any]:
            await asyncio.sleep(0.05)
            return {"type": "http.request", "body": b" ", "more_body": True}

        async def send(message: dict[str, Any]) -> None:
            sent.append(message)  # noqa: B023 - each loop's own list, used within the loop

        headers = [(b"host", b"127.0.0.1:8765"), (b"content-length", b"1000"), (b"content-type", content_type.encode())]
        scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "POST",
                 "scheme": "http", "path": path, "raw_path": path.encode(), "query_string": b"", "root_path": "",
                 "headers": headers, "client": ("127.0.0.1", 1), "server": ("127.0.0.1", 8765)}
        await asyncio.wait_for(app_with_doors()(scope, receive, send), 30)
        assert sent[0]["status"] == 408, sent
        assert b"arrives too slowly" in b"".join(m.get("body", b"") for m in sent)
    assert not REACHED
