from __future__ import annotations

import hashlib
import io
import os
import stat
import zipfile
import zlib
from pathlib import Path

import pytest
from cryptography.hazmat.primitives.ciphers import Cipher, algorithms, modes

from fabwire.errors import InputError
from fabwire.xyz.models import MODELS, FileFormat, PrinterModel, find_model
from fabwire.xyz.threew import (
    convert_3w_to_gcode,
    convert_gcode_file,
    inspect_3w,
    is_3w,
    read_3w,
    write_3w,
)

DATA = Path(__file__).parent / "data" / "threew"
TV_INPUT = (DATA / "tv_input.gcode").read_bytes()
TV_PROCESSED = (
    b"; filename = temp.3w\n; print_time = 600\n; machine = dv1MX0A000\n; facets = 50\n; total_layers = 3\n"
    b"; version = 18020109\n; total_filament = 250.00\n;TIME:600\n;LAYER_COUNT:3\n;Filament used: 0.25m\n"
    b"G28\nG1 X10 Y10\nG1 X20 Y20 E1\nM84\n"
)
KEY_256 = b"@xyzprinting.com@xyzprinting.com"
KEY_128 = b"@xyzprinting.com"


def sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def ecb(data: bytes, *, decrypt: bool = False) -> bytes:
    cipher = Cipher(algorithms.AES(KEY_256), modes.ECB())
    ctx = cipher.decryptor() if decrypt else cipher.encryptor()
    return ctx.update(data) + ctx.finalize()


def cbc(data: bytes, *, decrypt: bool = False) -> bytes:
    cipher = Cipher(algorithms.AES(KEY_128), modes.CBC(bytes(16)))
    ctx = cipher.decryptor() if decrypt else cipher.encryptor()
    return ctx.update(data) + ctx.finalize()


def pad(data: bytes) -> bytes:
    n = 16 - len(data) % 16
    return data + bytes([n]) * n


def u32(data: bytes, at: int) -> int:
    return int.from_bytes(data[at:at + 4], "big")


def official_layout(gcode: bytes, header: bytes, *, body: bytes | None = None) -> bytes:
    """A v5 file as XYZprint lays it out: 8-byte gap, exact header length, offset 68, header at 0x70, unpadded."""
    body = ecb(pad(gcode)) if body is None else body
    out = bytearray(b"3DPFNKG13WTW" + bytes([1, 5, 0, 0]) + (8).to_bytes(4, "big") + bytes(8) + b"TagEJ256")
    out += len(header).to_bytes(4, "big") + (68).to_bytes(4, "big") + (1).to_bytes(4, "big")
    out += zlib.crc32(body).to_bytes(4, "big")
    assert len(out) == 0x34
    out += bytes(0x70 - len(out)) + header
    out += bytes(0x2000 - len(out))
    return bytes(out) + body


# ---------------------------------------------------------------------------------------------------- test vectors


def test_tv1_minimaker_v2_byte_for_byte() -> None:
    assert sha(TV_INPUT) == "683c20c65c1480f8c05f4747b020a32abf0d96eaf6e68dcaa74401f5ce196a04"
    out = write_3w(TV_INPUT, "dv1MX0A000")
    assert len(out) == 8416
    assert sha(out) == "364ee1c26fe305e606eec020f7a01b2271b5b9d7c1017f45fc44ec0eb0b24fd4"
    assert out == (DATA / "tv1_minimaker_v2.3w").read_bytes()
    assert out[4716:4720] == bytes.fromhex("49b4a4a3")
    assert out[4784:4808] == bytes.fromhex("ca8eda42982ff85e072bc8813957079451dfdedd0c56bd36")
    assert out[8192:8224] == bytes.fromhex("f24365bdec27b2d4fae9f41b72f3c1bee9121b23f108b737980325a602458a6e")
    assert out[4704:4712] == b"TagEJ256"
    assert u32(out, 4712) == 68


