"""One G-code interpreter: a file previews exactly as the simulated machine draws it when the same lines are sent."""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fabwire.errors import InputError
from fabwire.lineus import kinematics as kin
from fabwire.lineus.interpreter import Ink, Interpreter, read_program, trace_text
from fabwire.lineus.plot import parse_gcode_text, plan_file
from fabwire.lineus.sim import LineUsSim, SimOptions
from fabwire.transport import memory_pair

DATA = Path(__file__).parent / "data" / "gcode"
TERM = b"\r\n\x00"


async def drawn_by_simulator(text: str, **options: object) -> LineUsSim:
    """Send every line of `text` (comments removed, as `files save` does) over the wire, one reply each."""
    sim = LineUsSim(SimOptions(speed=0, **options))  # type: ignore[arg-type]
    host, device = memory_pair("lineus")
    server = asyncio.create_task(sim.serve(device))
    buffer = b""

    async def reply() -> bytes:
        nonlocal buffer
        while TERM not in buffer:
            buffer += await host.read()
        message, buffer = buffer.split(TERM, 1)
        return message

    async with asyncio.timeout(30):
        assert (await reply()).startswith(b"hello")
        for line in read_program(text).lines:
            await host.write(line.text.encode() + b"\x00")
            assert (await reply()).startswith(b"ok"), line.text
        await host.close()
        await server
    return sim


def as_lists(strokes: object) -> list[list[tuple[float, float]]]:
    return [[(round(float(x), 6), round(float(y), 6)) for x, y in np.asarray(s).reshape(-1, 2)]
            for s in strokes]  # type: ignore[attr-defined]


@pytest.mark.parametrize("name", ["plt-scaled.txt", "dots.gcode", "mixed.gcode", "dot-left-down.gcode"])
async def test_file_reads_as_the_simulator_draws_it(name: str) -> None:
    text = (DATA / name).read_text()
    sim = await drawn_by_simulator(text)
    assert as_lists(parse_gcode_text(text)) == as_lists(sim.arm.strokes)
    assert sim.arm.strokes  # every file draws something
    assert not any(record.clamped for record in sim.arm.moves)


def test_scaled_plotter_file_lands_where_g54_puts_it() -> None:
    plan = plan_file(DATA / "plt-scaled.txt")
    [square] = plan.strokes
    assert square.min(axis=0).tolist() == pytest.approx([837, 174])
    assert square.max(axis=0).tolist() == pytest.approx([1237, 574])


def test_frames_z_and_comments() -> None:
    strokes = as_lists(parse_gcode_text((DATA / "mixed.gcode").read_text()))
    assert strokes == [
        [(1000, 0), (1200, 0), (1400, -300), (1400, -200)],  # G54, then G40 in machine units, Z300 still down
        [(1100, 200), (1300, 200)],  # after G28; parameters run together; lower case
        [(1100, -100), (900, -100)],  # mirrored G54; Z499 is down, Z500 up
        [(1500, 500), (1500, 200)],  # G00 with the pen up lands, then draws
    ]


def test_dots_are_one_point_marks() -> None:
    strokes = as_lists(parse_gcode_text((DATA / "dots.gcode").read_text()))
    assert strokes == [[(1000, 0)], [(1200, 0)], [(1400, 0)], [(1200, 300), (1300, 300)]]
    assert as_lists(parse_gcode_text((DATA / "dot-left-down.gcode").read_text())) == [[(1500, -500)]]


def test_ink_rules() -> None:
    ink = Ink()
    ink.move((1000, 0, 1000), (1000, 0, 0))  # drop: a dot so far
    ink.move((1000, 0, 0), (1000, 0, 0))  # staying down in place adds nothing
    ink.move((1000, 0, 0), (1100, 0, 1000))  # a lift happens before the XY motion
    ink.move((1100, 0, 1000), (1200, 0, 0))  # a drop after it
    ink.move((1200, 0, 0), (1300, 0, 0))
    assert ink.strokes == [[(1000, 0)], [(1200, 0), (1300, 0)]]
    assert ink.travel == [[(1000, 0), (1100, 0)], [(1100, 0), (1200, 0)]]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("G91\nG01 X1 Y1", "G91 .relative positioning"),
        ("G03 X1 Y1 I1 J1", "arcs"),
        ("G01 X10 Yabc Z0", "bad.gcode, line 1: cannot read parameters"),
        ("G01 X1000\nhello there", "bad.gcode, line 2: cannot read 'hello there'"),
        ("G05 X1", "unknown command G05"),
        ("G01 X1e3", "not a number"),
        ("G01 X1 X2", "given twice"),
    ],
)
def test_lines_the_machine_refuses_are_input_errors(text: str, message: str) -> None:
    with pytest.raises(InputError, match=message):
        read_program(text, name="bad.gcode")


def test_other_dialects_harmless_lines_are_skipped_and_named() -> None:
    program = read_program("G21\nG90\nM3 S1000\nG01 X1000 Y0 Z0\nM5\n")
    assert [line.text for line in program.lines] == ["G01 X1000 Y0 Z0"]
    assert [number for number, _, _ in program.skipped] == [1, 2, 3, 5]
    note = program.skipped_note()
    assert note is not None
    assert "line 1 'G21'" in note
    notes: list[str] = []
    parse_gcode_text("G21\nG01 X1000 Y0 Z0\nG01 Z1000\n", notes=notes)
    assert notes
    assert "skipped 1 line(s)" in notes[0]


