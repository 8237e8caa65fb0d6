"""Clients that flood the simulator and vanish: the robot takes a command off the socket only when its motion queue
has room, so whatever a client sent beyond that dies with its connection and never delays the next client."""

from __future__ import annotations

import asyncio
import socket
import struct

import pytest

FLOOD_PAIRS = 100
"""Pen-down strokes of 2000 units (400 steps, 4 model seconds each): the flood holds 800 model seconds of motion."""
DOWN = b"G01 X1000 Y-1000 Z0\x00"
UP = b"G01 X1000 Y1000 Z0\x00"
OWN_MOVES = 10
TAKEN_AT_MOST = 5
"""Flood moves that may still run: the one answered, the one whose reply found the client gone, the one executing
then, the one queued behind it and the one the connection had in hand (each reply write is how a gone client shows)."""


def _vanish(writer: asyncio.StreamWriter, how: str) -> None:
    """Go away as a crashed client does (reset) or as a rude one does (close with replies still owed)."""
    if how == "reset":
        sock = writer.get_extra_info("socket")
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        writer.transport.abort()
    else:
        writer.close()


@pytest.mark.parametrize("how", ["reset", "close"])
async def test_a_flood_left_behind_by_a_vanished_client_is_not_drawn(lineus_sim, raw_peer, how: str) -> None:
    running = await lineus_sim(speed=200.0)
    flooder = await raw_peer(running.port)
    await flooder.send((DOWN + UP) * FLOOD_PAIRS)
    assert await flooder.reply(timeout=30) == b"ok X:1000.00 Y:-1000.00 Z:0.00\r\n\x00"
    _vanish(flooder.writer, how)

    nxt = await raw_peer(running.port)
    own = [f"G01 X1200 Y{n * 50} Z1000".encode() for n in range(OWN_MOVES)]
    for n, move in enumerate(own):
        assert await nxt.ask(move + b"\x00", timeout=120) == f"ok X:1200.00 Y:{n * 50}.00 Z:1000.00\r\n\x00".encode()
    drawn = [move.command for move in running.sim.arm.moves]
    assert drawn[-OWN_MOVES:] == [move.decode() for move in own]  # one after the other: nothing of the flood between
    flood = drawn[:-OWN_MOVES]
    assert flood[0] == DOWN.rstrip(b"\x00").decode()
    assert 1 <= len(flood) <= TAKEN_AT_MOST, f"{len(flood)} of the vanished client's {2 * FLOOD_PAIRS} moves ran"
    assert not running.sim.arm.busy


async def test_a_client_that_stays_gets_every_reply_of_its_flood_in_order(lineus_sim, raw_peer) -> None:
    """The reading window and the bound on owed replies pace a flood; they lose nothing of a client that stays."""
    running = await lineus_sim()
    peer = await raw_peer(running.port)
    moves = [f"G01 X{1000 + n % 400} Y{n % 300} Z{0 if n % 2 else 1000}".encode() for n in range(3000)]
    await peer.send(b"".join(move + b"\r\n" for move in moves) + b"M114\x00")
    replies = [await peer.reply() for _ in range(len(moves) + 1)]
    expected = [f"ok X:{1000 + n % 400}.00 Y:{n % 300}.00 Z:{0 if n % 2 else 1000}.00\r\n\x00".encode()
                for n in range(3000)]
    assert replies[:-1] == expected
    assert replies[-1] == expected[-1]
    assert await peer.nothing_more() == b""