def test_tv2_jr_pro_v5_byte_for_byte() -> None:
    out = write_3w(TV_INPUT, find_model("dv1JP0A000"))
    assert len(out) == 8416
    assert sha(out) == "672e7a4210c962209bbcbcdcf00ffbc4f7efdaec54a29352244eca694fb531db"
    assert out == (DATA / "tv2_jr_pro_v5.3w").read_bytes()
    assert (u32(out, 4712), u32(out, 4716), u32(out, 4720)) == (192, 80, 1)
    header = TV_PROCESSED[:190].replace(b"dv1MX0A000", b"dv1JP0A000")
    assert out[4800:4992] == header + b"\x02\x02"
    assert u32(out, 4724) == zlib.crc32(out[8192:])


def test_tv1_decodes_to_the_processed_buffer() -> None:
    info = read_3w(DATA / "tv1_minimaker_v2.3w")
    assert info.gcode == TV_PROCESSED
    assert (info.container, info.tag, info.zipped, info.header_encrypted, info.body_encrypted) == (
        2, "TagEJ256", False, True, True)
    assert info.crc_ok
    assert info.crc_stored == 0x49B4A4A3
    assert info.pad_ok
    assert info.header == TV_PROCESSED[:190]
    assert info.model is find_model("miniMaker")
    assert (info.print_time_s, info.layers, info.filament_mm, info.machine) == (600, 3, 250.0, "dv1MX0A000")
    assert info.fields["version"] == "18020109"
    assert info.header_offset == 4784
    assert info.gap == 4684


def test_tv2_decodes_with_plaintext_header() -> None:
    info = read_3w((DATA / "tv2_jr_pro_v5.3w").read_bytes())
    assert info.gcode == TV_PROCESSED.replace(b"dv1MX0A000", b"dv1JP0A000")
    assert info.container == 5
    assert not info.header_encrypted
    assert info.crc_ok
    assert info.model is find_model("Jr 1.0 Pro")
    assert info.header_offset == 4800


def test_zip_variant_layout_and_round_trip() -> None:
    out = write_3w(TV_INPUT, "daVinci 1.0")
    assert out[:16] == b"3DPFNKG13WTW\x01\x02\x00\x00"
    assert out[4704:4712] == b"TagEa128"
    body = out[8192:]
    assert u32(out, 4716) == zlib.crc32(body)
    archive = zipfile.ZipFile(io.BytesIO(unpad(cbc(body, decrypt=True))))
    assert archive.namelist() == ["sample.gcode"]
    assert archive.read("sample.gcode") == TV_PROCESSED.replace(b"dv1MX0A000", b"daVinciF10")
    info = read_3w(out)
    assert info.zipped
    assert info.tag == "TagEa128"
    assert info.crc_ok
    assert info.gcode == TV_PROCESSED.replace(b"dv1MX0A000", b"daVinciF10")


def unpad(data: bytes) -> bytes:
    return data[:-data[-1]]


def incompressible_gcode(size: int, seed: int = 1) -> bytes:
    """G-code whose deflated size stays close to its own size (so zipped bodies span several pieces)."""
    import random

    rnd = random.Random(seed)
    lines = [b"G28\n"]
    total = 4
    while total < size:
        line = f"G1 X{rnd.uniform(0, 150):.5f} Y{rnd.uniform(0, 150):.5f} E{rnd.uniform(0, 9):.5f}\n".encode()
        lines.append(line)
        total += len(line)
    return b"".join(lines)[:size].rsplit(b"\n", 1)[0] + b"\n"


@pytest.mark.parametrize("size", [8192 * 6 - 1, 8192 * 9, 8192 * 15 + 7, 200_000])
def test_zip_bodies_spanning_several_pieces(size: int) -> None:
    gcode = incompressible_gcode(size)
    out = write_3w(gcode, "dvF200B000")
    body = out[8192:]
    pieces = [body[i:i + 0x2010] for i in range(0, len(body), 0x2010)]
    assert len(pieces) > 1
    assert all(len(p) == 0x2010 for p in pieces[:-1])
    joined = b"".join(unpad(cbc(p, decrypt=True)) for p in pieces)
    assert all(len(unpad(cbc(p, decrypt=True))) == 0x2000 for p in pieces[:-1])
    assert zipfile.ZipFile(io.BytesIO(joined)).read("sample.gcode") == read_3w(out).gcode
    assert read_3w(out).gcode.endswith(gcode.split(b"\n", 1)[1])


