"""Lines printers read differently (`gcodearrays.LINE_RULES`) are refused in one line naming the line number, in
ordinary slicer output (read into arrays) and in indented or numbered output (read line by line) alike."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.errors import InputError
from fabwire.xyz.gcodearrays import LINE_RULES, SEPARATORS, LineRule
from fabwire.xyz.threew import convert_gcode_file

BASE = b"G28\nG1 Z0.2 F1200\nG1 X10 Y10 E1 F1500\n"
TAIL = b"G1 X20 Y20 E2\nM84\n"

MORE: dict[str, list[bytes]] = {
    "a letter given twice in one move": [b"G1 X10 Y10 Y1000 E5", b"G0 Z1 Z900", b"G1 E1 E500", b"G1 X10 x1000 E5",
                                         b"G92 E0 E-100", b"G0 I+5 I0", b"G1 X10 J1 j2 E5", b"G0 R1 R2",
                                         b"G1 X10 S100 S200 E5", b"G1 X10 E5 T0 t1"],
    "a second command word on a line": [b"G1 X10 M400", b"G1 X10 g1 X1000", b"G0 Y5 G 1 Y900", b"G1 X1 G1",
                                        b"G1 X5 G0"],
    "a command subcode on a move, position or unit command (G1.0)": [b"G0.1 X1000", b"G0.5", b"G1. X5", b"G92.1 X0",
                                                                      b"G01.0 X5", b"G3.2 X10 Y10 I5"],
    "inch units (G20)": [b"G020", b"G20 ; inches", b"g20"],
}


def _refused(tmp_path: Path, code: bytes) -> str:
    src = tmp_path / "in.gcode"
    src.write_bytes(code)
    with pytest.raises(InputError) as caught:
        convert_gcode_file(src, tmp_path / "o.3w", "mini w", force=True)
    assert not (tmp_path / "o.3w").exists()
    return str(caught.value)


def test_every_row_names_its_source() -> None:
    assert all(rule.source and rule.reading and rule.advice and rule.example for rule in LINE_RULES)


@pytest.mark.parametrize("layout", ["arrays", "indented", "numbered"])
@pytest.mark.parametrize("rule", LINE_RULES, ids=lambda rule: rule.construct[:40])
def test_each_rule_is_refused_with_its_line(tmp_path: Path, rule: LineRule, layout: str) -> None:
    for example in [rule.example, *MORE.get(rule.construct, [])]:
        code = BASE + example + b"\n" + TAIL
        if layout != "arrays":
            code = b"".join((b"  " if layout == "indented" else b"N%d " % n) + line + b"\n"
                            for n, line in enumerate(code.splitlines(), 1))
        message = _refused(tmp_path, code)
        assert "\n" not in message
        assert message.startswith(f"{tmp_path / 'in.gcode'}: line 4: ")
        reading = "a number with an exponent" if rule is LINE_RULES[0] else rule.reading
        assert reading in message, example


@pytest.mark.parametrize("rule", LINE_RULES, ids=lambda rule: rule.construct[:40])
def test_the_cli_refuses_each_rule_in_one_line(tmp_path: Path, rule: LineRule) -> None:
    src = tmp_path / "in.gcode"
    src.write_bytes(BASE + rule.example + b"\n" + TAIL)
    refused = run_cli("xyz", "convert", "--force", str(src), str(tmp_path / "o.3w"), env=cli_env())
    assert refused.returncode == 4
    assert len(refused.stderr.strip().splitlines()) == 1
    assert ": line 4: " in refused.stderr


SECOND_WORDS = [b"G4 P1 G1 X140 Y140 E5", b"G53 G1 X140 E5", b"M400 G1 X140", b"G90 G1 X140", b"G21 G1 X140",
                b"M83 G1 X140", b"M106 S255 G1 X140", b"g4 p1 g1 x140", b"G4 (wait) G1 X140", b"G28 M84",
                b"M104 S200 M109 S200", b"G92 E0 G1 X140"]
"""A second command word after a command that is not a move, each through every layout and every door."""


@pytest.mark.parametrize("layout", ["arrays", "indented", "numbered"])
@pytest.mark.parametrize("line", SECOND_WORDS, ids=lambda line: line.decode())
@pytest.mark.parametrize("command", ["convert", "info"])
def test_a_second_command_word_after_any_command_is_refused(tmp_path: Path, line: bytes, layout: str,
                                                            command: str) -> None:
    """RepRapFirmware runs both commands of such a line, Marlin only the first: convert and info refuse it,
    with its line, whether the line is read into arrays or line by line (and with the slicer's figures stated)."""
    body = BASE + line + b"\n" + TAIL
    if layout == "indented":
        body = b"".join(b"  " + row + b"\n" for row in body.splitlines())
    elif layout == "numbered":
        body = b"".join(b"N%d " % (i + 1) + row + b"\n" for i, row in enumerate(body.splitlines()))
    src = tmp_path / "in.gcode"
    src.write_bytes(body + b"; estimated printing time (normal mode) = 1h\n"
                    b"; filament used [mm] = 12.5\n; total layers count = 3\n")
    args = ["xyz", "convert", str(src), str(tmp_path / "o.3w")] if command == "convert" else ["xyz", "info", str(src)]
    refused = run_cli(*args, env=cli_env())
    assert refused.returncode == 4, refused.stdout
    assert ": line 4: " in refused.stderr
    assert "second command word" in refused.stderr


@pytest.mark.parametrize("line", [b"G21", b"M862.3 P \"MK3S\"", b"M117 Printing G1 layer", b"G1 X10 Y10 ; G1 X1000",
                                  b"G1 X10 Y10 E1 ; X1000 X2000", b"M204 P500 T1000", b"G28 X Y",
                                  b"; a comment with G20 in it", b"G1 X10 ; \xe2\x80\xa8G1 X1000 E5",
                                  b";\x0c\x0b\xc2\x85 any text", b"M117 Going to G1 X500 next", b"M23 g1x500.gco",
                                  b"M118 G28 done", b"M0 Press G1 to go on", b"M1117 x"])
def test_lines_printers_agree_on_are_kept(tmp_path: Path, line: bytes) -> None:
    src = tmp_path / "in.gcode"
    src.write_bytes(BASE + line + b"\n" + TAIL)
    convert_gcode_file(src, tmp_path / "o.3w", "mini w")


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 200), st.sampled_from(SEPARATORS), st.booleans())
def test_a_separator_anywhere_is_refused_at_its_line(tmp_path_factory: pytest.TempPathFactory, at: int,
                                                     separator: bytes, indented: bool) -> None:
    lines = [b"G1 X%d Y%d E%d" % (10 + k % 50, 10 + k % 7, k) for k in range(200)]
    code = (b"  " if indented else b"") + lines[at % 200]
    lines[at % 200] = code[:4] + separator + code[4:]
    message = _refused(tmp_path_factory.mktemp("sep"), BASE + b"\n".join(lines) + b"\n")
    assert f": line {4 + at % 200}: " in message
