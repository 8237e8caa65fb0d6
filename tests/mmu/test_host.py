"""Printer-side logic against the simulator on one fake clock: exact handshake bytes, heartbeat, retries, failures."""

from __future__ import annotations

import pytest

from fabwire.errors import LocalProtocolError
from fabwire.mmu import host as h
from fabwire.mmu.protocol import ButtonPress, Cut, Eject, Home, Load, Mode, Request, ToolChange, Unload, encode
from fabwire.mmu.sim import Lockstep, MMUSimulator

REFERENCE_HANDSHAKE = [
    (">", "S0*c6"), ("<", "S0 A3*22"), (">", "S1*ad"), ("<", "S1 A0*34"), (">", "S2*10"), ("<", "S2 A2*65"),
    (">", "S3*7b"), ("<", "S3 A36e*4c"), (">", "Wb 5*33"), ("<", "Wb A*5c"), (">", "W14 14*94"),
    ("<", "W14 A*52"), (">", "f0*21"), ("<", "f0 A*c5"), (">", "Q0*ea"), ("<", "X0 F0*87"), (">", "R8*81"),
    ("<", "R8 A0*8d"), (">", "R1b*9e"), ("<", "R1b Aff*bf"), (">", "R1c*88"), ("<", "R1c Aff*60"), (">", "R4*7b"),
    ("<", "R4 A0*66"), (">", "R1a*f5"), ("<", "R1a A0*41"),
]
"""Right after power-on both axes are still homing, so their slots read 0xff; once homed the same poll reads
`R1b A5*29` / `R1c A5*f6` (idle capture, prusa3d/Prusa-Firmware#4301)."""


def _pair(version: str = "3.0.4", faults: tuple[str, ...] = (), **options: object) -> Lockstep:
    clock = [0.0]
    sim = MMUSimulator(version, faults=faults, clock=lambda: clock[0])
    logic = h.HostLogic(**options)  # type: ignore[arg-type]
    pair = Lockstep(logic, sim)
    pair.record = True
    logic.start(0.0)
    pair.run(lambda new: any(isinstance(e, h.LinkUp) for e in new))
    assert logic.link is h.Link.READY
    return pair


def _lines(pair: Lockstep) -> list[tuple[str, str]]:
    out = []
    for _, direction, data in pair.wire:
        out += [(direction, line) for line in data.decode().splitlines()]
    return out


def _ended(new: list[object]) -> bool:
    return any(isinstance(e, h.CommandFinished | h.CommandRejected | h.CommandInterrupted | h.LinkFailed)
               or (isinstance(e, h.ErrorRaised) and not e.auto_retry) for e in new)


def _run(pair: Lockstep, request: Request) -> list[object]:
    pair.host.plan_command(request, pair.now)  # type: ignore[attr-defined]
    return pair.run(_ended)


def test_handshake_bytes_match_the_printer() -> None:
    pair = _pair("3.0.2")
    lines = _lines(pair)
    assert lines[0] == (">", "S0*c6")
    first_answer = lines.index(("<", "S0 A3*22"))
    assert lines[first_answer - 1:] == REFERENCE_HANDSHAKE
    assert all(line == (">", "S0*c6") for line in lines[:first_answer])  # re-sent every 2 s while it boots
    s0_times = [t for t, d, data in pair.wire if data == b"S0*c6\n"]
    assert s0_times == [0.0, 2.0, 4.0]
    pair.run(lambda new: any(isinstance(e, h.StatusUpdated) and e.status.selector == 5 for e in new), limit=10)
    assert ("<", "R1b A5*29") in _lines(pair)[len(lines):]
    assert ("<", "R1c A5*f6") in _lines(pair)[len(lines):]


