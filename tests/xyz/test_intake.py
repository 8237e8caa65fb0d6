"""What a file is: one intake for convert, info, print and the simulator; G-code text as editors write it."""

from __future__ import annotations

import base64
import io
import json
import re
import struct
import zipfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clitools import run_cli
from fabwire.errors import InputError
from fabwire.xyz import intake
from fabwire.xyz.intake import Kind
from fabwire.xyz.models import MODELS
from fabwire.xyz.threew import convert_gcode_file, read_3w, write_3w

MOVES = b"G28\nG1 Z0.3 F3000\nG0 X5 Y5\nG1 X20 Y10 E2 F1200\nG1 X20 Y20 E3\nM84\n"


def _zip(members: dict[str, bytes]) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return out.getvalue()


def _binary_stl() -> bytes:
    facet = struct.pack("<12fH", *([0.0] * 12), 0)
    return b"binary stl".ljust(80, b" ") + struct.pack("<I", 2) + facet * 2


NOT_GCODE = {
    "binary G-code": (b"GCDE\x01\x00\x00\x00\x01\x00" + bytes(range(64)), Kind.BINARY_GCODE,
                      "turn off Binary G-code in PrusaSlicer"),
    "3MF project": (_zip({"[Content_Types].xml": b"<Types/>", "3D/3dmodel.model": b"<model/>"}), Kind.PROJECT_3MF,
                    "a 3MF project, not G-code: export G-code from the slicer"),
    "zip": (_zip({"part.gcode": MOVES}), Kind.ZIP, "a zip archive"),
    "gzip": (b"\x1f\x8b\x08\x00" + bytes(40), Kind.GZIP, "gzip-compressed"),
    "png": (b"\x89PNG\r\n\x1a\n" + bytes(40), Kind.IMAGE, "an image (PNG)"),
    "jpeg": (b"\xff\xd8\xff\xe0" + bytes(40), Kind.IMAGE, "an image (JPEG)"),
    "pdf": (b"%PDF-1.7\n%\xe2\xe3\n1 0 obj\n", Kind.PDF, "a PDF document"),
    "ascii stl": (b"solid cube\n facet normal 0 0 1\n  outer loop\n", Kind.STL, "slice it to G-code first"),
    "binary stl": (_binary_stl(), Kind.STL, "an STL model"),
    "svg": (b'<?xml version="1.0"?>\n<svg xmlns="http://www.w3.org/2000/svg"/>\n', Kind.XML, "SVG/XML"),
    "utf-16": ("G28\nG1 X1\n".encode("utf-16"), Kind.UTF16, "save the G-code as UTF-8"),
    "junk": (bytes(range(256)) * 4, Kind.BINARY, "binary data"),
    "empty": (b"", Kind.EMPTY, "is empty"),
}


@pytest.mark.parametrize("case", NOT_GCODE, ids=str)
def test_each_kind_is_named_and_refused_with_what_to_do(case: str, tmp_path: Path) -> None:
    data, kind, message = NOT_GCODE[case]
    assert intake.identify(data[:intake.SNIFF], len(data)) is kind
    with pytest.raises(InputError, match=re.escape(message)):
        write_3w(data)
    src = tmp_path / "input.gcode"
    src.write_bytes(data)
    with pytest.raises(InputError, match=re.escape(message)):
        convert_gcode_file(src, tmp_path / "out.3w")
    assert not (tmp_path / "out.3w").exists()


@pytest.mark.parametrize("case", ["binary G-code", "3MF project", "junk"])
def test_convert_and_info_refuse_the_same_kinds_with_exit_4(case: str, tmp_path: Path) -> None:
    data, _kind, message = NOT_GCODE[case]
    src = tmp_path / "model.gcode"
    src.write_bytes(data)
    for args in (("convert", str(src), str(tmp_path / "out.3w")), ("info", str(src))):
        result = run_cli("xyz", *args)
        assert result.returncode == 4, result.stderr
        assert message in result.stderr
        assert "Traceback" not in result.stderr
    assert not (tmp_path / "out.3w").exists()


def _commands(gcode: bytes) -> list[bytes]:
    """The command lines of processed G-code (what the printer executes)."""
    return [line for line in gcode.split(b"\n") if line and not line.startswith(b";")]


