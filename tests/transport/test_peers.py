"""A client pointed at another kind of machine or server names what it found, from what that peer said, instead of
waiting out its reply timeout: every row of `FOREIGN`, each client kind, over real TCP through the real CLI."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from hypothesis import given
from hypothesis import strategies as st

from clitools import run_cli
from fabwire.transport.peers import FOREIGN, identify
from peertools import SAID, saying

OWN: dict[str, list[bytes]] = {
    "xyz": [b"j:9511,0\n", b"ok\n", b"$\n", b"E4$\n", b"b:20\n", b"t:1,180,200\n"],
    "mmu": [b"S0 A1*3f\n", b"X0 A0*a1\n", b"Q0 E8008*1c\n"],
    "lineus": [SAID["a Line-us drawing robot"], b"ok X:1000 Y:1000 Z:1000\r\n\0"],
}
"""What each machine of ours says itself: never taken for another peer by its own client."""

CLIENTS = {"xyz": ("xyz", "status"), "mmu": ("mmu", "status"), "lineus": ("lineus", "info")}
EXPECTED = {"xyz": "an XYZv3 printer", "mmu": "a Prusa MMU3", "lineus": "a Line-us"}


def test_every_row_has_what_its_peer_says() -> None:
    assert {row.what for row in FOREIGN} == set(SAID)
    for row in FOREIGN:
        assert row.source
        assert identify(SAID[row.what], "mmu") is row


@pytest.mark.parametrize("kind", OWN)
def test_a_machine_of_ours_is_not_taken_for_another(kind: str) -> None:
    for said in OWN[kind]:
        assert identify(said, kind) is None, said


@given(st.binary(max_size=300))
def test_identify_takes_any_bytes(data: bytes) -> None:
    found = identify(data, "xyz")
    assert found is None or found.said.match(data[:256])


@pytest.fixture
def peer(request: pytest.FixtureRequest) -> Iterator[int]:
    """A TCP server that says its words on connect and again after every line it is sent."""
    with saying(request.param) as port:
        yield port


CASES = [(kind, row.what) for kind in CLIENTS for row in FOREIGN if row.kind != kind]


@pytest.mark.parametrize(("kind", "what", "peer"), [(k, w, SAID[w]) for k, w in CASES], indirect=["peer"],
                         ids=[f"{k}-{w}" for k, w in CASES])
def test_a_client_names_the_peer_it_reached(kind: str, what: str, peer: int) -> None:
    result = run_cli(*CLIENTS[kind][:1], "-d", f"127.0.0.1:{peer}", *CLIENTS[kind][1:])
    assert result.returncode == 6, result.stderr  # a protocol error, not a link timeout (exit 9)
    line = result.stderr.strip()
    assert line == line.splitlines()[0]
    assert f"127.0.0.1:{peer} is not {EXPECTED[kind]}: it is {what} (it said " in line, line