def test_heartbeat_after_one_second_of_silence() -> None:
    pair = _pair()
    start = pair.now
    pair.run(lambda new: False, limit=5.0)
    q0 = [t for t, d, data in pair.wire if data == b"Q0*ea\n" and t > start]
    assert q0 == pytest.approx([start + 1, start + 2, start + 3, start + 4, start + 5])
    after_q0 = [data for t, d, data in pair.wire if d == ">" and t == q0[0]]
    assert after_q0 == [b"Q0*ea\n", b"R8*81\n", b"R1b*9e\n", b"R1c*88\n", b"R4*7b\n", b"R1a*f5\n"]
    assert not any(data.startswith(b"f") for t, d, data in pair.wire if t > start)  # no f while idle


@pytest.mark.parametrize("request_", [ToolChange(1), Load(2), Unload(0), Eject(3), Cut(1), Home(0), Mode(1)],
                         ids=str)
def test_each_command_runs_to_completion(request_: Request) -> None:
    pair = _pair()
    events = _run(pair, request_)
    if isinstance(request_, Eject):  # ends waiting for the user to take the filament: Continue
        assert isinstance(events[-1], h.ErrorRaised)
        assert events[-1].code == 0x800C
        pair.host.press(1, pair.now)  # type: ignore[attr-defined]
        events += pair.run(_ended)
    finished = [e for e in events if isinstance(e, h.CommandFinished)]
    assert finished == [h.CommandFinished(str(request_), 0)]
    seen = [f"P{e.code:x}" for e in events if isinstance(e, h.ProgressChanged)]
    truth = pair.sim.progress_sequence(str(request_))
    it = iter(truth)
    assert all(code in it for code in seen), (seen, truth)  # what the host saw, in the MMU's order


def test_tool_change_reports_fsensor_and_polls_during_command() -> None:
    pair = _pair()
    _run(pair, ToolChange(1))
    lines = [line for d, line in _lines(pair) if d == ">"]
    assert "T1*cf" in lines
    assert "f1*4a" in lines
    t1 = lines.index("T1*cf")
    assert lines[t1 + 1:t1 + 8] == ["Q0*ea", "f0*21", "R8*81", "R1b*9e", "R1c*88", "R4*7b", "R1a*f5"]
    second = _run(pair, ToolChange(3))
    assert h.CommandFinished("T3", 0) in second
    assert "f0*21" in [line for d, line in _lines(pair) if d == ">"][t1 + 10:]


def test_injected_error_is_retried_automatically() -> None:
    pair = _pair(faults=("finda-didnt-trigger:1",))
    events = _run(pair, ToolChange(2))
    errors = [e for e in events if isinstance(e, h.ErrorRaised)]
    assert [(e.code, e.auto_retry) for e in errors] == [(0x8001, True)]
    assert h.ButtonSent(1) in events
    assert events[-1] == h.CommandFinished("T2", 0)
    assert pair.sim.progress_sequence("T2")[:4] == ["P5", "Pa", "E8001", "P5"]


def test_stuck_error_ends_after_three_retries() -> None:
    pair = _pair(faults=("finda-didnt-trigger:always",))
    events = _run(pair, ToolChange(2))
    errors = [e for e in events if isinstance(e, h.ErrorRaised)]
    assert [(e.auto_retry, e.retries_left) for e in errors] == [(True, 3), (True, 2), (True, 1), (False, 0)]
    assert sum(1 for _, d, data in pair.wire if data == encode(ButtonPress(1))) == 3
    final = errors[-1]
    assert final.info.meaning == "FINDA didn't trigger"
    assert final.info.action == "check the filament path, then Retry"
    assert pair.sim.model.eeprom.drive_errors == 4


def test_non_retryable_error_is_not_pressed() -> None:
    pair = _pair()
    events = _run(pair, Eject(1))
    errors = [e for e in events if isinstance(e, h.ErrorRaised)]
    assert [(e.code, e.auto_retry) for e in errors] == [(0x800C, False)]
    assert not any(data.startswith(b"B") for _, d, data in pair.wire)