def test_lenient_reading_skips_what_the_firmware_refuses() -> None:
    program = read_program("G01 X1000 Y0\nbogus\nG02 X1\nG01 Y100\n", strict=False)
    assert [line.number for line in program.lines] == [1, 4]
    assert len(program.skipped) == 2


def test_interpreter_targets() -> None:
    from fabwire.lineus import protocol as p

    machine = Interpreter()
    machine.set_origin(p.SetOrigin(100, -50, 2.5))
    here = (1000.0, 1000.0, 1000.0)
    assert machine.motion(p.Move(400, 40), here).target == (1100, 50, 1000)
    assert machine.motion(p.RawMove(1200, 0), here).target == (1200, 0, 1000)  # G40: no G54
    assert machine.motion(p.Home(), (1200, 0, 0)).target == (1000, 1000, 1000)
    assert machine.motion(p.Move(z=-1), here).target[2] == 1000  # below 0: fully up
    assert machine.motion(p.Move(z=1001), here).target[2] == 1000
    out = machine.motion(p.Move(1000, 0, 0), here)  # machine (2600, -50): outside, clamped, pen lifted
    assert out.clamped
    assert out.target[2] == 1000
    assert kin.is_reachable(*out.target[:2])
    raw = Interpreter(clamp=False).motion(p.Move(3000, 0, 0), here)
    assert raw.target == (3000, 0, 0)
    assert not raw.clamped


SAFE_X = st.floats(800, 1600, allow_nan=False).map(lambda v: round(v, 2))
SAFE_Y = st.floats(-600, 600, allow_nan=False).map(lambda v: round(v, 2))
Z = st.sampled_from([None, 0, 300, 499, 500, 1000, -100, 1500])


@st.composite
def programs(draw: st.DrawFn) -> str:
    """Random in-area programs: G54 frames, G01/G00/G40/G28, partial axes, odd Z, comments."""
    lines = []
    ox, oy, scale = 0.0, 0.0, 1.0
    for _ in range(draw(st.integers(1, 25))):
        kind = draw(st.sampled_from(["G01", "G01", "G01", "G00", "G40", "G28", "G54", "Z", "note"]))
        if kind == "G54":
            ox, oy = draw(st.sampled_from([0.0, 100.0, -250.0])), draw(st.sampled_from([0.0, 50.0, -75.0]))
            scale = draw(st.sampled_from([1.0, 2.0, 0.5, -1.0]))
            lines.append(f"G54 X{ox:g} Y{oy:g} S{scale:g}")
        elif kind == "G28":
            lines.append("G28")
        elif kind == "note":
            lines.append("; a comment line")
        elif kind == "Z":
            lines.append(f"G01 Z{draw(st.sampled_from([0, 300, 1000]))}")
        else:
            x, y, z = draw(SAFE_X), draw(SAFE_Y), draw(Z)
            if kind != "G40":  # drawing units through G54, so the machine point stays in the safe box
                x, y = round((x - ox) / scale, 4), round((y - oy) / scale, 4)
            tail = "" if z is None else f" Z{z}"
            lines.append(f"{kind} X{x:g} Y{y:g}{tail}  (move)")
    return "\n".join(lines) + "\n"


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(programs())
def test_any_program_reads_as_the_simulator_draws_it(text: str) -> None:
    sim = asyncio.run(drawn_by_simulator(text))
    expected = as_lists(sim.arm.strokes)
    got = as_lists(trace_text(text).ink.strokes)
    assert len(got) == len(expected)
    for a, b in zip(got, expected, strict=True):
        assert np.allclose(a, b, atol=1e-3)


def test_a_bounded_ink_record_drops_its_oldest_points_and_keeps_the_stroke_under_the_pen() -> None:
    from fabwire.lineus.interpreter import TRIM_EVERY

    keep = 50
    ink = Ink(keep=keep)
    ink.move((1000, 0, 1000), (1000, 0, 0))
    for n in range(1, 2 * TRIM_EVERY):  # one long stroke, one point per move
        ink.move((1000 + n - 1, 0, 0), (1000 + n, 0, 0))
    ink.move((1000 + 2 * TRIM_EVERY - 1, 0, 0), (1200, 300, 1000))  # lift and travel
    ink.move((1200, 300, 1000), (1200, 300, 0))
    ink.move((1200, 300, 0), (1300, 300, 0))
    held = sum(map(len, ink.strokes))
    assert held <= keep + TRIM_EVERY
    assert ink.dropped == 2 * TRIM_EVERY - held + 2  # the dropped and the held add up to every point drawn
    assert ink.strokes[-1] == [(1200, 300), (1300, 300)]
    assert ink.strokes[0][-1] == (1000 + 2 * TRIM_EVERY - 1, 0)  # the old stroke lost its start, not its end
    for _ in range(TRIM_EVERY):  # dots, each its own stroke
        ink.move((1300, 300, 0), (1300, 300, 1000))
        ink.move((1300, 300, 1000), (1300, 300, 0))
    assert sum(map(len, ink.strokes)) <= keep + TRIM_EVERY
    assert ink.strokes[-1] == [(1300, 300)]


def test_an_unbounded_ink_record_keeps_every_point() -> None:
    from fabwire.lineus.interpreter import TRIM_EVERY

    ink = Ink()
    ink.move((1000, 0, 1000), (1000, 0, 0))
    for n in range(1, 3 * TRIM_EVERY):
        ink.move((1000 + n - 1, 0, 0), (1000 + n, 0, 0))
    assert ink.strokes == [[(1000 + n, 0) for n in range(3 * TRIM_EVERY)]]
    assert ink.dropped == 0
