"""The Moonraker JSON-RPC WebSocket answers every message that is no request with a JSON-RPC 2.0 error response
and stays open, against a real `fabwire serve` and a real WebSocket client."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any
from urllib.parse import urlsplit

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from fabwire.agent.doors.moonraker import INVALID_REQUEST, MAX_MESSAGE, PARSE_ERROR, REFUSALS

from .agenttools import RunningAgent, start_agent

DEEP_PARAMS = '{"jsonrpc":"2.0","method":"server.info","params":{"a":' + "[" * 20000 + "]" * 20000 + '},"id":1}'

BAD_MESSAGES: tuple[tuple[str, str | bytes, int, Any], ...] = (
    # (what, frame, error code, id in the reply) — JSON-RPC 2.0 §5.1 error codes, §4 request object, §6 batch
    ("not JSON (§5.1 Parse error)", '{"jsonrpc": "2.0", "method"', PARSE_ERROR, None),
    ("an id of 5000 digits (Python refuses the integer: §5.1)", '{"jsonrpc":"2.0","method":"server.info","id":'
     + "1" * 5000 + "}", PARSE_ERROR, None),
    ("60000 open brackets (deeper than the depth limit: §5.1)", "[" * 60000, PARSE_ERROR, None),
    ("params nested 20000 deep (§5.1)", DEEP_PARAMS, PARSE_ERROR, None),
    ("NaN id (not JSON: RFC 8259 §6, §5.1)", '{"jsonrpc":"2.0","method":"server.info","id":NaN}', PARSE_ERROR, None),
    ("Infinity in params (RFC 8259 §6)", '{"jsonrpc":"2.0","method":"server.info","params":{"a":-Infinity},"id":3}',
     PARSE_ERROR, None),
    ("a binary frame (RFC 6455 §5.6)", b"\xff\xfe", INVALID_REQUEST, None),
    ("a binary frame holding a request", b'{"jsonrpc":"2.0","method":"server.info","id":1}', INVALID_REQUEST, None),
    ("a number, not an object (§4)", "1", INVALID_REQUEST, None),
    ("a string, not an object (§4)", '"server.info"', INVALID_REQUEST, None),
    ("an empty batch (§6)", "[]", INVALID_REQUEST, None),
    ("no jsonrpc member (§4)", '{"method":"server.info","id":7}', INVALID_REQUEST, 7),
    ('jsonrpc "1.0" (§4)', '{"jsonrpc":"1.0","method":"server.info","id":"a"}', INVALID_REQUEST, "a"),
    ("method not a string (§4)", '{"jsonrpc":"2.0","method":1,"id":8}', INVALID_REQUEST, 8),
    ("no method (§4)", '{"jsonrpc":"2.0","id":9}', INVALID_REQUEST, 9),
    ("id an object (§4)", '{"jsonrpc":"2.0","method":"server.info","id":{"a":1}}', INVALID_REQUEST, None),
    ("id true (§4)", '{"jsonrpc":"2.0","method":"server.info","id":true}', INVALID_REQUEST, None),
    ("params a string (§4.2)", '{"jsonrpc":"2.0","method":"server.info","params":"x","id":10}',
     INVALID_REQUEST, 10),
    ("an unknown method (§5.1 -32601)", '{"jsonrpc":"2.0","method":"no.such","id":11}', -32601, 11),
    ("params by position (Moonraker takes names: §5.1 -32602)",
     '{"jsonrpc":"2.0","method":"server.info","params":[1],"id":12}', -32602, 12),
)


@pytest.fixture(scope="module")
def agent(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningAgent]:
    running = start_agent(tmp_path_factory.mktemp("jsonrpc") / "state", "--demo")
    yield running
    _code, log = running.stop()
    assert "Traceback" not in log, log
    assert "Exception in ASGI" not in log, log


@pytest.fixture(scope="module")
def ws(agent: RunningAgent) -> Iterator[ClientConnection]:
    url = urlsplit(agent.url)
    with connect(f"ws://{url.netloc}/websocket", max_size=None, open_timeout=30) as conn:
        yield conn


def replies_until_server_info(ws: ClientConnection, marker: str) -> list[Any]:
    """Send `server.info` with id `marker`; every message received before its answer, then that answer."""
    ws.send(json.dumps({"jsonrpc": "2.0", "method": "server.info", "id": marker}))
    seen = []
    while True:
        message = json.loads(ws.recv(timeout=30), parse_constant=lambda c: pytest.fail(f"{c} in a reply"))
        seen.append(message)
        if isinstance(message, dict) and message.get("id") == marker:
            assert "klippy_state" in message["result"], message
            return seen


def test_the_refusal_table_names_its_sources() -> None:
    assert all("JSON-RPC 2.0 §" in r.source for r in REFUSALS)


@pytest.mark.parametrize(("frame", "code", "rpc_id"), [row[1:] for row in BAD_MESSAGES],
                         ids=[row[0] for row in BAD_MESSAGES])
def test_each_bad_message_gets_an_error_reply_and_the_socket_stays_open(ws: ClientConnection, frame: str | bytes,
                                                                        code: int, rpc_id: Any) -> None:
    ws.send(frame)
    reply = json.loads(ws.recv(timeout=30))
    assert reply["jsonrpc"] == "2.0", reply
    assert reply["id"] == rpc_id, reply
    assert "result" not in reply, reply
    assert reply["error"]["code"] == code, reply
    assert reply["error"]["message"], reply
    assert replies_until_server_info(ws, "after")[-1]["id"] == "after"


def test_a_message_over_the_limit_is_closed_with_1009_and_a_new_connection_answers(agent: RunningAgent) -> None:
    url = urlsplit(agent.url)
    big = '{"jsonrpc":"2.0","method":"server.info","params":{"a":"' + "x" * MAX_MESSAGE + '"},"id":1}'
    with connect(f"ws://{url.netloc}/websocket", max_size=None, open_timeout=30) as conn:
        conn.send(big)
        with pytest.raises(ConnectionClosed) as closed:
            conn.recv(timeout=30)
    assert closed.value.rcvd is not None
    assert closed.value.rcvd.code == 1009
    with connect(f"ws://{url.netloc}/websocket", open_timeout=30) as conn:
        assert replies_until_server_info(conn, "again")[-1]["id"] == "again"


def test_a_batch_is_answered_in_one_array_without_the_notifications(ws: ClientConnection) -> None:
    ws.send(json.dumps([{"jsonrpc": "2.0", "method": "server.info", "id": 1}, 5,
                        {"jsonrpc": "2.0", "method": "server.info"}]))
    reply = json.loads(ws.recv(timeout=30))
    assert [r["id"] for r in reply] == [1, None], reply
    assert reply[1]["error"]["code"] == INVALID_REQUEST, reply


def test_the_http_door_reads_the_same_json_through_the_bounded_reader(agent: RunningAgent) -> None:
    with agent.client() as client:
        for body in ("[" * 60000, '{"a":' + "1" * 5000 + "}"):
            answer = client.post("/printer/print/start", content=body, headers={"Content-Type": "application/json"})
            assert answer.status_code == 400, answer.text
            assert "JSON" in answer.text, answer.text


frames = st.one_of(st.text(max_size=200), st.binary(max_size=200),
                   st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=10),
                                lambda c: st.lists(c, max_size=4) | st.dictionaries(st.sampled_from(
                                    ["jsonrpc", "method", "id", "params", "objects"]), c, max_size=4),
                                max_leaves=12).map(lambda v: json.dumps(v)),
                   st.fixed_dictionaries({"jsonrpc": st.just("2.0"), "method": st.sampled_from(
                       ["server.info", "printer.objects.query", "printer.objects.list", "server.files.metadata",
                        "server.history.list", "printer.info", "server.files.list"]),
                       "params": st.dictionaries(st.sampled_from(["objects", "filename", "limit", "start", "a"]),
                                                 st.none() | st.integers() | st.text(max_size=5)
                                                 | st.lists(st.text(max_size=5), max_size=3)
                                                 | st.dictionaries(st.text(max_size=5), st.none(), max_size=2)),
                       "id": st.integers()}).map(json.dumps))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(frame=frames)
def test_any_frame_gets_a_json_rpc_reply_or_none_and_the_socket_still_answers(ws: ClientConnection,
                                                                            frame: str | bytes) -> None:
    ws.send(frame)
    for message in replies_until_server_info(ws, "probe")[:-1]:
        items = message if isinstance(message, list) else [message]
        for item in items:
            assert item["jsonrpc"] == "2.0", item
            assert "result" in item or "error" in item or "method" in item, item


JSON_TYPES = (
    # (Content-Type, source): each is application/json, as the boundary reads it
    ("application/json", "RFC 8259 §11"),
    ("Application/JSON", "RFC 9110 §8.3.1: type and subtype are case-insensitive"),
    ("APPLICATION/JSON; charset=utf-8", "RFC 9110 §8.3.1: parameters follow the subtype"),
    ("application/json;charset=UTF-8", "RFC 9110 §5.6.6: no space is needed around ';'"),
    ("application/json (comment)", "RFC 2045 §5.1: a comment in the Content-Type value"),
)


@pytest.mark.parametrize("ctype", [row[0] for row in JSON_TYPES], ids=[row[1] for row in JSON_TYPES])
def test_moonraker_http_json_bodies_are_read_whatever_the_media_type_case(agent: RunningAgent, ctype: str) -> None:
    with agent.client() as client:
        answer = client.post("/printer/print/start", content=json.dumps({"filename": "nosuch.gcode"}),
                             headers={"Content-Type": ctype})
    assert answer.status_code == 404, answer.text
    assert "nosuch.gcode" in answer.text, answer.text