def test_version_mismatch_after_six_tries() -> None:
    clock = [0.0]
    sim = MMUSimulator("3.0.4", clock=lambda: clock[0])
    logic = h.HostLogic(accepted={(3, 0, 3)})
    pair = Lockstep(logic, sim)
    pair.record = True
    logic.start(0.0)
    events = pair.run(lambda new: any(isinstance(e, h.LinkFailed) for e in new))
    failed = [e for e in events if isinstance(e, h.LinkFailed)]
    assert failed[0].code == 0x802C
    assert "3.0.4" in failed[0].detail
    assert sum(1 for _, d, data in pair.wire if data == b"S2*10\n") == 6
    assert logic.link is h.Link.FAILED
    assert logic.next_deadline() is None


def test_silent_mmu_times_out_then_fails_after_ten_drop_outs() -> None:
    logic = h.HostLogic()
    logic.start(0.0)
    sent: list[tuple[float, bytes]] = [(0.0, logic.data_to_send())]
    events: list[object] = []
    for _ in range(12):
        deadline = logic.next_deadline()
        assert deadline is not None
        logic.handle_timer(deadline)
        sent.append((deadline, logic.data_to_send()))
        events += logic.events()
    assert all(data == b"S0*c6\n" for _, data in sent)
    assert [t for t, _ in sent][:4] == [0.0, 2.0, 4.0, 6.0]
    lost = [e for e in events if isinstance(e, h.LinkLost)]
    assert len(lost) == 12
    failed = [e for e in events if isinstance(e, h.LinkFailed)]
    assert [e.code for e in failed] == [0x802E]
    assert failed[0].info.meaning == "the MMU does not answer"


def test_a_garbled_reply_costs_a_short_resync_not_a_handshake_and_the_command_continues() -> None:
    pair = _pair()
    pair.host.plan_command(ToolChange(1), pair.now)  # type: ignore[attr-defined]
    pair.run(lambda new: any(isinstance(e, h.ProgressChanged) for e in new))
    corrupted = [False]

    def mangle(reply: bytes) -> bytes:
        if not corrupted[0] and reply.startswith(b"T1 P"):
            corrupted[0] = True
            return reply.replace(b"P", b"Z", 1)
        return reply

    events = pair.run(_ended, mangle=mangle)
    lost = [e for e in events if isinstance(e, h.LinkLost)]
    assert len(lost) == 1
    assert lost[0].reason.startswith("protocol error")
    bad = next(i for i, (_, d, data) in enumerate(pair.wire) if d == "<" and data.startswith(b"T1 Z"))
    after = [(t, data) for t, d, data in pair.wire[bad + 1:] if d == ">"]
    assert after[0] == (pair.wire[bad][0] + h.RESYNC_GAP, b"Q0*ea\n")  # asked again once the line was quiet
    assert all(not data.startswith(b"S") for _, data in after)  # no new handshake: the link was fine
    assert events[-1] == h.CommandFinished("T1", 0)


def test_a_lost_command_acknowledgement_is_looked_up_not_sent_twice() -> None:
    pair = _pair()
    pair.host.plan_command(ToolChange(2), pair.now)  # type: ignore[attr-defined]
    dropped = [False]

    def mangle(reply: bytes) -> bytes:
        if not dropped[0] and reply.startswith(b"T2 A"):
            dropped[0] = True
            return b"T2 A*00\n"  # CRC broken: the host cannot know the MMU accepted it
        return reply

    events = pair.run(_ended, mangle=mangle)
    sent = [data for _, d, data in pair.wire if d == ">" and data.startswith(b"T2")]
    assert len(sent) == 1, sent  # the look-up found T2 running: no second T2
    assert events[-1] == h.CommandFinished("T2", 0)