SPELLINGS = {
    "lf": lambda text: text,
    "crlf": lambda text: text.replace(b"\n", b"\r\n"),
    "cr": lambda text: text.replace(b"\n", b"\r"),
    "bom": lambda text: intake.BOM + text,
    "bom crlf": lambda text: intake.BOM + text.replace(b"\n", b"\r\n"),
    "no final newline": lambda text: text.rstrip(b"\n"),
    "latin-1 comment": lambda text: b"; Pi\xe8ce d'essai, 20\xb0C\n" + text,
}


@pytest.mark.parametrize("spelling", SPELLINGS, ids=str)
def test_text_as_editors_write_it_gives_the_same_body_and_metadata(spelling: str) -> None:
    source = b";TIME:600\n;LAYER_COUNT:3\n" + MOVES
    reference = read_3w(write_3w(source))
    decoded = read_3w(write_3w(SPELLINGS[spelling](source)))
    assert _commands(decoded.gcode) == _commands(reference.gcode)
    assert intake.BOM not in decoded.gcode
    assert b"\r" not in decoded.gcode
    assert decoded.print_time_s == 600
    assert decoded.layers == 3


@pytest.mark.parametrize(("before", "length", "after"), [
    (b"G28\n", 3 << 20, b"\nG28\n"),  # longer than a read: carried across reads
    (b"G28\nG1 X1\n", (1 << 20) + 10, b"\n"),  # found inside one read
    (b"G28\n" * 1_200_000, 2 << 20, b""),  # after many reads, at the end without a newline
    (b"G28\r\n" * 1000, 3 << 20, b"\r\nG28\r\n"),
])
def test_a_line_over_the_limit_is_named_by_its_number_and_the_limit(tmp_path: Path, before: bytes, length: int,
                                                                     after: bytes) -> None:
    src = tmp_path / "long.gcode"
    src.write_bytes(before + b";" + b"x" * length + after)
    line = before.count(b"\n") + 1
    with pytest.raises(InputError) as caught:
        convert_gcode_file(src, tmp_path / "long.3w")
    assert f"has a line of over {intake.MAX_LINE} bytes, the limit (line {line})" in str(caught.value)


