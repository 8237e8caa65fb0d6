"""The array reading of G-code against straightforward computations written out here, one line at a time."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fabwire.xyz.gcodearrays import PAD, line_count, parse_numbers
from fabwire.xyz.gcodeinfo import MoveAnalyzer

NUMBER = re.compile(rb"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)")


@given(st.binary(max_size=300))
def test_lines_are_counted_as_bytes_count_them(text: bytes) -> None:
    assert line_count(text) == text.count(b"\n")


@settings(max_examples=300, deadline=None)
@given(st.lists(st.text(alphabet="0123456789.+-", max_size=24), min_size=1, max_size=40),
       st.sampled_from([" ", "\n", "E", ";", ""]))
def test_numbers_are_read_as_the_float_parser_reads_them(tokens: list[str], after: str) -> None:
    text = b"\n" + "".join(f"X{token}{after}" for token in tokens).encode() + b"\n"
    at = np.array([m.start() + 1 for m in re.finditer(rb"X", text)], dtype=np.intp)
    parsed = parse_numbers(text, np.frombuffer(text + bytes(PAD), dtype=np.uint8), at)
    for offset, value in zip(at.tolist(), parsed.tolist(), strict=True):
        found = NUMBER.match(text, offset)
        if found is None:
            assert math.isnan(value)
        else:
            expected = float(found.group(0))
            assert value == expected
            assert math.copysign(1.0, value) == math.copysign(1.0, expected)


def reference(text: str) -> tuple[float, float, set[int], float]:
    """(path length over feed in seconds, net filament, heights of flat printing moves in µm, how far printing moves
    rose) of plain G-code, one move at a time in Python floats."""
    pos, e, feed = [0.0, 0.0, 0.0], 0.0, 1500.0
    absolute, absolute_e = True, True
    seconds = filament = rise = 0.0
    heights: set[int] = set()
    for line in text.splitlines():
        command, *words = line.split(";")[0].split() or [""]
        given = {word[0]: float(word[1:]) for word in reversed(words)}  # the first of a letter wins
        if command in ("G0", "G1"):
            target = list(pos)
            for k, axis in enumerate("XYZ"):
                if axis in given:
                    target[k] = given[axis] if absolute else pos[k] + given[axis]
            new_e = e
            if "E" in given:
                new_e = given["E"] if absolute_e else e + given["E"]
            if given.get("F", 0.0) > 0:
                feed = given["F"]
            delta = [t - p for t, p in zip(target, pos, strict=True)]
            length = math.sqrt(sum(d * d for d in delta)) or abs(new_e - e)
            seconds += length * 60.0 / feed
            filament += new_e - e
            if new_e > e and (delta[0] or delta[1]):
                if delta[2]:
                    rise += max(0.0, delta[2])
                else:
                    heights.add(round(target[2] * 1000))
            pos, e = target, new_e
        elif command == "G92":
            for k, axis in enumerate("XYZ"):
                pos[k] = given.get(axis, pos[k])
            e = given.get("E", e)
        elif command in ("G90", "G91"):
            absolute = absolute_e = command == "G90"
        elif command in ("M82", "M83"):
            absolute_e = command == "M82"
    return seconds, filament, heights, rise


def coordinate(places: int = 5) -> st.SearchStrategy[str]:
    return st.builds(lambda v, d: f"{v:.{d}f}", st.floats(-300, 300, allow_nan=False), st.integers(0, places))


@st.composite
def program(draw: st.DrawFn) -> str:
    """Slicer-like G-code: moves with any of X Y Z E F, position resets, mode switches, comments."""
    lines = []
    for _ in range(draw(st.integers(1, 30))):
        kind = draw(st.sampled_from(["move"] * 6 + ["set", "mode", "comment"]))
        if kind == "move":
            letters = draw(st.lists(st.sampled_from("XYZEF"), unique=True, max_size=5))
            # Z to the micrometre, as layer heights are counted: a relative Z sum that lands on half a micrometre
            # rounds either way depending on the order the floats are added in, which says nothing about layers
            words = [a + draw(st.integers(1, 9000).map(str) if a == "F" else coordinate(3 if a == "Z" else 5))
                     for a in letters]
            line = " ".join([draw(st.sampled_from(["G0", "G1"])), *words])
            if draw(st.booleans()):
                line += draw(st.sampled_from([" ; X9 E9", ";G92 E0"]))
        elif kind == "set":
            letters = draw(st.lists(st.sampled_from("XYZE"), unique=True, min_size=1, max_size=4))
            line = " ".join(["G92", *(a + draw(coordinate(3 if a == "Z" else 5)) for a in letters)])
        elif kind == "mode":
            line = draw(st.sampled_from(["G90", "G91", "M82", "M83"]))
        else:
            line = draw(st.sampled_from([";LAYER_CHANGE", ";Z:0.4", "; E5 X9 Y2", "M104 S200", "M106 S255"]))
        lines.append(line + "\n")
    return "".join(lines)


@settings(max_examples=200, deadline=None)
@given(program())
def test_moves_add_up_as_a_line_by_line_computation_says(text: str) -> None:
    analyzer = MoveAnalyzer()
    analyzer.feed_chunk(text.encode())
    seconds, filament, heights, rise = reference(text)
    assert analyzer.path_seconds == pytest.approx(seconds, rel=1e-9, abs=1e-9)
    assert analyzer.vase_rise == pytest.approx(rise, rel=1e-9, abs=1e-9)
    assert analyzer.filament == pytest.approx(filament, rel=1e-9, abs=1e-9)
    assert analyzer.layer_heights == heights


@pytest.mark.parametrize("run", [1, 7, 8, 9, 10, 50, 300_000])
def test_a_long_run_of_blanks_reads_as_one_blank(run: int) -> None:
    """Blanks between a letter and its number and between words, however many, read the same words; past the
    first few bytes a run is skipped by one match, not a byte at a time."""
    from fabwire.xyz import gcodearrays

    def words(line: bytes) -> list[tuple[list[int], list[float]]]:
        found = gcodearrays.scan(b"\n" + line * 3 + bytes(gcodearrays.PAD))
        assert found is not None
        return [(axis.lines.tolist(), axis.values.tolist()) for axis in found.axes]

    spaced = b"G1 X" + b" " * run + b"40" + b" " * run + b"Y-4.5" + b"\t" * run + b"E1 F" + b" \t" * run + b"600\n"
    assert words(spaced) == words(b"G1 X40 Y-4.5 E1 F600\n")