# ---------------------------------------------------------------------------------------------------- other layouts


def test_official_compact_layout_with_crlf_header() -> None:
    header = b"; filename = 1.3w\r\n; print_time = 2351\r\n; machine = dv1NX0A000\r\n; total_layers = 90\r\n"
    gcode = header + b"G21\r\nG90\r\nG1 X1 Y1\r\n"
    data = official_layout(gcode, header)
    assert data[0x1C:0x24] == b"TagEJ256"
    info = read_3w(data)
    assert info.gcode == gcode
    assert info.header == header
    assert not info.header_encrypted
    assert (info.container, info.gap, info.header_offset) == (5, 8, 0x70)
    assert info.print_time_s == 2351
    assert info.layers == 90
    assert info.model is find_model("nano")
    assert info.crc_ok


def test_plaintext_v2_header_and_plaintext_body() -> None:
    gcode = b"; machine = dv1MW0A000\nG28\nG1 X5\n"
    out = bytearray(write_3w(gcode, "mini w"))
    header = b"; machine = dv1MW0A000\n"
    out[4784:8192] = header + bytes(8192 - 4784 - len(header))
    body = b";plain body\nG28\n"
    out = out[:8192] + body
    out[4716:4720] = zlib.crc32(body).to_bytes(4, "big")
    info = read_3w(bytes(out))
    assert not info.header_encrypted
    assert not info.body_encrypted
    assert info.header == header
    assert info.gcode == body
    assert info.crc_ok


def test_missing_final_pad_is_tolerated() -> None:
    processed = b"; machine = dv1MX0A000\nG28\n"
    processed += b";" * (15 - len(processed) % 16) + b"\n"
    assert len(processed) % 16 == 0
    data = official_layout(processed, b"; machine = dv1MX0A000\n", body=ecb(processed))
    info = read_3w(data)
    assert info.gcode == processed
    assert not info.pad_ok
    assert info.crc_ok


def test_crc_mismatch_is_reported_not_raised(tmp_path: Path) -> None:
    data = bytearray((DATA / "tv1_minimaker_v2.3w").read_bytes())
    data[4716] ^= 0xFF
    info = read_3w(bytes(data))
    assert not info.crc_ok
    assert info.crc_computed == 0x49B4A4A3
    assert info.crc_stored == 0x49B4A4A3 ^ 0xFF000000
    assert info.gcode == TV_PROCESSED
    src = tmp_path / "bad.3w"
    src.write_bytes(bytes(data))
    assert not convert_3w_to_gcode(src, tmp_path / "out.gcode").crc_ok
    assert (tmp_path / "out.gcode").read_bytes() == TV_PROCESSED


# ---------------------------------------------------------------------------------------------------- round trips


