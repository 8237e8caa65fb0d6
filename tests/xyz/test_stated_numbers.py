"""What .3w files and slicer comments state is outside input: any bytes there give a known value, none, or the
one-line refusal for bad input, never an exception the caller does not expect (the CLI's internal error, a
simulator's dead handler)."""

from __future__ import annotations

import contextlib
import math
from io import BytesIO
from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import run_cli
from fabwire.errors import InputError
from fabwire.xyz.gcodeinfo import header_metadata
from fabwire.xyz.personas import personality
from fabwire.xyz.printer import Printer
from fabwire.xyz.threew import (
    BODY_OFFSET,
    TAG_ECB,
    ZIP_CIPHER_PIECE,
    ZIP_PIECE,
    _cbc128,
    _encrypt_ecb,
    _pkcs7,
    _preamble,
    _stored_header,
    _unpad,
    read_3w,
    write_3w,
)

FILE_ID = "dv1MX0A000"
stated = st.one_of(
    st.sampled_from(["inf", "-inf", "nan", "1e999", "-1e999", "1.2.3", ".", "-", "1" * 400, "0x10", "1_000", "٣"]),
    st.text(alphabet="0123456789.e+-_ xinfa", max_size=30),
)


def threew_stating(print_time: str, filament: str, layers: str) -> bytes:
    """A .3w whose header and body carry these values as XYZprint writes its keys."""
    header = (f"; filename = part.3w\n; print_time = {print_time}\n; machine = {FILE_ID}\n; facets = 50\n"
              f"; total_layers = {layers}\n; version = 18020109\n; total_filament = {filament}\n").encode()
    out = BytesIO()
    out.seek(BODY_OFFSET)
    crc, _size, _plain = _encrypt_ecb(iter([header + b"G28\nG1 X10 Y10 E1 F1200\n"]), out)
    out.seek(0)
    out.write(_preamble(2, TAG_ECB, _stored_header(2, header), crc))
    return out.getvalue()


def known(value: float | None) -> bool:
    return value is None or math.isfinite(value)


@settings(max_examples=150, deadline=None)
@given(stated, stated, stated)
def test_header_numbers_are_finite_or_unknown(print_time: str, filament: str, layers: str) -> None:
    data = threew_stating(print_time, filament, layers)
    info = read_3w(data)
    assert known(info.print_time_s)
    assert known(info.filament_mm)
    assert known(info.layers)
    verdict = Printer(personality(FILE_ID)).check_file(data)
    assert verdict.ok
    assert math.isfinite(verdict.print_time)
    assert math.isfinite(verdict.filament_mm)


@settings(max_examples=300, deadline=None)
@given(st.sampled_from([
    "; estimated printing time (normal mode) = {}", ";   Build time: {}", ";TIME:{}", "; print_time = {}",
    "; filament used [mm] = {}", ";Filament used: {}", ";   Filament length: {} mm", "; total_layers = {}",
    ";LAYER_COUNT:{}", "; facets = {}",
]), st.lists(st.sampled_from(["1", "25", "2.5", ".", "..", "1.2.3", "9" * 400, "h", "m", "s", "d", " ", "hours",
                                "min", "sec", ",", ":", "e9", "-", "+", "m,"]), max_size=10).map("".join))
def test_slicer_comments_give_numbers_or_nothing(template: str, value: str) -> None:
    meta = header_metadata(template.format(value).encode() + b"\nG28\n", b"")
    assert all(known(v) for v in (meta.print_time_s, meta.filament_mm, meta.layers, meta.facets))


def test_info_and_convert_take_unreadable_durations(tmp_path: Path) -> None:
    folder = tmp_path
    for n, comment in enumerate(["; estimated printing time (normal mode) = 1.2.3h", ";   Build time: . hours"]):
        src = folder / f"part{n}.gcode"
        src.write_bytes(b"G28\nG1 Z0.2 F600\nG1 X10 Y10 E1\n" + comment.encode() + b"\n")
        shown = run_cli("xyz", "info", str(src))
        assert shown.returncode == 0, shown.stderr
        done = run_cli("xyz", "convert", str(src), str(folder / f"part{n}.3w"))
        assert done.returncode == 0, done.stderr
    (folder / "odd.3w").write_bytes(threew_stating("inf", "nan", "1e999"))
    shown = run_cli("xyz", "info", str(folder / "odd.3w"))
    assert shown.returncode == 0, shown.stderr
    assert "print time" in shown.stdout


def _zipped_parts() -> tuple[bytes, bytes]:
    """(the first 0x2000 bytes, the zip archive) of a zipped .3w."""
    made = write_3w(b"G28\n" + b"".join(b"G1 X%d Y%d E%d\n" % (i % 150, i % 7, i) for i in range(2000)), "dvF100B000")
    body = made[BODY_OFFSET:]
    pieces = [body[i:i + ZIP_CIPHER_PIECE] for i in range(0, len(body), ZIP_CIPHER_PIECE)]
    return made[:BODY_OFFSET], b"".join(_unpad(_cbc128(piece, decrypt=True))[0] for piece in pieces)


PREAMBLE, ARCHIVE = _zipped_parts()


END_RECORD = ARCHIVE.rindex(b"PK\x05\x06")
"""Where the archive's end record starts: its sizes and offsets are what a damaged archive gets wrong."""


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.one_of(st.integers(0, len(ARCHIVE) - 1), st.integers(END_RECORD, len(ARCHIVE) - 1)),
                          st.binary(min_size=1, max_size=4)), min_size=1, max_size=4),
       st.integers(4, len(ARCHIVE)))
def test_a_damaged_zip_inside_a_3w_is_bad_input(changes: list[tuple[int, bytes]], keep: int) -> None:
    """The archive itself damaged (then encrypted as the format wants), so the zip reader meets hostile offsets,
    lengths and truncation, not only blocks that fail to decrypt."""
    archive = bytearray(ARCHIVE[:keep])
    for at, value in changes:
        archive[at:at + len(value)] = value[:max(0, len(archive) - at)]
    archive[:4] = b"PK\x03\x04"
    body = b"".join(_cbc128(_pkcs7(bytes(archive[i:i + ZIP_PIECE]))) for i in range(0, len(archive), ZIP_PIECE))
    with contextlib.suppress(InputError):  # anything else fails the test
        read_3w(PREAMBLE + body)
