"""A word value that is not exactly one plain decimal number (`gcodearrays.NUMBER_FORMS`) is refused on a G line
with the line number and the word, by the CLI, in ordinary slicer output (read into arrays), in indented output
(read line by line) and when the slicer's comments state every figure (the lines are only checked); the plain
forms slicers write still convert."""

from __future__ import annotations

import io
import math
import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.errors import InputError, excerpt
from fabwire.xyz import intake
from fabwire.xyz.gcodearrays import EMPTY_VALUE, NUMBER_FORMS, NumberForm, malformed_word

BASE = b"G28\nG1 Z0.2 F1200\nG1 X10 Y10 E1 F1500\n"
TAIL = b"G1 X20 Y20 E2\nM84\n"
STATED = b";TIME:600\n;LAYER_COUNT:3\n;Filament used: 0.25m\n"
"""Comments that state every figure, so `xyz info` reads no move and only checks the lines."""
ROWS = [(form, example) for form in (*NUMBER_FORMS, EMPTY_VALUE) for example in form.examples]


def _id(row: tuple[NumberForm, bytes]) -> str:
    return row[1].decode("utf-8", "replace")


def test_every_row_names_its_source_and_examples() -> None:
    for form in (*NUMBER_FORMS, EMPTY_VALUE):
        assert form.construct
        assert form.reading
        assert form.source
        assert form.examples


@pytest.mark.parametrize("row", ROWS, ids=_id)
def test_each_example_is_named_by_its_own_row(row: tuple[NumberForm, bytes]) -> None:
    form, example = row
    found = malformed_word(b"G1 " + example + b" Y10")
    assert found is not None
    assert found[1] is form
    assert found[0].startswith(example[:1])


@pytest.mark.parametrize("layout", ["arrays", "indented", "stated"])
@pytest.mark.parametrize("row", ROWS, ids=_id)
def test_the_cli_refuses_each_form_with_its_line_and_word(tmp_path: Path, row: tuple[NumberForm, bytes],
                                                          layout: str) -> None:
    form, example = row
    line = b"G1 " + example + b" Y10 E5"
    code = BASE + line + b"\n" + TAIL
    if layout == "indented":
        code = b"".join(b"  " + each + b"\n" for each in code.splitlines())
    head = STATED if layout == "stated" else b""
    src = tmp_path / "in.gcode"
    src.write_bytes(head + code)
    number = 4 + head.count(b"\n")
    out = tmp_path / "out.3w"
    command = ("xyz", "info", str(src)) if layout == "stated" else ("xyz", "convert", str(src), str(out))
    done = run_cli(*command, env=cli_env(tmp_path))
    assert done.returncode == 4, done.stdout + done.stderr
    message = done.stderr.strip()
    assert "\n" not in message
    assert "Traceback" not in message
    assert f"line {number}: " in message
    assert f"({form.construct})" in message
    word = malformed_word(line)
    assert word is not None
    assert excerpt(word[0].decode("utf-8"), 30) in message
    assert not out.exists()


PLAIN = [b"G1 X-0.5 Y+1 Z.5 E-.5 F1.", b"G1 X007.50 Y0010 E00.5", b"G0 X+.5 Y-0", b"G1X10Y10F1500",
         b"G1 X 10 Y\t10 E 5", b"G28 X Y", b"G92 E0", b"G2 X20 Y20 I5 J5 E6", b"G1 X10 ; X-- Ynan in a comment",
         b"G1 X10 (X--1) Y10", b"M117 X-- Y. on the screen", b"G4 P100", b"G1 X10*35"]


@pytest.mark.parametrize("line", PLAIN, ids=lambda line: line.decode())
def test_plain_forms_slicers_write_still_convert(tmp_path: Path, line: bytes) -> None:
    src = tmp_path / "in.gcode"
    src.write_bytes(BASE + line + b"\n" + TAIL)
    done = run_cli("xyz", "convert", str(src), str(tmp_path / "out.3w"), env=cli_env(tmp_path))
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "out.3w").stat().st_size > 0


_PLAIN_WORD = rb"[ \t]*[A-Z][ \t]*([+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+))(?![EX0-9.])"
_PLAIN_CODE = re.compile(rb"G[0-9]+(?:" + _PLAIN_WORD + rb")*[ \t]*", re.IGNORECASE)
"""A move as every firmware reads it alike: words of a letter and one plain decimal number (Marlin valid_float,
without the exponent and hexadecimal that strtod would read)."""
VALUE_TEXT = st.text(alphabet=list("0123456789.+- \teExXnNaAiIfF,_#\u2212\uff11\u00b7Y"), max_size=12)


