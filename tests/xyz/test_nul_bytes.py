"""NUL bytes in G-code, one rule at every offset: padding at the end is dropped with a note; a NUL inside the
G-code is refused with its line number, or with --repair dropped and reported."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.errors import InputError
from fabwire.xyz import intake
from fabwire.xyz.threew import convert_gcode_file, read_3w

LINES = [b"G28\n", b"G1 Z0.3 F600\n"] + [b"G1 X%d Y%d E%d F1200\n" % (i % 90, i % 13, i) for i in range(6000)]
TEXT = b"".join(LINES)


def _line_of(offset: int) -> int:
    return TEXT.count(b"\n", 0, offset) + 1


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(offset=st.integers(1, len(TEXT) - 2), run=st.integers(1, 40))
def test_a_nul_inside_is_refused_with_its_line_at_any_offset(tmp_path: Path, offset: int, run: int) -> None:
    (tmp_path / "out.3w").unlink(missing_ok=True)  # examples share the folder
    src = tmp_path / "nul.gcode"
    src.write_bytes(TEXT[:offset] + bytes(run) + TEXT[offset:])
    with pytest.raises(InputError, match=rf"NUL byte inside its G-code on line {_line_of(offset)} "):
        convert_gcode_file(src, tmp_path / "out.3w")
    with pytest.raises(InputError, match=rf"on line {_line_of(offset)} "):
        intake.gcode_metadata(src)
    assert not (tmp_path / "out.3w").exists()
    repaired = convert_gcode_file(src, tmp_path / "out.3w", repair=True)
    assert repaired.notes[-1] == f"NUL bytes dropped from line {_line_of(offset)}"
    assert b"\0" not in read_3w(tmp_path / "out.3w").gcode


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(1, len(LINES)), padding=st.sampled_from([1, 15, 512, 3000, 65_536, 200_000]))
def test_padding_at_the_end_is_dropped_at_any_length(tmp_path: Path, cut: int, padding: int) -> None:
    text = b"".join(LINES[:cut])
    src = tmp_path / "padded.gcode"
    src.write_bytes(text + bytes(padding))
    info = convert_gcode_file(src, tmp_path / "out.3w")
    assert info.notes[-1].endswith(f"the {padding} NUL bytes that pad its end were dropped")
    clean = tmp_path / "clean.gcode"
    clean.write_bytes(text)
    (tmp_path / "clean").mkdir(exist_ok=True)
    convert_gcode_file(clean, tmp_path / "clean" / "out.3w")
    assert read_3w(tmp_path / "out.3w").gcode == read_3w(tmp_path / "clean" / "out.3w").gcode


def test_nul_past_the_first_chunk(tmp_path: Path) -> None:
    big = TEXT * (intake.CHUNK // len(TEXT) + 2)
    offset = big.index(b"\n", intake.CHUNK + 1000) - 2
    src = tmp_path / "big.gcode"
    src.write_bytes(big[:offset] + b"\0" + big[offset:])
    line = big.count(b"\n", 0, offset) + 1
    with pytest.raises(InputError, match=rf"on line {line} "):
        intake.gcode_metadata(src)


def test_cli_padding_note_and_inside_refusal(tmp_path: Path) -> None:
    padded = tmp_path / "padded.gcode"
    padded.write_bytes(b";TIME:600\n;Filament used: 0.5m\nG28\nG1 X10 Y10 E1 F1200\n" + bytes(3000))
    done = run_cli("--json", "xyz", "convert", str(padded), str(tmp_path / "p.3w"), env=cli_env())
    assert done.returncode == 0, done.stderr
    assert "3000 NUL bytes that pad its end were dropped" in done.stderr
    assert any("NUL" in note for note in json.loads(done.stdout)["notes"])
    inside = tmp_path / "inside.gcode"
    inside.write_bytes(b"G28\nG1 X10\0 Y10 E1 F1200\nG1 X20\n")
    refused = run_cli("xyz", "convert", str(inside), str(tmp_path / "i.3w"), env=cli_env())
    assert refused.returncode == 4
    assert refused.stderr.strip().splitlines() == [
        f"fabwire: error: {inside} has a NUL byte inside its G-code on line 2 (a printer stalls on it); "
        "`fabwire xyz convert --repair` drops such bytes"]
    repaired = run_cli("xyz", "convert", "--repair", str(inside), str(tmp_path / "i.3w"), env=cli_env())
    assert repaired.returncode == 0, repaired.stderr
    assert "NUL bytes dropped from line 2" in repaired.stderr
    assert b"G1 X10 Y10 E1 F1200" in read_3w(tmp_path / "i.3w").gcode


def test_only_nuls_is_still_binary_data() -> None:
    assert intake.identify(bytes(5000), 5000) is intake.Kind.BINARY
    assert intake.identify("G28\nG1 X1 Y2 Z3\n".encode("utf-16-le") * 40, 1280) is intake.Kind.BINARY
