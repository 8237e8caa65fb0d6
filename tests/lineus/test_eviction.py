"""A client the Line-us simulator's connection limit closes is told why, as a Line-us error reply, and the host
client shows that reason as its one-line error."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

from clitools import RunningSimulator, cli_env, start_simulator
from fabwire.errors import LinkClosed
from fabwire.lineus.client import LineUs

PLACE_TIMEOUT = 60.0
REPLACED = b'error INFO:"lineus simulator replaced this quiet connection: all 1 connections were in use"\r\n\x00'
BUSY = b'error INFO:"lineus simulator busy: all 1 connections are in use, try again later"\r\n\x00'


@pytest.fixture
def one_place() -> Iterator[RunningSimulator]:
    """A Line-us simulator that serves one client at a time."""
    sim = start_simulator("lineus", "--listen", "127.0.0.1:0", "--max-connections", "1", "--speed", "0")
    try:
        yield sim
    finally:
        sim.stop()


def address(sim: RunningSimulator) -> tuple[str, int]:
    host, port = sim.url.removeprefix("tcp://").rsplit(":", 1)
    return host, int(port)


def first_message(sock: socket.socket) -> bytes:
    got = b""
    while not got.endswith(b"\x00"):
        chunk = sock.recv(256)
        if not chunk:
            break
        got += chunk
    return got


def until_closed(sock: socket.socket) -> bytes:
    got = b""
    while chunk := sock.recv(256):
        got += chunk
    return got


def take_the_place(where: tuple[str, int]) -> tuple[socket.socket, list[bytes]]:
    """Connect until the simulator serves this client (the one connected must first have been quiet a while);
    returns the served socket and what each refused attempt was told."""
    refusals: list[bytes] = []
    deadline = time.monotonic() + PLACE_TIMEOUT
    while time.monotonic() < deadline:
        sock = socket.create_connection(where, timeout=10)
        said = first_message(sock)
        if said.startswith(b"hello"):
            return sock, refusals
        sock.close()
        refusals.append(said)
        time.sleep(0.1)
    raise AssertionError(f"never served within {PLACE_TIMEOUT:g} s; told {refusals[-3:]}")


def test_the_quiet_client_replaced_hears_why_in_the_protocols_form(one_place: RunningSimulator) -> None:
    where = address(one_place)
    with socket.create_connection(where, timeout=10) as quiet:
        assert first_message(quiet).startswith(b"hello")
        with contextlib.closing(socket.create_connection(where, timeout=10)) as early:
            assert until_closed(early) == BUSY  # the one connected is not quiet yet: the newcomer goes
        newcomer, refusals = take_the_place(where)
        with newcomer:
            assert until_closed(quiet) == REPLACED  # one whole reply, then the close
            assert all(said == BUSY for said in refusals)
            newcomer.sendall(b"M114\x00")
            assert first_message(newcomer).startswith(b"ok X:")
    assert "closed the quietest connection" in one_place.stop()


@pytest.mark.parametrize("lookahead", [False, True])
async def test_the_host_client_reports_the_reason(one_place: RunningSimulator, lookahead: bool) -> None:
    where = address(one_place)
    async with LineUs.open(one_place.url, lookahead=lookahead) as arm:
        await arm.position()
        newcomer, _ = await asyncio.to_thread(take_the_place, where)
        with newcomer, pytest.raises(LinkClosed) as caught:
            await arm.position()
    assert str(caught.value) == (f"{where[0]}:{where[1]}: the lineus simulator closed this connection, quiet the "
                                 "longest of its 1, to serve a new client (its --max-connections); connect again "
                                 "to go on")


def test_the_shell_ends_with_the_reason_as_one_line(one_place: RunningSimulator) -> None:
    where = address(one_place)
    shell = subprocess.Popen([sys.executable, "-m", "fabwire", "lineus", "-d", one_place.url, "shell"],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env=cli_env())
    assert shell.stdin is not None
    assert shell.stdout is not None
    try:
        shell.stdin.write("pos\n")
        shell.stdin.flush()
        assert "1000" in shell.stdout.readline()  # connected, and answered
        newcomer, _ = take_the_place(where)
        with newcomer:
            _, stderr = shell.communicate("pos\n", timeout=60)
    finally:
        if shell.poll() is None:
            shell.kill()
            shell.communicate()
    assert shell.returncode == 8, stderr
    greeting, error = stderr.splitlines()
    assert greeting.startswith("connected to line-us")
    assert error == (f"fabwire: error: {where[0]}:{where[1]}: the lineus simulator closed this connection, quiet "
                     "the longest of its 1, to serve a new client (its --max-connections); connect again to go on")
