"""Every field the client reads from a Line-us may be missing: greetings and replies as firmware versions, clones
and test rigs write them, against the client over a real loopback socket, and through the CLI."""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.errors import FabwireError, LinkClosed
from fabwire.lineus import kinematics as kin
from fabwire.lineus.client import LineUs, Position
from fabwire.transport import Transport, open_tcp, serve_tcp

TERM = b"\r\n\x00"

GREETINGS = [
    # (greeting, public source)
    ('hello VERSION:"3.2.0 Nov 17 2019 17:54:57" NAME:line-us SERIAL:123456', "Line-us-Programming README"),
    ("hello VERSION:1.0.1 NAME:line-us SERIAL:1", "firmware 1.0.1 fixture (official lineus module tests)"),
    ('hello VERSION:"2.0.2Beta6" NAME:lineus SERIAL:42', "websocket hello of 2.0.2Beta6 (Beardy's Line-us client)"),
    ("hello", "a bare hello: the official lineus module parses it as {} and carries on"),
    ("hello NAME:line-us SERIAL:990055", "clones and test rigs without VERSION"),
    ('hello VERSION:"" NAME:line-us SERIAL:1', "an empty VERSION"),
    ("hello VERSION:unknown", "a VERSION that is not a number"),
    ("hello SERIAL:1", "SERIAL alone"),
]


@contextlib.asynccontextmanager
async def scripted(greeting: str, replies: list[str]) -> AsyncIterator[int]:
    """A loopback peer that greets with `greeting` and answers each command line with the next of `replies`;
    once they run out, like a plain robot: moves and M114 with where the commands put the arm, the rest `ok`."""

    async def handler(transport: Transport) -> None:
        await transport.write(greeting.encode() + TERM)
        answers = iter(replies)
        where = {"X": 1000.0, "Y": 1000.0, "Z": 1000.0}
        buffer = b""
        with contextlib.suppress(LinkClosed):
            while True:
                buffer += await transport.read()
                while (cut := buffer.find(b"\x00")) >= 0:
                    line, buffer = buffer[:cut].strip().decode(), buffer[cut + 1 :]
                    if not line:
                        continue
                    words = line.split()
                    for word in words[1:]:
                        if words[0] in ("G00", "G01") and word[:1] in where:
                            where[word[0]] = float(word[1:])
                    plain = f"ok X:{where['X']:g} Y:{where['Y']:g} Z:{where['Z']:g}" \
                        if words[0] in ("G00", "G01", "M114") else "ok"
                    await transport.write(next(answers, plain).encode() + TERM)

    server = await serve_tcp(handler, "127.0.0.1", 0)
    try:
        yield server.sockets[0].getsockname()[1]
    finally:
        server.close()


async def _connect(port: int) -> LineUs:
    return await LineUs.connect(await open_tcp("127.0.0.1", port), hello_timeout=2.0, reply_timeout=2.0)


@pytest.mark.parametrize(("greeting", "source"), GREETINGS, ids=[g for g, _ in GREETINGS])
async def test_every_greeting_connects_and_moves(greeting: str, source: str) -> None:
    async with asyncio.timeout(20), scripted(greeting, []) as port:
        arm = await _connect(port)
        try:
            assert arm.hello.firmware_label  # words for messages, whatever the greeting held
            where = await arm.move(600, -300, 0)
        finally:
            await arm.close()
    if arm.hello.firmware_major <= 1:  # an unknown firmware is kept out of the body notch like 1.x
        assert not kin.in_body_zone(where.x, where.y)
    else:  # firmware 2 and 3 keep out of it themselves
        assert (where.x, where.y, where.z) == (600, -300, 0)


def _serve_in_thread(greeting: str) -> Iterator[int]:
    ready: list[int] = []
    started = threading.Event()
    loop = asyncio.new_event_loop()
    stop = loop.create_future()

    async def main() -> None:
        async with scripted(greeting, []) as port:
            ready.append(port)
            started.set()
            await stop

    thread = threading.Thread(target=loop.run_until_complete, args=(main(),), daemon=True)
    thread.start()
    assert started.wait(10)
    try:
        yield ready[0]
    finally:
        loop.call_soon_threadsafe(stop.set_result, None)
        thread.join(10)
        loop.close()


