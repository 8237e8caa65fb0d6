"""A coordinate a printer's number reader takes differently from plain decimals (an exponent, NaN, infinity) is
refused with its line, at any place in the file and in any axis or parameter word; the same text in a comment
or a message is left alone."""

from __future__ import annotations

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
    with pytest.raises(InputError, match=rf"line {at + 1}: .* exponent or no number"):
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
