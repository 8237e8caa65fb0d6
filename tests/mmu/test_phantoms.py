"""The phantom frame: a one-byte garbage line right after a valid frame, which the firmware's response decoder
reports as a second copy of that frame (Prusa-Firmware-MMU protocol.cpp DecodeResponse, first-field error path).
fabwire reproduces it only behind a switch, and its host never acts on one."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fabwire.mmu import host as h
from fabwire.mmu.protocol import (
    Accepted,
    DecodeError,
    Finished,
    Processing,
    RequestDecoder,
    ResponseDecoder,
    ToolChange,
    encode,
    encode_response,
)
from fabwire.mmu.sim import Lockstep, MMUSimulator

FRAME = b"T1 A*27\n"
GARBAGE = st.binary(min_size=1, max_size=4).filter(lambda b: not set(b) & set(b"QTLMUXPSBEWKFfHR\r\n"))


def test_the_firmware_quirk_behind_the_switch() -> None:
    assert ResponseDecoder().feed(FRAME + b"a\n") == [Accepted("T", 1), DecodeError("not a request code", b"a")]
    assert ResponseDecoder(phantoms=True).feed(FRAME + b"a\n") == [
        Accepted("T", 1), DecodeError("not a request code", b"a"), Accepted("T", 1)]
    assert ResponseDecoder(phantoms=True).feed(FRAME + b"ab\n")[2:] == []  # a second bad byte marks it unknown
    assert ResponseDecoder(phantoms=True).feed(b"a\n") == [DecodeError("not a request code", b"a")]  # no frame yet
    split = ResponseDecoder(phantoms=True)
    assert [split.feed(FRAME), split.feed(b"a"), split.feed(b"\n")][2] == [Accepted("T", 1)]


FRAMES = [FRAME, encode_response(Processing("T", 1, 5)), encode_response(Accepted("R", 8, 1)),
          encode_response(Finished("T", 1, 0))]


@given(frames=st.lists(st.sampled_from(FRAMES), min_size=1, max_size=6),
       garbage=st.lists(GARBAGE, min_size=1, max_size=6))
def test_the_default_decoder_reports_each_frame_once(frames: list[bytes], garbage: list[bytes]) -> None:
    wire = b"".join(f + g + b"\n" for f, g in zip(frames, garbage, strict=False)) + b"".join(frames[len(garbage):])
    plain = [e for e in ResponseDecoder().feed(wire) if not isinstance(e, DecodeError)]
    assert len(plain) == len(frames)
    quirky = [e for e in ResponseDecoder(phantoms=True).feed(wire) if not isinstance(e, DecodeError)]
    assert len(quirky) == len(frames) + sum(1 for g in garbage[:len(frames)] if len(g) == 1)


def test_a_simulator_can_repeat_a_request_for_hosts_to_be_tested_against() -> None:
    assert RequestDecoder(phantoms=True).feed(b"B1*dc\na\n")[-1] == RequestDecoder().feed(b"B1*dc\n")[0]
    clock = [0.0]
    quirky = MMUSimulator(clock=lambda: clock[0], phantom_requests=True)
    plain = MMUSimulator(clock=lambda: clock[0])
    clock[0] = 10.0  # booted
    assert quirky.exchange(b"B1*dc\na\n") == b"B1 A*38\nB1 A*38\n"  # the press arrives twice
    assert plain.exchange(b"B1*dc\na\n") == b"B1 A*38\n"


def test_the_fault_sends_a_phantom_after_a_reply() -> None:
    clock = [0.0]
    sim = MMUSimulator(clock=lambda: clock[0], faults=["phantom-reply:1"])
    clock[0] = 10.0
    assert sim.exchange(b"Q0*ea\n") == encode_response(Finished("X", 0, 0)) + b"a\n"
    assert sim.exchange(b"Q0*ea\n") == encode_response(Finished("X", 0, 0))


@pytest.mark.parametrize("skip", range(0, 60, 4))
def test_the_host_never_acts_on_a_phantom(skip: int) -> None:
    """Whichever reply the phantom follows (the command's A, a status, a register, the Retry's B1 A), the host
    takes it as the line error it is: the command runs once, Retry is pressed once, it finishes once."""
    clock = [0.0]
    sim = MMUSimulator(clock=lambda: clock[0], faults=["finda-didnt-trigger:1"])
    logic = h.HostLogic()
    pair = Lockstep(logic, sim)
    pair.record = True
    logic.start(0.0)
    pair.run(lambda new: any(isinstance(e, h.LinkUp) for e in new))
    sim.inject(f"phantom-reply@{skip}:1")
    logic.plan_command(ToolChange(1), pair.now)
    events = pair.run(lambda new: any(isinstance(e, h.CommandFinished) for e in new))
    assert [e for e in events if isinstance(e, h.CommandFinished)] == [h.CommandFinished("T1", 0)]
    sent = [data for _, direction, data in pair.wire if direction == ">"]
    assert sent.count(encode(ToolChange(1))) == 1
    assert sum(1 for e in events if isinstance(e, h.ButtonSent)) == 1
    assert sim.progress_sequence("T1").count("E8001") == 1
    assert "phantom-reply" not in sim.causes()  # the phantom was sent