def processed_for(gcode: bytes, model_file_id: str) -> bytes:
    return read_3w(write_3w(gcode, model_file_id)).gcode


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.model_number)
def test_round_trip_for_every_model(model: PrinterModel, tmp_path: Path) -> None:
    gcode = b";FLAVOR:Marlin\r\n;TIME:61\r\nG28\r\nG0 X1 Y2\r\nG1 X3 Y4 E0.5 ; a G0 in a comment\r\nM84\r\n"
    src = tmp_path / "part.gcode"
    src.write_bytes(gcode)
    info = convert_gcode_file(src, tmp_path / "part.3w", model)
    assert info.container == model.container
    assert info.zipped == model.zipped
    decoded = read_3w(tmp_path / "part.3w")
    assert decoded.crc_ok
    assert decoded.machine == model.file_id
    assert decoded.container == model.container
    assert decoded.zipped == model.zipped
    assert decoded.header_encrypted == (model.file_format is not FileFormat.V5)
    assert decoded.fields["filename"] == "part.3w"
    assert decoded.gcode.endswith(b";FLAVOR:Marlin\n;TIME:61\nG28\nG1 X1 Y2\nG1 X3 Y4 E0.5 ; a G0 in a comment\nM84\n")
    assert decoded.header == decoded.gcode[:decoded.gcode.index(b"G28")]
    back = convert_3w_to_gcode(tmp_path / "part.3w", tmp_path / "back.gcode")
    assert (tmp_path / "back.gcode").read_bytes() == decoded.gcode
    assert back.gcode_size == len(decoded.gcode)
    # A second conversion of the decoded G-code gives the same file.
    assert convert_gcode_file(tmp_path / "back.gcode", tmp_path / "part.3w", model).crc_computed == info.crc_computed


def lengths_around(multiple: int, count: int) -> list[int]:
    return sorted({n for k in range(1, count + 1) for n in (k * multiple - 1, k * multiple, k * multiple + 1)})


@pytest.mark.parametrize("extra", range(16))
def test_every_length_modulo_16_gets_a_full_pad(extra: int) -> None:
    gcode = b"G28\n;" + b"x" * extra + b"\n"
    out = write_3w(gcode, "dv1MX0A000")
    processed = read_3w(out).gcode
    body = out[8192:]
    assert len(body) == (len(processed) // 16 + 1) * 16
    plain = ecb(body, decrypt=True)
    assert plain[len(processed):] == bytes([len(body) - len(processed)]) * (len(body) - len(processed))
    header = processed[:processed.index(b"G28")]
    v5 = write_3w(gcode, "dv1JP0A000")
    assert u32(v5, 4712) == (len(header) // 16 + 1) * 16


def exact_gcode(size: int) -> bytes:
    """G-code of exactly `size` bytes (LF), ending in a comment line that takes up the slack."""
    base = incompressible_gcode(max(size - 8, 0), seed=size)
    slack = size - len(base)
    assert slack >= 1
    return base + (b";" + b"x" * (slack - 2) + b"\n" if slack >= 2 else b"\n")


@pytest.mark.parametrize("size", lengths_around(16, 6) + lengths_around(8192, 3))
@pytest.mark.parametrize("model", ["dv1MX0A000", "dv1JP0A000", "dvF100B000"])
@pytest.mark.parametrize("newline", [b"\n", b"\r\n"])
def test_round_trip_at_block_and_chunk_boundaries(size: int, model: str, newline: bytes) -> None:
    assert len(exact_gcode(size)) == size
    gcode = exact_gcode(size).replace(b"\n", newline)
    info = read_3w(write_3w(gcode, model))
    assert info.crc_ok
    assert info.pad_ok
    assert info.gcode.endswith(gcode.replace(b"\r\n", b"\n"))
    lf = read_3w(write_3w(gcode.replace(b"\r\n", b"\n"), model))
    assert lf.gcode == info.gcode


def test_crlf_and_lf_inputs_give_identical_files() -> None:
    assert write_3w(TV_INPUT.replace(b"\n", b"\r\n"), "mini w") == write_3w(TV_INPUT, "mini w")


def test_input_without_final_newline() -> None:
    assert read_3w(write_3w(TV_INPUT[:-1])).gcode == TV_PROCESSED
    assert read_3w(write_3w(TV_INPUT[:-1] + b"\r")).gcode == TV_PROCESSED


# ---------------------------------------------------------------------------------------------------- processing


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        (b"G0 X5", b"G1 X5"),
        (b"G00 X5", b"G01 X5"),
        (b"G0", b"G1"),
        (b"G0X5Y2", b"G1X5Y2"),
        (b"G0\tX5", b"G1\tX5"),
        (b"G0;travel", b"G1;travel"),
        (b"g0 x5", b"g1 x5"),
        (b"  G0 X5", b"  G1 X5"),
        (b"N12 G0 X5", b"N12 G1 X5"),
        (b"G01 X5", b"G01 X5"),
        (b"G04 P100", b"G04 P100"),
        (b"G05 X1", b"G05 X1"),  # G2/G3 arcs become segments (test_arcs.py)
        (b"G10", b"G10"),
        (b"G10.5", b"G10.5"),
        (b"G 0 X5", b"G 1 X5"),
        (b"G\t00 X5", b"G\t01 X5"),
        (b"G 1 X5", b"G 1 X5"),
        (b"G1 X10 ; G0 in a comment", b"G1 X10 ; G0 in a comment"),
        (b"; G0 in a comment", b"; G0 in a comment"),
        (b"M117 G0 done", b"M117 G0 done"),
    ],
)
def test_only_g0_command_words_become_g1(line: bytes, expected: bytes) -> None:
    gcode = b"M83\n" + line + b"\nM84\n"
    processed = processed_for(gcode, "dv1MX0A000")
    assert processed.endswith(b"M83\n" + expected + b"\nM84\n")