def test_after_a_full_restart_the_host_adopts_the_running_command_and_its_error() -> None:
    pair = _pair(faults=("fsensor-didnt-trigger:always",), auto_retries=0)
    pair.host.plan_command(ToolChange(1), pair.now)  # type: ignore[attr-defined]
    pair.run(lambda new: any(isinstance(e, h.ProgressChanged) for e in new))
    cut_until = pair.now + 5.0

    def cable_out(reply: bytes) -> bytes:  # 5 s without replies: the host gives up on the link and restarts it
        return b"" if pair.now < cut_until else reply

    events = pair.run(_ended, mangle=cable_out)
    assert any(isinstance(e, h.LinkUp) for e in events)  # a new handshake happened
    assert pair.host.busy  # type: ignore[attr-defined]
    last = events[-1]
    assert isinstance(last, h.ErrorRaised)
    assert (last.code, last.command) == (0x8003, "T1")


def test_interrupted_when_the_mmu_reboots_mid_command() -> None:
    pair = _pair()
    pair.host.plan_command(ToolChange(1), pair.now)  # type: ignore[attr-defined]
    pair.run(lambda new: any(isinstance(e, h.ProgressChanged) for e in new))
    pair.sim.model.power_on(pair.sim.now())
    events = pair.run(_ended)
    assert events[-1] == h.CommandInterrupted("T1", "X0")


def test_rejected_command_is_resent_then_given_up() -> None:
    pair = _pair(faults=("finda-didnt-trigger:always",))
    pair.sim.exchange(b"T0*a4\n", pair.now)  # someone else started a command the MMU is now stuck in
    pair.sim.model.advance(pair.now + 20)
    pair.now += 20
    logic = pair.host
    assert isinstance(logic, h.HostLogic)
    logic._command = None
    logic._scope = "idle"
    logic.plan_command(Load(1), pair.now)
    events = pair.run(lambda new: any(isinstance(e, h.CommandRejected) for e in new))
    rejected = [e for e in events if isinstance(e, h.CommandRejected)]
    assert rejected == [h.CommandRejected("L1", h.REJECT_LIMIT)]
    sends = [t for t, d, data in pair.wire if data == encode(Load(1))]
    assert len(sends) == h.REJECT_LIMIT
    assert sends[1] == sends[0]  # the first re-sends go out at once


def test_ok_from_old_firmware_is_a_version_mismatch() -> None:
    logic = h.HostLogic()
    logic.start(0.0)
    logic.receive(b"ok\nok\n", 0.1)
    failed = [e for e in logic.events() if isinstance(e, h.LinkFailed)]
    assert failed[0].code == 0x802C


def test_ten_garbled_replies_surface_a_communication_error() -> None:
    logic = h.HostLogic()
    logic.start(0.0)
    events: list[object] = []
    now = 0.0
    for _ in range(10):
        logic.data_to_send()
        logic.receive(b"S0 A3*ff\n", now)
        now += 1.0
        logic.handle_timer(now)
        events += logic.events()
    failed = [e for e in events if isinstance(e, h.LinkFailed)]
    assert [e.code for e in failed] == [0x802D]


def test_buttons_registers_and_reset_through_the_logic() -> None:
    pair = _pair()
    logic = pair.host
    assert isinstance(logic, h.HostLogic)
    logic.read_register(0x22, pair.now)
    events = pair.run(lambda new: any(isinstance(e, h.RegisterRead) for e in new))
    assert h.RegisterRead(0x22, 360) in events
    logic.write_register(0x0B, 7, pair.now)
    events = pair.run(lambda new: any(isinstance(e, h.RegisterWritten) for e in new))
    assert h.RegisterWritten(0x0B, 7, True) in events
    logic.write_register(0x00, 1, pair.now)
    events = pair.run(lambda new: any(isinstance(e, h.RegisterWritten) for e in new))
    assert h.RegisterWritten(0x00, 1, False) in events
    logic.press(2, pair.now)
    assert h.ButtonSent(2) in pair.run(lambda new: any(isinstance(e, h.ButtonSent) for e in new))
    logic.reset(pair.now)
    events = pair.run(lambda new: any(isinstance(e, h.LinkUp) for e in new))
    assert any(isinstance(e, h.LinkLost) for e in events)
    assert pair.sim.model.requests_seen > 0
    assert (">", "X0*4c") in _lines(pair)


