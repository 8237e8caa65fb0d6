"""Outside bytes and text at every MMU boundary become values or the project's own error, and no single input
item makes the codec hold memory in proportion to it."""

from __future__ import annotations

import tracemalloc

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clitools import run_cli
from fabwire.errors import FabwireError, InputError, LocalProtocolError
from fabwire.mmu import protocol as mp
from fabwire.mmu.faults import Fault, parse_fault
from fabwire.mmu.host import HostLogic
from fabwire.mmu.protocol import encode_request, encode_response
from fabwire.mmu.sim import MMUSimulator, options_to_simulator

SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _padded_request(value: int, zeros: int) -> bytes:
    """A well-formed Q request whose number carries `zeros` leading zeros (legal: the automaton keeps low bits)."""
    return b"Q" + b"0" * zeros + f"{value:x}*{mp.request_crc('Q', value):x}\n".encode()


def _padded_response(value: int, zeros: int) -> bytes:
    return b"Q0 P" + b"0" * zeros + f"{value:x}*{mp.response_crc('Q', 0, 'P', value):x}\n".encode()


@pytest.mark.parametrize(("decoder", "line"), [(mp.RequestDecoder, _padded_request),
                                               (mp.ResponseDecoder, _padded_response)], ids=["requests", "responses"])
def test_long_well_formed_lines_are_decoded_but_not_kept(decoder: type[mp.RequestDecoder | mp.ResponseDecoder],
                                                         line: object) -> None:
    make = line
    assert callable(make)
    codec = decoder()
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for i in range(200):
            events = codec.feed(make(i & 0xFF, 4000 + i))
            assert len(events) == 1, events
            assert not isinstance(events[0], mp.DecodeError), events
            assert events[0].value == i & 0xFF or getattr(events[0], "number", None) == i & 0xFF
        held = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert held < 100_000, f"the decoder holds {held} bytes after 200 lines of ~4 KB"


@SETTINGS
@given(st.text(max_size=60) | st.from_regex(r"[a-z-]{3,25}(@[0-9]{0,6000})?(:[0-9]{0,6000})?", fullmatch=True))
def test_a_fault_spec_is_a_fault_or_one_input_error(text: str) -> None:
    try:
        fault: Fault | InputError = parse_fault(text)
    except InputError as exc:
        fault = exc
    assert isinstance(fault, Fault) or len(str(fault)) < 2000


@pytest.mark.parametrize("spec", ["finda-stuck@" + "9" * 5000, "finda-stuck:" + "9" * 5000, "finda-stuck:\u0661",
                                  "finda-stuck@\u0661", "x" * 100_000])
def test_digits_beyond_any_count_are_refused_with_a_reason(spec: str) -> None:
    with pytest.raises(InputError, match="fault") as caught:
        parse_fault(spec)
    assert len(str(caught.value)) < 2000


def test_a_simulator_address_with_a_huge_fault_skip_is_one_line_of_bad_input() -> None:
    done = run_cli("mmu", "-d", "sim://mmu?fault=finda-stuck@" + "9" * 5000, "version", timeout=60)
    assert done.returncode == 4, done.stderr
    assert done.stderr.count("\n") == 1
    assert "whole number" in done.stderr
    assert "internal error" not in done.stderr


@SETTINGS
@given(st.dictionaries(st.sampled_from(["speed", "fault", "version", "other"]),
                       st.text(max_size=30) | st.from_regex(r"[0-9]{300,5000}", fullmatch=True), max_size=4))
def test_simulator_options_are_a_simulator_or_one_input_error(options: dict[str, str]) -> None:
    try:
        sim = options_to_simulator(options)
    except InputError:
        return
    assert isinstance(sim, MMUSimulator)


# ----------------------------------------------------------------------------------- the host's reply parser