def test_previous_xyz_keys_are_replaced_other_comments_kept() -> None:
    gcode = (
        b"; filename = old.3w\n; print_time = 42\n; machine = daVinciF10\n; version = 17110616\n"
        b";Generated with Cura_SteamEngine version 4.8\n; nozzle_diameter = 0.4\n\n; total_filament = 1.5\nG28\n"
    )
    processed = processed_for(gcode, "dv1MX0A000")
    header = processed[:processed.index(b"G28")]
    assert header.count(b"; machine = ") == 1
    assert b"; machine = dv1MX0A000\n" in header
    assert b"; print_time = 42\n" in header
    assert b"; total_filament = 1.50\n" in header
    assert b";Generated with Cura_SteamEngine version 4.8\n" in header
    assert b"; nozzle_diameter = 0.4\n\n" in header
    assert b"old.3w" not in header
    assert b"17110616" not in header


def test_processing_is_idempotent() -> None:
    once = processed_for(TV_INPUT, "dv1MX0A000")
    assert processed_for(once, "dv1MX0A000") == once


def test_metadata_is_computed_when_no_slicer_states_it() -> None:
    gcode = b"G28\nG92 E0\nG1 Z0.2 F600\nG1 X10 E2 F600\nG1 Y10 E4\nG1 Z0.4\nG1 X0 E6\n"
    info = read_3w(write_3w(gcode))
    assert info.layers == 2
    assert info.filament_mm == 6.0
    # 0.2 + 10 + 10 + 0.2 + 10 mm at 10 mm/s
    assert info.print_time_s == 3


def test_metadata_from_prusaslicer_footer() -> None:
    gcode = (b"; generated by PrusaSlicer 2.6.0\nG28\nG1 X1 E1\n"
             b"; filament used [mm] = 1234.56\n; estimated printing time (normal mode) = 1h 2m 3s\n"
             b"; total layers count = 42\n")
    info = read_3w(write_3w(gcode, "nano"))
    assert (info.print_time_s, info.filament_mm, info.layers) == (3723, 1234.56, 42)


# ---------------------------------------------------------------------------------------------------- bad input


def test_is_3w(tmp_path: Path) -> None:
    assert is_3w((DATA / "tv1_minimaker_v2.3w").read_bytes())
    assert is_3w(DATA / "tv1_minimaker_v2.3w")
    assert is_3w(str(DATA / "tv2_jr_pro_v5.3w"))
    assert not is_3w(TV_INPUT)
    assert not is_3w(DATA / "tv_input.gcode")
    assert not is_3w(tmp_path / "missing.3w")
    assert not is_3w(b"")


def corrupt_tag(data: bytes, tag: bytes) -> bytes:
    return data[:4704] + tag + data[4712:]


def recrc(data: bytes) -> bytes:
    return data[:4716] + zlib.crc32(data[8192:]).to_bytes(4, "big") + data[4720:]