def test_plan_refuses_a_second_command() -> None:
    pair = _pair()
    pair.host.plan_command(ToolChange(1), pair.now)  # type: ignore[attr-defined]
    with pytest.raises(LocalProtocolError):
        pair.host.plan_command(ToolChange(2), pair.now)  # type: ignore[attr-defined]
    with pytest.raises(LocalProtocolError):
        h.HostLogic().plan_command(Request(0), 0.0)


def test_time_scale_shrinks_every_timer() -> None:
    logic = h.HostLogic(time_scale=100)
    logic.start(0.0)
    assert logic.next_deadline() == pytest.approx(0.02)


@pytest.mark.parametrize(("ask", "answered"), [
    (lambda logic, now: logic.read_register(0x22, now), h.RegisterRead(0x22, 360)),
    (lambda logic, now: logic.write_register(0x22, 400, now), h.RegisterWritten(0x22, 400, True)),
    (lambda logic, now: logic.press(2, now), h.ButtonSent(2)),
], ids=["read", "write", "button"])
def test_a_request_in_flight_when_the_link_restarts_is_asked_again(ask: object, answered: object) -> None:
    """The caller's read, write or button press is not dropped with the link: after the new handshake it is sent
    again and answered (else the caller waits out its whole timeout)."""
    pair = _pair()
    assert callable(ask)
    ask(pair.host, pair.now)
    cut_until = pair.now + 5.0

    def cable_out(reply: bytes) -> bytes:  # silent for 5 s: two timeouts in a row restart the handshake
        return b"" if pair.now < cut_until else reply

    handshakes = _lines(pair).count((">", "S0*c6"))
    events = pair.run(lambda new: answered in new, mangle=cable_out, limit=60)
    assert _lines(pair).count((">", "S0*c6")) > handshakes  # it was a full restart
    assert events.count(answered) == 1


@pytest.mark.parametrize("junk", [b"ok\n", b"T1 Pok*00\n", b"\x00book\r\n"])
def test_ok_in_line_noise_after_the_handshake_is_no_version_verdict(junk: bytes) -> None:
    """Only an MMU that answers the handshake with 'ok' runs firmware 1.x; once the version is known, bytes that
    happen to hold 'ok' are one garbled reply, resynchronised like any other."""
    pair = _pair()
    pair.host.read_register(0x22, pair.now)  # type: ignore[attr-defined]
    pair.host.data_to_send()  # type: ignore[attr-defined]  # the read is in flight: its reply is replaced by junk
    pair.host.receive(junk, pair.now)  # type: ignore[attr-defined]
    events = pair.run(lambda new: h.RegisterRead(0x22, 360) in new, limit=30)
    assert h.RegisterRead(0x22, 360) in events
    assert not any(isinstance(e, h.LinkFailed) for e in events)
    assert pair.host.link is h.Link.READY  # type: ignore[attr-defined]


def test_a_reply_trickled_byte_by_byte_without_an_end_is_a_timeout() -> None:
    """Each byte restarts the firmware's 2 s clock; a device that trickles digits of a never-ending line is still
    a drop-out once the reply has taken two link timeouts, and the read is asked again."""
    pair = _pair()
    logic = pair.host
    logic.read_register(0x22, pair.now)  # type: ignore[attr-defined]
    assert logic.data_to_send() == b"R22*45\n"  # type: ignore[attr-defined]
    now = pair.now
    logic.receive(b"R22 A", now)  # type: ignore[attr-defined]
    lost: list[object] = []
    for _ in range(40):  # a digit every 0.5 s: never 2 s of silence
        now += 0.5
        logic.receive(b"0", now)  # type: ignore[attr-defined]
        logic.handle_timer(now)  # type: ignore[attr-defined]
        lost += [e for e in logic.events() if isinstance(e, h.LinkLost)]  # type: ignore[attr-defined]
        if lost:
            break
    assert lost == [h.LinkLost("timeout: no complete reply within 4 s", 1)]
    assert now - pair.now <= 4.5