REPLIES = [encode_response(r) for r in (
    mp.Accepted("S", 0, 3), mp.Accepted("S", 1, 0), mp.Accepted("S", 2, 4), mp.Accepted("S", 3, 936),
    mp.Accepted("W", 0x0B), mp.Accepted("f", 0), mp.Finished("X", 0), mp.Accepted("R", 8, 1),
    mp.Accepted("T", 1), mp.Rejected("T", 1), mp.Processing("T", 1, 5), mp.CommandError("T", 1, 0x8004),
    mp.Finished("T", 1), mp.ButtonPressed("T", 1, 1), mp.Accepted("B", 1), mp.Processing("X", 0, 0x1A),
    mp.CommandError("X", 0, 0xC2C0), mp.Finished("L", 7, 0xFFFF), mp.Accepted("R", 0x1A, 0xFFFF),
)] + [b"ok\n", b"\r\n", b"T1 E80*00\n", b"\x00\xff", b"Q0 P" + b"0" * 3000 + b"5*00\n"]

Step = tuple[str, bytes | int]
STEPS = st.lists(st.one_of(
    st.tuples(st.just("bytes"), st.lists(st.sampled_from(REPLIES) | st.binary(max_size=30), max_size=4).map(
        b"".join)),
    st.tuples(st.just("wait"), st.integers(0, 3000)),
    st.tuples(st.sampled_from(["command", "press", "read", "write", "reset", "abandon", "fsensor"]),
              st.integers(0, 255)),
), max_size=40)


@SETTINGS
@given(STEPS)
def test_the_host_logic_takes_any_reply_bytes_in_any_state(steps: list[Step]) -> None:
    """Whatever the MMU sends, whenever: the host emits events and bytes, and raises only for a caller's misuse."""
    logic = HostLogic(time_scale=10)
    now = 0.0
    logic.start(now)
    refused: list[str] = []
    for kind, arg in steps:
        if kind == "bytes":
            assert isinstance(arg, bytes)
            logic.receive(arg, now)
        elif kind == "wait":
            assert isinstance(arg, int)
            now += arg / 1000
            logic.handle_timer(now)
        else:
            assert isinstance(arg, int)
            try:
                if kind == "command":
                    logic.plan_command(mp.make_request("TLUEKHM"[arg % 7], arg % 6), now)
                elif kind == "press":
                    logic.press(arg % 3, now)
                elif kind == "read":
                    logic.read_register(arg % 0x24, now)
                elif kind == "write":
                    logic.write_register(arg % 0x24, arg * 257, now)
                elif kind == "reset":
                    logic.reset(now)
                elif kind == "abandon":
                    logic.abandon()
                else:
                    logic.set_fsensor(arg % 4, now)
            except LocalProtocolError as exc:
                refused.append(str(exc))
        for event in logic.events():
            str(event)  # every event can be shown
        sent = logic.data_to_send()
        if sent:
            assert all(isinstance(e, mp.Request) for e in mp.RequestDecoder().feed(sent))
    assert all("already running" in r for r in refused)
    deadline = logic.next_deadline()
    assert deadline is None or deadline >= 0


@SETTINGS
@given(st.binary(max_size=200))
def test_any_bytes_to_a_simulator_are_answered_or_ignored(data: bytes) -> None:
    """The simulator's side of the same boundary: anything in, well-formed replies (or none) out."""
    t = [0.0]
    sim = MMUSimulator(speed=1, clock=lambda: t[0])
    t[0] = 5.0  # booted
    out = sim.exchange(data + b"\n", t[0])
    query = encode_request(mp.Query(0))
    out += sim.exchange(query, t[0]) + sim.exchange(query, t[0])  # a line in error eats the next one, no more
    events = mp.ResponseDecoder().feed(out)
    assert all(isinstance(e, mp.Response) for e in events)
    if not sim.model.booting:  # an X in the junk reboots it: deaf for 4 s, as the board is
        assert any(isinstance(e, mp.Response) and e.param in "PEFB" for e in events), out


def test_project_errors_share_one_base() -> None:
    assert issubclass(InputError, FabwireError)


@pytest.mark.parametrize("port", ["9" * 5000, "\u0661\u0662", "65536", "-1", "1e3"])
def test_a_listen_port_beyond_any_port_is_one_line_of_bad_input(port: str) -> None:
    done = run_cli("sim", "mmu", "--listen", f"127.0.0.1:{port}", timeout=60)
    assert done.returncode == 4, done.stderr
    assert done.stderr.count("\n") == 1
    assert "port must be a number from 0 to 65535" in done.stderr