def zipped_body_with(zip_bytes: bytes) -> bytes:
    return b"".join(cbc(pad(zip_bytes[i:i + 0x2000])) for i in range(0, len(zip_bytes), 0x2000))


TV1 = (DATA / "tv1_minimaker_v2.3w").read_bytes()
TV_ZIP = write_3w(TV_INPUT, "dvF100B000")


def _two_member_zip() -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("a.gcode", "G28\n")
        archive.writestr("b.gcode", "G28\n")
    return buffer.getvalue()


def _damaged_zip() -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("sample.gcode", "G28\n" * 1000)
    raw = bytearray(buffer.getvalue())
    raw[60:80] = bytes(20)
    return bytes(raw)


BAD_FILES = {
    "garbage": (b"\x89PNG\r\n\x1a\n" + bytes(9000), "not a .3w file"),
    "gcode": (TV_INPUT, "not a .3w file"),
    "empty": (b"", "not a .3w file"),
    "truncated header area": (TV1[:5000], "truncated"),
    "no body": (TV1[:8192], "no body"),
    "body cut mid-block": (TV1[:8192 + 37], "not a multiple of 16"),
    "zip body cut mid-block": (TV_ZIP[:8192 + 37], "truncated or corrupt"),
    "unknown version": (TV1[:13] + b"\x03" + TV1[14:], "container version 3"),
    "unknown tag": (corrupt_tag(TV1, b"TagXX999"), "unknown body tag"),
    "gap past the body": (TV1[:16] + (9000).to_bytes(4, "big") + TV1[20:], "runs past the body"),
    "wrong variant ecb as zip": (corrupt_tag(TV1, b"TagEa128"), "wrong key or variant"),
    "wrong variant zip as ecb": (corrupt_tag(TV_ZIP, b"TagEJ256"), "wrong key or encryption variant"),
    "wrong key": (recrc(TV1[:8192] + Cipher(algorithms.AES(b"k" * 32), modes.ECB()).encryptor().update(
        pad(TV_PROCESSED))), "wrong key or encryption variant"),
    "corrupt zip": (TV_ZIP[:8192] + zipped_body_with(_damaged_zip()), "zipped body is corrupt"),
    "two zip members": (TV_ZIP[:8192] + zipped_body_with(_two_member_zip()), "holds 2 files"),
    "header not decryptable": (TV1[:4784] + b"\x01" * 16 + TV1[4800:], "header does not decrypt"),
}


@pytest.mark.parametrize("case", BAD_FILES, ids=str)
def test_bad_3w_files_raise_specific_errors(case: str, tmp_path: Path) -> None:
    data, message = BAD_FILES[case]
    with pytest.raises(InputError, match=message):
        read_3w(data)
    with pytest.raises(InputError, match=message):
        inspect_3w(data)
    src = tmp_path / "bad.3w"
    src.write_bytes(data)
    dst = tmp_path / "out.gcode"
    with pytest.raises(InputError, match=message):
        convert_3w_to_gcode(src, dst)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.3w"]


BAD_GCODE = {
    "empty": (b"", "is empty"),
    "blank": (b"\r\n \n\t\n", "empty G-code"),
    "only comments": (b"; just a comment\n;another\n", "no commands"),
    "text without commands": (b"Dear printer,\nplease print a cube.\n", "text, not G-code"),
}


@pytest.mark.parametrize("case", BAD_GCODE, ids=str)
def test_bad_gcode_raises_and_leaves_no_output(case: str, tmp_path: Path) -> None:
    data, message = BAD_GCODE[case]
    with pytest.raises(InputError, match=message):
        write_3w(data)
    src = tmp_path / "in.gcode"
    src.write_bytes(data)
    dst = tmp_path / "out.3w"
    dst.write_bytes(b"previous")
    with pytest.raises(InputError, match=message):
        convert_gcode_file(src, dst, "miniMaker")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.gcode", "out.3w"]
    assert dst.read_bytes() == b"previous"