@pytest.fixture(params=GREETINGS, ids=[g for g, _ in GREETINGS])
def greeter(request: pytest.FixtureRequest) -> Iterator[int]:
    yield from _serve_in_thread(request.param[0])


def test_cli_guarded_move_under_every_greeting(greeter: int, tmp_path: Any) -> None:
    done = run_cli("lineus", "-d", f"127.0.0.1:{greeter}", "move", "600", "-300", "--pen", "down",
                   env=cli_env(tmp_path))
    assert done.returncode == 0, done.stderr
    assert "internal error" not in done.stderr


def test_cli_info_under_a_bare_hello(tmp_path: Any) -> None:
    for port in _serve_in_thread("hello"):
        done = run_cli("lineus", "-d", f"127.0.0.1:{port}", "info", env=cli_env(tmp_path))
        assert done.returncode == 0, done.stderr
        assert "internal error" not in done.stderr


# -- property: any subset of any reply's fields -----------------------------------------------------------------

_VALUE = st.one_of(
    st.sampled_from(["", "0", "1000", "-300", "1.5", "abc", "3.2.0", "1;2;3;4", "/0000001.txt-12;", "nan", "inf"]),
    st.text(alphabet=st.characters(min_codepoint=0x21, max_codepoint=0x7E, exclude_characters='":'), max_size=8),
)
_KEYS = ["X", "Y", "Z", "INFO", "ZMap", "FS", "MACHINENAME", "S1", "S2", "Used", "Free", "CONNECTMODE", "ChipID",
         "VERSION", "NAME", "SERIAL", "home"]


def _field(key: str, value: str) -> str:
    return f'{key}:"{value}"' if " " in value or not value else f"{key}:{value}"


_FIELDS = st.lists(st.tuples(st.sampled_from(_KEYS), _VALUE), max_size=5)
_REPLY = st.builds(lambda ok, fields: " ".join(["ok" if ok else "error", *(_field(k, v) for k, v in fields)]),
                   st.booleans(), _FIELDS)
_GREETING = st.builds(lambda fields: " ".join(["hello", *(_field(k, v) for k, v in fields)]),
                      st.lists(st.tuples(st.sampled_from(["VERSION", "NAME", "SERIAL", "X"]), _VALUE), max_size=4))

CALLS: dict[str, Callable[[LineUs], Awaitable[Any]]] = {
    "move": lambda arm: arm.move(1200, 200),
    "pen_down": lambda arm: arm.pen_down(),
    "pen_up": lambda arm: arm.pen_up(),
    "home": lambda arm: arm.home(),
    "position": lambda arm: arm.position(),
    "servo_angles": lambda arm: arm.servo_angles(),
    "capabilities": lambda arm: arm.capabilities(),
    "diagnostics": lambda arm: arm.diagnostics(),
    "name": lambda arm: arm.name(),
    "storage": lambda arm: arm.storage(),
    "zmap": lambda arm: arm.zmap(),
    "list_drawings": lambda arm: arm.list_drawings(),
    "wifi_networks": lambda arm: arm.wifi_networks(),
}


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(greeting=_GREETING, replies=st.lists(_REPLY, min_size=len(CALLS), max_size=len(CALLS)))
def test_any_greeting_and_replies_give_a_result_or_a_clear_error(greeting: str, replies: list[str]) -> None:
    outcomes: dict[str, object] = {}

    async def main() -> None:
        async with asyncio.timeout(30), scripted(greeting, replies) as port:
            arm = await _connect(port)
            try:
                for name, call in CALLS.items():
                    try:
                        outcomes[name] = await call(arm)
                    except FabwireError as exc:  # a clear, one-line error; anything else is a bug
                        outcomes[name] = exc
            finally:
                await arm.close()

    asyncio.run(main())
    assert all(str(o) for o in outcomes.values() if isinstance(o, FabwireError))
    for name, reply in zip(CALLS, replies, strict=True):
        fields = dict(part.split(":", 1) for part in reply.split()[1:] if ":" in part)
        if name in ("move", "pen_down", "pen_up", "home", "position") and isinstance(outcomes[name], Position):
            # a position is only ever what the robot reported, never made up
            assert reply.startswith("ok")
            where = outcomes[name]
            assert isinstance(where, Position)
            assert (where.x, where.y, where.z) == tuple(float(fields[k]) for k in "XYZ")
