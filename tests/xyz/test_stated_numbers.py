"""Numbers that .3w headers and slicer comments state are outside input: any text there gives a known value or
none, never an exception the caller does not expect (the CLI's internal error, a simulator's dead handler)."""

from __future__ import annotations

import math
from io import BytesIO
from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import run_cli
from fabwire.xyz.gcodeinfo import header_metadata
from fabwire.xyz.personas import personality
from fabwire.xyz.printer import Printer
from fabwire.xyz.threew import BODY_OFFSET, TAG_ECB, _encrypt_ecb, _preamble, _stored_header, read_3w

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
