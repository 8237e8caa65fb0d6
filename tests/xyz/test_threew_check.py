"""`check_3w` (what `xyz print` checks before an upload) tells what `inspect_3w` tells of a file's header and
checksum, for every container variant, damaged bodies and bodies that do not decrypt, while decrypting only the
body's first block."""

from __future__ import annotations

import base64
from collections.abc import Callable
from pathlib import Path

import pytest

from fabwire.errors import InputError
from fabwire.xyz.printjob import check_in_background
from fabwire.xyz.threew import BODY_OFFSET, check_3w, convert_gcode_file, inspect_3w

DATA = Path(__file__).parent / "data" / "threew"
GCODE = (DATA / "tv_input.gcode").read_bytes()


def converted(model: str, **options: object) -> Callable[[Path], bytes]:
    def make(tmp: Path) -> bytes:
        source, target = tmp / "in.gcode", tmp / "out.3w"
        source.write_bytes(GCODE * 40)
        convert_gcode_file(source, target, model, **options)  # type: ignore[arg-type]
        return target.read_bytes()

    return make


def damaged(make: Callable[[Path], bytes], at: int | None) -> Callable[[Path], bytes]:
    """A byte of the body flipped at `at` (None: halfway through the body)."""

    def spoil(tmp: Path) -> bytes:
        data = bytearray(make(tmp))
        data[(BODY_OFFSET + len(data)) // 2 if at is None else at] ^= 0x5A
        return bytes(data)

    return spoil


VARIANTS: dict[str, Callable[[Path], bytes]] = {
    # variant: how the file is made (the vendor's files for the model, per the model table)
    "miniMaker v2 ECB (test vector)": lambda _: (DATA / "tv1_minimaker_v2.3w").read_bytes(),
    "Jr. Pro v5 (test vector)": lambda _: (DATA / "tv2_jr_pro_v5.3w").read_bytes(),
    "mini w v2 ECB": converted("mini w"),
    "nano v5": converted("nano", container=5),
    "1.0 zipped CBC": converted("1.0", zipped=True),
    "base64 text (XYZware import)": lambda tmp: base64.b64encode(converted("mini w")(tmp)),
    "a byte of the body flipped at its end": damaged(converted("mini w"), -20),
    "a byte of the body flipped in its middle": damaged(converted("mini w"), None),
}


@pytest.mark.parametrize("variant", VARIANTS)
def test_check_agrees_with_a_full_inspection(variant: str, tmp_path: Path) -> None:
    path = tmp_path / "job.3w"
    path.write_bytes(VARIANTS[variant](tmp_path))
    full, quick = inspect_3w(path), check_3w(path)
    assert (quick.fields, quick.crc_stored, quick.crc_computed) == (full.fields, full.crc_stored, full.crc_computed)
    assert quick.crc_ok == ("flipped" not in variant)


@pytest.mark.parametrize("where", [BODY_OFFSET, BODY_OFFSET + 16])
def test_a_body_that_does_not_decrypt_is_refused_alike(where: int, tmp_path: Path) -> None:
    data = bytearray(converted("mini w")(tmp_path))
    data[where:where + 16] = bytes(range(16))  # the first blocks: no longer G-code once decrypted
    path = tmp_path / "job.3w"
    path.write_bytes(bytes(data))
    with pytest.raises(InputError) as full:
        inspect_3w(path)
    with pytest.raises(InputError) as quick:
        check_3w(path)
    assert str(quick.value) == str(full.value)


@pytest.mark.parametrize("variant", VARIANTS)
def test_a_file_and_its_bytes_are_checked_alike(variant: str, tmp_path: Path) -> None:
    """A file on disk and the same bytes in memory (what a pipe gives): one outcome."""
    path = tmp_path / "job.3w"
    path.write_bytes(VARIANTS[variant](tmp_path))
    on_disk, in_memory = check_3w(path), check_3w(path.read_bytes())
    assert (on_disk.fields, on_disk.crc_stored, on_disk.crc_computed) == \
        (in_memory.fields, in_memory.crc_stored, in_memory.crc_computed)


@pytest.mark.parametrize("variant", VARIANTS)
def test_the_check_in_the_background_is_the_check(variant: str, tmp_path: Path) -> None:
    """What `xyz print` starts while it reaches the printer: `check_3w` of a binary .3w on disk, nothing for a
    base64 one (decoded first, then checked) or for bytes."""
    path = tmp_path / "job.3w"
    path.write_bytes(VARIANTS[variant](tmp_path))
    found = check_in_background(path).result(timeout=60)
    if "base64" in variant:
        assert found is None
    else:
        assert found == check_3w(path)
    assert check_in_background(path.read_bytes()).result(timeout=60) is None


def test_the_check_in_the_background_hands_over_its_refusal(tmp_path: Path) -> None:
    data = bytearray(converted("mini w")(tmp_path))
    data[BODY_OFFSET:BODY_OFFSET + 16] = bytes(range(16))
    path = tmp_path / "job.3w"
    path.write_bytes(bytes(data))
    with pytest.raises(InputError) as direct:
        check_3w(path)
    with pytest.raises(InputError) as handed:
        check_in_background(path).result(timeout=60)
    assert str(handed.value) == str(direct.value)
