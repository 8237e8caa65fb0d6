"""A coordinate a printer's number reader takes differently from plain decimals (an exponent, NaN, infinity) is
refused with its line, at any place in the file and in any axis or parameter word; the same text in a comment
or a message is left alone."""

from __future__ import annotations

import io
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fabwire.errors import InputError
from fabwire.xyz import intake
from fabwire.xyz.threew import convert_gcode_file

LINES = [b"G28\n", b"G1 Z0.3 F600\n"] + [b"G1 X%d Y%d E%d F1200\n" % (i % 90, i % 13, i) for i in range(6000)]
ODD = [b"X1e308", b"X1E5", b"Y.5e2", b"Z-1e400", b"E+2e1", b"F1e9", b"XNaN", b"Yinf", b"Z-INF", b"X nan", b"I1e3",
       b"R2E1"]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(at=st.integers(2, len(LINES)), word=st.sampled_from(ODD), move=st.sampled_from([b"G1", b"G0", b"N12 G1",
                                                                                       b"g1", b"G2"]))
def test_an_odd_number_is_refused_with_its_line(tmp_path: Path, at: int, word: bytes, move: bytes) -> None:
    src = tmp_path / "odd.gcode"
    src.write_bytes(b"".join(LINES[:at]) + move + b" " + word + b" E1\n" + b"".join(LINES[at:]))
    forms = r"\((a number with an exponent|NaN or infinity)\)"
    said = r"(is not one plain decimal number|runs two words together)"  # X1E5: an exponent, or E5 glued on
    with pytest.raises(InputError, match=rf"line {at + 1}: .* {said} {forms}"):
        intake.gcode_metadata(src)
    with pytest.raises(InputError, match=rf"line {at + 1}: "):
        convert_gcode_file(src, tmp_path / "out.3w")


@pytest.mark.parametrize("line", [b"; X1e5 in a comment\n", b"M117 XNaN on the screen\n",
                                  b"G1 X10 Y10 E1 ; Xinf\n", b"G1 X10 (Y1e5) E1\n", b"G1 X12.5 E0.5\n"])
def test_the_same_text_outside_a_move_is_left_alone(tmp_path: Path, line: bytes) -> None:
    src = tmp_path / "ok.gcode"
    src.write_bytes(b"".join(LINES[:5]) + line + b"".join(LINES[5:]))
    convert_gcode_file(src, tmp_path / "out.3w")
    assert (tmp_path / "out.3w").exists()


_PLAIN = [b"G1 X10.5 Y2 E0.25", b"G0 X1 Y2", b"G92 E0", b"G28", b"G4 P100", b"M117 XNaN here", b"; X1e5 in a comment",
          b"G1 X1 ; Yinf", b"T0", b"", b"G1 X1 Y1 E2", b";LAYER_CHANGE", b"G1 Z0.2", b"G1 X" + b"1" * 30,
          b"G1 ;" + b"x" * 50, b"G2 X1 Y1 I1 J0 E1", b"M204 S500"]
_RARE = [b"G1X10E5", b"G1 X1 (Y1e5) E1", b"  G1 X1e5", b"N10 G1 Xnan", b"g1 x1e5", b"G1 X1 I1e3", b"G28 Xinf",
        b"G1 E1.5e", b"G1 X.5e2", b"G1 X+inf", b"G1 X - nan", b"G1 Rinf", b"G1 X1.E2", b"G29 Je1", b"\0",
        b"  G1 X1", b"N3 G1 X2 E1", b"G92 X1 E1e3", b"G1 X--5", b"G1 X- Y1", b"G1 X. E1", b"G1 X1.2.3",
        b"G1 X1 0", b"G1 X10,5", b"G1 X Y1", b"G28 X-", b"G1 X1-", b"G0 X\xe2\x88\x921", b"G1 #X1", b"G1 X1 E1 ; X--1",
        b"G28 X Y", b"G92 E", b"G1 X0x10"]
_PIECES = _PLAIN * 8 + _RARE
"""Lines of a file: plain ones mostly, and rarer ones that hold such a number (in their code, a comment or elsewhere)
or that only the line-by-line reader reads (indented, numbered, lower case, comments in parentheses), or a NUL."""


@settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(lines=st.lists(st.sampled_from(_PIECES), max_size=80), ends=st.lists(st.sampled_from([b"\n", b"\r\n", b"\r"]),
                                                                          min_size=1, max_size=3),
       chunk=st.integers(16, 200), longest=st.integers(24, 400), final=st.booleans())
def test_the_analysis_finds_the_same_first_odd_number_as_reading_every_line(
        monkeypatch: pytest.MonkeyPatch, lines: list[bytes], ends: list[bytes], chunk: int, longest: int,
        final: bool) -> None:
    from fabwire.xyz.gcodeinfo import MoveAnalyzer

    text = b"".join(line + ends[k % len(ends)] for k, line in enumerate(lines))
    text = text if final else text.rstrip(b"\r\n")
    monkeypatch.setattr(intake, "CHUNK", chunk)
    monkeypatch.setattr(intake, "MAX_LINE", longest)

    def outcome(analysed: bool) -> str:
        try:
            if analysed:
                odd: list[tuple[int, int]] = []
                analyzer = MoveAnalyzer()
                for piece in intake.gcode_lines(io.BytesIO(text), "f", odd=odd):
                    analyzer.feed_chunk(piece, odd)
            else:
                for _ in intake.gcode_lines(io.BytesIO(text), "f"):
                    pass
        except InputError as exc:
            return str(exc)
        return "read"

    assert outcome(True) == outcome(False)
