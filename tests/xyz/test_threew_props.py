from __future__ import annotations

import re

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from fabwire.errors import InputError
from fabwire.xyz import intake
from fabwire.xyz.threew import read_3w, write_3w

XYZ_KEYS = re.compile(
    rb"^[ \t]*;[ \t]*(?:filename|print_time|machine|facets|total_layers|version|total_filament)[ \t]*="
)
G0_WORD = re.compile(rb"^([ \t]*(?:[Nn][0-9]+[ \t]*)?[Gg][ \t]*0?)0(?![0-9.])")
ARC = re.compile(rb"^[ \t]*(?:[Nn][0-9]+[ \t]*)?[Gg][ \t]*0*[23](?![0-9.])(.*)$", re.DOTALL)
"""A G2/G3 line: without I, J or R it is written as `G1` and its words (`arcwork`), with them as segments."""


def _as_written(line: bytes) -> bytes:
    arc = ARC.match(line)
    if arc is None:
        return G0_WORD.sub(rb"\g<1>1", line)
    assume(not re.search(rb"[IiJjRr]", arc.group(1).partition(b";")[0]))  # segments: see test_arcs
    return b"G1" + arc.group(1)


def expected_body(text: bytes) -> bytes | None:
    """What follows the seven generated header lines, worked out line by line; None if nothing is printable (no
    command, not G-code text at all: control characters, another kind of file, or a NUL inside the G-code; NULs
    that pad its end are dropped)."""
    text = text.removeprefix(intake.BOM)
    if intake.identify(text) is not intake.Kind.GCODE or not intake.has_commands(text.replace(b"\r", b"")):
        return None
    text = text.rstrip(b"\0")
    if b"\0" in text:
        return None
    lines = text.split(b"\n")
    if lines[-1] == b"":
        lines.pop()
    lines = [line.removesuffix(b"\r") for line in lines]
    code = [i for i, line in enumerate(lines) if line.strip(b" \t\r") and not line.lstrip(b" \t").startswith(b";")]
    if not code:
        return None
    first = code[0]
    header = [line for line in lines[:first] if not XYZ_KEYS.match(line)]
    rest = [_as_written(line) for line in lines[first:]]
    return b"".join(line + b"\n" for line in header + rest)


gcode_line = st.one_of(
    st.sampled_from(["G0 X1 Y2", "G00 X5", "G01 Y1", "G1 X1 E0.5 F1200", "  G0 X3", "N5 G0 Z1", "g0 x1", "G0",
                     "G 0 X1", "G\t00",
                     "; G0 in a comment", ";TIME:42", "; print_time = 7", ";LAYER_COUNT:3", "M82", "G92 E0", "",
                     "G0X1", "G04 P1", "G10.5", "M117 G0"]),
    st.text(st.characters(codec="utf-8", exclude_characters="\n\r\x0b\x0c\x1c\x1d\x1e\x1f\x85\u2028\u2029"),
            max_size=40),
)
gcode_text = st.builds(
    lambda lines, newline, final: newline.join(lines) + (newline if final else ""),
    st.lists(gcode_line, max_size=40), st.sampled_from(["\n", "\r\n"]), st.booleans(),
)


@settings(max_examples=300, deadline=None)
@given(gcode_text, st.sampled_from(["dv1MX0A000", "dv1JP0A000", "dvF100B000"]))
def test_any_gcode_text_round_trips(text: str, model: str) -> None:
    data = text.encode()
    expected = expected_body(data)
    if expected is None:
        with pytest.raises(InputError):
            write_3w(data, model)
        return
    info = read_3w(write_3w(data, model))
    assert info.crc_ok
    lines = info.gcode.split(b"\n", 7)
    assert [line.split(b" = ")[0] for line in lines[:7]] == [
        b"; filename", b"; print_time", b"; machine", b"; facets", b"; total_layers", b"; version", b"; total_filament"]
    assert lines[7] == expected
    assert read_3w(write_3w(info.gcode, model)).gcode == info.gcode