def test_a_line_over_the_limit_is_refused_and_memory_stays_bounded(tmp_path: Path) -> None:
    src = tmp_path / "long.gcode"
    with src.open("wb") as out:
        out.write(b"G28\n;")
        for _ in range(3):
            out.write(b"a" * intake.MAX_LINE)
        out.write(b"\nG1 X1 Y1 E1\n")
    with pytest.raises(InputError, match="has a line of over"):
        convert_gcode_file(src, tmp_path / "long.3w")
    assert not (tmp_path / "long.3w").exists()
    # A line just under the limit, split across the reader's chunks, is still G-code.
    filler = (b";" * 99 + b"\n") * ((intake.CHUNK - 1000) // 100)
    src.write_bytes(b"G28\n" + filler + b";" + b"a" * (intake.MAX_LINE - 100) + b"\nG1 X1 Y1 E1\n")
    convert_gcode_file(src, tmp_path / "fine.3w")
    assert read_3w(tmp_path / "fine.3w").gcode.endswith(b"\nG1 X1 Y1 E1\n")


def test_a_cr_only_file_split_between_chunks_is_read_line_by_line() -> None:
    body = b"".join(b"G1 X%d Y1 E%d\r" % (i % 100, i) for i in range(400_000))
    chunks = list(intake.gcode_lines(io.BytesIO(b"G28\r\n" + body), "x"))
    text = b"".join(chunks)
    assert b"\r" not in text
    assert text.count(b"\n") == 400_001
    assert all(chunk.endswith(b"\n") for chunk in chunks)


def test_base64_text_of_a_3w_and_of_gcode_is_recognised(tmp_path: Path) -> None:
    threew = write_3w(MOVES, "dv1MW0A000")
    wrapped = base64.encodebytes(threew)  # 76-character lines, as MIME tools write it
    assert intake.identify(wrapped) is Kind.THREEW_BASE64
    assert intake.plain_bytes(wrapped, "x") == threew
    gcode = b"; filename = web.gcode\n; machine = dv1MW0A000\n" + MOVES
    encoded = base64.b64encode(gcode)
    assert intake.identify(encoded) is Kind.GCODE_BASE64
    src = tmp_path / "web.3w"
    src.write_bytes(encoded)
    result = run_cli("--json", "xyz", "convert", str(src), str(tmp_path / "out.3w"), "--model", "mini w")
    assert result.returncode == 0, result.stderr
    assert _commands(read_3w(tmp_path / "out.3w").gcode) == _commands(read_3w(write_3w(gcode, "mini w")).gcode)
    info = run_cli("--json", "xyz", "info", str(tmp_path / "out.3w"))
    assert json.loads(info.stdout)["machine"] == "dv1MW0A000"
    src.write_bytes(wrapped[:-7])
    truncated = run_cli("xyz", "info", str(src))
    assert truncated.returncode == 4
    assert "base64" in truncated.stderr


def test_plain_gcode_made_of_base64_letters_is_still_gcode() -> None:
    assert intake.identify(b"G28\nM84\n") is Kind.GCODE
    assert intake.identify(b"G28\nG90\nM104S200\nM109S200\n") is Kind.GCODE


_comment_line = st.text(st.characters(min_codepoint=32, max_codepoint=0x2FF, exclude_characters="\x7f"),
                        max_size=120).map(lambda text: b";" + text.encode("utf-8") + b"\n")


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(
    block_size=st.integers(0, 100_000),
    sample=st.lists(_comment_line, min_size=1, max_size=8),
    bom=st.booleans(),
    line_end=st.sampled_from([b"\n", b"\r\n", b"\r"]),
    final_newline=st.booleans(),
    model=st.sampled_from(MODELS),
)
def test_any_leading_comment_block_converts_for_every_model_and_decodes_to_the_same_commands(
    block_size: int, sample: list[bytes], bom: bool, line_end: bytes, final_newline: bool, model: object,
) -> None:
    block = b""
    while len(block) < block_size:
        block += b"".join(sample)
    text = block[:block_size].rpartition(b"\n")[0] + (b"\n" if block_size else b"") + MOVES
    if not final_newline:
        text = text.rstrip(b"\n")
    data = (intake.BOM if bom else b"") + text.replace(b"\n", line_end)
    decoded = read_3w(write_3w(data, model))  # type: ignore[arg-type]
    assert _commands(decoded.gcode) == _commands(read_3w(write_3w(MOVES, model)).gcode)  # type: ignore[arg-type]
    assert decoded.machine == model.file_id  # type: ignore[attr-defined]
    assert len(decoded.header) < 8192


_BODY_LINES = [b"G0 X1 Y2", b"G00 X3", b"G0X4", b"G01 X5 E1", b"G000 X6", b"G10.5", b"G0\tX7", b"G0", b"G00", b"G10",
               b"G1 X8 Y9 E2", b"; G0 X1 comment", b"", b"M117 G0", b"G28", b"G92 E0", b"  G0 X1", b"N5 G0 X2",
               b"g0 x3", b"G 0 X4", b";LAYER_CHANGE", b"G2 X1 Y1 I1 J0 E3"]


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(lead=st.lists(st.sampled_from([b"; generated by X", b";", b"", b"; filename = a.3w"]), max_size=5),
       lines=st.lists(st.sampled_from(_BODY_LINES), max_size=80), chunk=st.integers(100, 300), keep_arcs=st.booleans())
def test_the_g0_words_the_analysis_found_make_the_same_body(monkeypatch: pytest.MonkeyPatch, lead: list[bytes],
                                                            lines: list[bytes], chunk: int, keep_arcs: bool) -> None:
    """The body written from the G0 words the analysis found is the body written by reading every line again."""
    from dataclasses import replace

    text = b"".join(line + b"\n" for line in [*lead, b"G28", *lines])
    monkeypatch.setattr(intake, "CHUNK", chunk)
    src = io.BytesIO(text)
    prepared = intake.prepare(src, "t", MODELS[0], "t.3w", 8192, None, force=True, keep_arcs=keep_arcs)
    assert prepared.g0_words is not None
    found = b"".join(intake.processed_body(src, "t", prepared, None))
    again = b"".join(intake.processed_body(src, "t", replace(prepared, g0_words=None), None))
    assert found == again
    assert b"\nG0 " not in found
    assert b"\nG00 " not in found