def _refusal(text: bytes) -> str | None:
    try:
        intake.stream_metadata(io.BytesIO(text), "f")
    except InputError as exc:
        return str(exc)
    return None


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(value=VALUE_TEXT, indented=st.booleans(), command=st.sampled_from([b"G1", b"G0", b"G92"]),
       letter=st.sampled_from([b"X", b"Z", b"E", b"F", b"x"]))
def test_an_accepted_value_is_exactly_one_finite_plain_number(value: str, indented: bool, command: bytes,
                                                              letter: bytes) -> None:
    line = command + b" " + letter + value.encode() + b" Y10"
    text = BASE + (b"  " if indented else b"") + line + b"\n" + TAIL
    refused = _refusal(text)
    if re.fullmatch(r"[ \t]*[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)[ \t]*", value):  # a plain value is never refused as one
        assert refused is None or "plain decimal" not in refused, refused
    if refused is not None:
        return
    found = _PLAIN_CODE.fullmatch(line)
    assert found is not None, line
    for number in re.findall(_PLAIN_WORD, line, re.IGNORECASE):
        assert math.isfinite(float(number))


@pytest.mark.parametrize("eol", [b"\n", b"\r\n", b"\r"], ids=["LF", "CRLF", "CR"])
def test_a_malformed_last_line_after_many_blocks_is_refused_with_its_own_number(tmp_path: Path, eol: bytes) -> None:
    """The last line, without its line break, is checked once whole, and its number counts every line of the
    blocks before it, whatever ends them."""
    from fabwire.xyz.intake import CHUNK

    lines = [b"G28", b"G1 Z0.2 F1200"] + [b"G1 X%d Y10 E%d F1500" % (i % 100, i) for i in range(CHUNK // 12)]
    source = tmp_path / "last.gcode"
    source.write_bytes(eol.join(lines) + eol + b"G1 X--1000 Y10 E5")
    done = run_cli("xyz", "convert", str(source), str(tmp_path / "last.3w"))
    assert done.returncode == 4
    assert f"line {len(lines) + 1}: 'X--1000' is not one plain decimal number" in done.stderr
    assert not (tmp_path / "last.3w").exists()


@pytest.mark.parametrize(("line", "advice"), [
    (b"G1 X5 Y10E1 F1200", "Marlin reads Y10 and E1, a reader using C's strtod one number (10E1 = 100); "
                           "write 'Y10 E1'"),
    (b"G1 X5 Y-1.5E-0.8", "Marlin reads Y-1.5 and E-0.8, a reader that takes E into the number something else; "
                          "write 'Y-1.5 E-0.8'"),
    (b"G1 X5 Y10e1", None),  # lower case: an exponent, not a word
    (b"G1 X1e3 Y10", None),
])
def test_two_words_run_together_are_told_apart_from_an_exponent(tmp_path: Path, line: bytes,
                                                                 advice: str | None) -> None:
    source = tmp_path / "glued.gcode"
    source.write_bytes(b"G28\n" + line + b"\n")
    result = run_cli("xyz", "convert", str(source), str(tmp_path / "glued.3w"), env=cli_env(tmp_path))
    assert result.returncode == InputError.exit_code
    assert result.stderr.count("\n") == 1
    assert "line 2:" in result.stderr
    if advice is None:
        assert "runs two words together" not in result.stderr
    else:
        assert "runs two words together" in result.stderr
        assert result.stderr.rstrip().endswith(advice)


@pytest.mark.parametrize("example", [row.examples[0] for row in NUMBER_FORMS], ids=lambda e: e.decode())
def test_info_of_a_file_whose_slicer_states_its_figures_still_refuses_a_malformed_number(tmp_path: Path,
                                                                                         example: bytes) -> None:
    """The stated figures spare the move analysis, not the check of every line: a malformed word deep in a
    PrusaSlicer file is refused by `xyz info` with its line."""
    moves = b"".join(b"G1 X%d.5 Y%d E0.0%d\n" % (i % 150, (i * 7) % 150, i % 10) for i in range(60_000))
    bad_line = 2 + 60_000 + 1  # the slicer line, G28, the moves
    source = tmp_path / "stated.gcode"
    source.write_bytes(b"; generated by PrusaSlicer 2.6.0+linux-x64-GTK3\nG28\n" + moves + b"G1 " + example + b"\n"
                       + moves + b"; filament used [mm] = 1234.5\n; estimated printing time (normal mode) = 2h 3m\n")
    result = run_cli("xyz", "info", str(source), env=cli_env(tmp_path))
    assert result.returncode == InputError.exit_code, result.stdout
    assert f"line {bad_line}: " in result.stderr, result.stderr
    clean = tmp_path / "clean.gcode"
    clean.write_bytes(source.read_bytes().replace(b"G1 " + example + b"\n", b"G1 X1 Y1\n"))
    assert run_cli("xyz", "info", str(clean), env=cli_env(tmp_path)).returncode == 0