@pytest.mark.parametrize("model", ["dv1MX0A000", "dv1JP0A000"])
def test_a_comment_block_too_big_for_the_header_leaves_only_the_xyz_keys_there(model: str) -> None:
    comments = b"".join(b"; setting_%04d = some value\n" % i for i in range(200))
    gcode = comments + b"G28\nG1 X1 Y1 E1\n"
    decoded = read_3w(write_3w(gcode, model))
    assert decoded.header.count(b"\n") == 7
    assert list(decoded.fields)[:7] == ["filename", "print_time", "machine", "facets", "total_layers", "version",
                                        "total_filament"]
    assert decoded.gcode.endswith(gcode)


def test_unknown_model_and_missing_files(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="unknown printer model 'prusa'"):
        write_3w(TV_INPUT, "prusa")
    with pytest.raises(InputError, match="cannot read"):
        convert_gcode_file(tmp_path / "nope.gcode", tmp_path / "x.3w")
    with pytest.raises(InputError, match="cannot read"):
        read_3w(tmp_path / "nope.3w")
    with pytest.raises(InputError, match="cannot write"):
        convert_3w_to_gcode(DATA / "tv1_minimaker_v2.3w", tmp_path / "no" / "such" / "dir.gcode")
    with pytest.raises(InputError, match="container version 4"):
        write_3w(TV_INPUT, container=4)  # type: ignore[arg-type]


def test_progress_reports_reach_the_total(tmp_path: Path) -> None:
    src = tmp_path / "big.gcode"
    src.write_bytes(incompressible_gcode(300_000))
    seen: list[tuple[int, int]] = []
    convert_gcode_file(src, tmp_path / "big.3w", progress=lambda done, total: seen.append((done, total)))
    assert seen[-1] == (src.stat().st_size, src.stat().st_size)
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)
    back: list[tuple[int, int]] = []
    convert_3w_to_gcode(tmp_path / "big.3w", tmp_path / "back.gcode", lambda d, t: back.append((d, t)))
    assert back[-1][0] == back[-1][1] == (tmp_path / "big.3w").stat().st_size


def test_v5_file_with_an_encrypted_header() -> None:
    data = bytearray((DATA / "tv2_jr_pro_v5.3w").read_bytes())
    header = TV_PROCESSED[:190].replace(b"dv1MX0A000", b"dv1JP0A000")
    data[4800:4992] = cbc(pad(header))
    info = read_3w(bytes(data))
    assert info.header_encrypted
    assert info.header == header
    assert info.machine == "dv1JP0A000"


def test_an_interrupted_conversion_leaves_nothing_behind(tmp_path: Path) -> None:
    src = tmp_path / "big.gcode"
    src.write_bytes(incompressible_gcode(12_000_000))

    def stop(done: int, total: int) -> None:
        if done > total // 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        convert_gcode_file(src, tmp_path / "big.3w", progress=stop)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.gcode"]
    convert_gcode_file(src, tmp_path / "big.3w")
    with pytest.raises(KeyboardInterrupt):
        convert_3w_to_gcode(tmp_path / "big.3w", tmp_path / "back.gcode", progress=stop)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.3w", "big.gcode"]


@pytest.mark.parametrize("mask", [0o022, 0o002, 0o077])
def test_converted_files_get_the_mode_the_umask_gives(mask: int, tmp_path: Path) -> None:
    src = tmp_path / "part.gcode"
    src.write_bytes(TV_INPUT)
    previous = os.umask(mask)
    try:
        convert_gcode_file(src, tmp_path / "part.3w")
        convert_3w_to_gcode(tmp_path / "part.3w", tmp_path / "back.gcode")
        (tmp_path / "plain").write_bytes(b"")
    finally:
        os.umask(previous)
    expected = 0o666 & ~mask
    assert stat.S_IMODE((tmp_path / "plain").stat().st_mode) == expected
    assert stat.S_IMODE((tmp_path / "part.3w").stat().st_mode) == expected
    assert stat.S_IMODE((tmp_path / "back.gcode").stat().st_mode) == expected
