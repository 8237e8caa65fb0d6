"""XYZprinting `.3w` print files: G-code in, the encrypted container the printers accept out, and back.

Layout: magic, a zero gap, a cipher tag, offsets and a CRC-32 of the stored body, the header comment block (AES-128-CBC
in v2, plaintext in v5) and, from 0x2000, the body: the whole processed G-code either AES-256-ECB (`TagEJ256`) or
zipped and AES-128-CBC in 0x2000-byte pieces (`TagEa128`). Everything streams in large chunks so file size does not
bound memory.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import struct
import tempfile
import zipfile
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO, Literal

from fabwire.errors import InputError
from fabwire.xyz import intake
from fabwire.xyz.models import PrinterModel, default_model, find_model, model_for_file_id

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.ciphers import Cipher

MAGIC = intake.MAGIC
BODY_OFFSET = 0x2000
TAG_ECB = b"TagEJ256"
TAG_ZIP = b"TagEa128"
KEY_256 = b"@xyzprinting.com@xyzprinting.com"
KEY_128 = b"@xyzprinting.com"
ZIP_PIECE = 0x2000
ZIP_CIPHER_PIECE = ZIP_PIECE + 16
ZIP_MEMBER = "sample.gcode"
GAP = 4684
"""Zero bytes before the tag in miniMover/XYZware files (XYZprint's compact layout uses 8)."""
HEADER_OFFSET = {2: 68, 5: 80}
CHUNK = 1 << 22
DECODE_PIECE = 1 << 20
"""Bytes decrypted at once when reading a .3w: each piece is held about four times over (read, decrypted,
joined, written), so a small piece keeps decoding within a few MiB whatever the file's size."""
SNIFF_BLOCK = 1 << 12
"""Bytes of an encrypted body decrypted to see that it is G-code (a multiple of the AES block)."""
GCODE_SUFFIXES = (".gcode", ".gco", ".g")

Progress = intake.Progress

_HEADER_FIELD = re.compile(rb"^[ \t]*;[ \t]*([A-Za-z_][A-Za-z0-9_ ]*?)[ \t]*=[ \t]*(.*?)[ \t\r]*$", re.MULTILINE)


@dataclass(frozen=True, slots=True)
class ThreeWInfo:
    """What a .3w says about itself; `gcode_size` is the processed G-code's length."""

    container: int
    tag: str
    zipped: bool
    header_encrypted: bool
    body_encrypted: bool
    header: bytes
    fields: dict[str, str]
    crc_stored: int
    crc_computed: int
    gcode_size: int
    body_size: int
    gap: int = GAP
    header_offset: int = 0
    pad_ok: bool = True
    model: PrinterModel | None = None
    notes: tuple[str, ...] = ()
    """What the conversion set aside or changed (figures not believed, NUL padding or bytes dropped)."""

    @property
    def crc_ok(self) -> bool:
        return self.crc_stored == self.crc_computed

    @property
    def machine(self) -> str | None:
        return self.fields.get("machine")

    @property
    def print_time_s(self) -> int | None:
        return _int(self.fields.get("print_time"))

    @property
    def filament_mm(self) -> float | None:
        return _float(self.fields.get("total_filament"))

    @property
    def layers(self) -> int | None:
        return _int(self.fields.get("total_layers"))

    @property
    def variant(self) -> str:
        return f"v{self.container} {self.tag}" + (" zipped" if self.zipped else "")


@dataclass(frozen=True, slots=True)
class ThreeWFile(ThreeWInfo):
    gcode: bytes = field(default=b"", repr=False)


def _float(text: str | None) -> float | None:
    """A header field's number; None for a missing one, for text, and for `inf`/`nan` (no print takes for ever)."""
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _int(text: str | None) -> int | None:
    value = _float(text)
    return None if value is None else round(value)


def _pkcs7(data: bytes) -> bytes:
    n = 16 - len(data) % 16
    return data + bytes([n]) * n


def _unpad(data: bytes) -> tuple[bytes, bool]:
    """Strip a valid PKCS#7 pad; keep everything when there is none (miniMover omits it on aligned sizes)."""
    n = data[-1] if data else 0
    if 1 <= n <= 16 and len(data) >= n and data[-n:] == bytes([n]) * n:
        return data[:-n], True
    return data, False


def _aes(key: bytes, *, cbc: bool = False) -> Cipher[Any]:
    """AES under `key`: ECB, or CBC from a zero IV. The cipher library loads on first use: a command that only
    sends or lists files needs none."""
    from cryptography.hazmat.primitives.ciphers import Cipher, algorithms, modes

    return Cipher(algorithms.AES(key), modes.CBC(bytes(16)) if cbc else modes.ECB())


def _cbc128(data: bytes, *, decrypt: bool = False) -> bytes:
    cipher = _aes(KEY_128, cbc=True)
    ctx = cipher.decryptor() if decrypt else cipher.encryptor()
    return ctx.update(data) + ctx.finalize()


def _resolve_model(model: PrinterModel | str | None) -> PrinterModel:
    if model is None:
        return default_model()
    return model if isinstance(model, PrinterModel) else find_model(model)


# --------------------------------------------------------------------------------------------------------------------
# Writing


def _header_start(container: int) -> int:
    """Where the header goes: right after the offset field (and the v5 `1` field) plus the offset."""
    offset_field_end = 20 + GAP + 8 + (4 if container == 5 else 0) + 4
    return offset_field_end + HEADER_OFFSET[container]


def _preamble(container: int, tag: bytes, stored_header: bytes, crc: int) -> bytes:
    """The first 0x2000 bytes, in the miniMover/XYZware layout."""
    out = bytearray(MAGIC + bytes([1, container, 0, 0]) + GAP.to_bytes(4, "big") + bytes(GAP) + tag)
    offset = HEADER_OFFSET[container]
    if container == 5:
        out += len(stored_header).to_bytes(4, "big")
    out += offset.to_bytes(4, "big")
    if container == 5:
        out += (1).to_bytes(4, "big")
    out += crc.to_bytes(4, "big")
    start = _header_start(container)
    space = BODY_OFFSET - start
    if len(stored_header) > space:
        raise InputError(
            f"the G-code's leading comment block makes a {len(stored_header)}-byte .3w header; "
            f"a v{container} file has room for {space} bytes — shorten the comments before the first command"
        )
    out += bytes(start - len(out)) + stored_header
    out += bytes(BODY_OFFSET - len(out))
    return bytes(out)


def _stored_header(container: int, header: bytes) -> bytes:
    padded = _pkcs7(header)
    return padded if container == 5 else _cbc128(padded)


def _encrypt_ecb(pieces: Iterator[bytes], out: BinaryIO) -> tuple[int, int, int]:
    """Returns (crc of stored body, stored size, plaintext size)."""
    encryptor = _aes(KEY_256).encryptor()  # buffers partial blocks itself
    crc = size = plain = 0
    for piece in pieces:
        plain += len(piece)
        enc = encryptor.update(piece)
        crc = zlib.crc32(enc, crc)
        size += len(enc)
        out.write(enc)
    pad = 16 - plain % 16
    enc = encryptor.update(bytes([pad]) * pad) + encryptor.finalize()
    crc = zlib.crc32(enc, crc)
    out.write(enc)
    return crc, size + len(enc), plain


def _encrypt_zip(pieces: Iterator[bytes], out: BinaryIO) -> tuple[int, int, int]:
    plain = 0
    with tempfile.TemporaryFile() as scratch:
        info = zipfile.ZipInfo(ZIP_MEMBER, date_time=(1980, 1, 1, 0, 0, 0))
        info.compress_type = zipfile.ZIP_DEFLATED
        info.external_attr = 0o644 << 16
        try:
            with zipfile.ZipFile(scratch, "w") as archive, archive.open(info, "w", force_zip64=False) as member:
                for piece in pieces:
                    plain += len(piece)
                    member.write(piece)
        except (RuntimeError, zipfile.LargeZipFile) as exc:
            raise InputError(f"the G-code is too large for a zipped .3w ({exc})") from exc
        scratch.seek(0)
        crc = size = 0
        while piece := scratch.read(ZIP_PIECE):
            enc = _cbc128(_pkcs7(piece))
            crc = zlib.crc32(enc, crc)
            size += len(enc)
            out.write(enc)
    return crc, size, plain


def _write(
    src: BinaryIO, name: str, out: BinaryIO, model: PrinterModel, container: int | None, zipped: bool | None,
    filename: str, progress: Progress | None, repair: bool = False, force: bool = False, keep_arcs: bool = False,
) -> ThreeWInfo:
    container = model.container if container is None else container
    zipped = model.zipped if zipped is None else zipped
    if container not in HEADER_OFFSET:
        raise InputError(f"unknown .3w container version {container}; use 2 or 5")
    prepared = intake.prepare(src, name, model, filename, BODY_OFFSET - _header_start(container), progress,
                              repair=repair, force=force, keep_arcs=keep_arcs)
    stored = _stored_header(container, prepared.header)
    tag = TAG_ZIP if zipped else TAG_ECB
    _preamble(container, tag, stored, 0)  # fail on an oversized header before writing the body
    out.seek(BODY_OFFSET)
    body = intake.processed_body(src, name, prepared, progress)
    crc, size, plain = (_encrypt_zip if zipped else _encrypt_ecb)(body, out)
    out.seek(0)
    out.write(_preamble(container, tag, stored, crc))
    return ThreeWInfo(
        container=container, tag=tag.decode(), zipped=zipped, header_encrypted=container != 5, body_encrypted=True,
        header=prepared.header, fields=_fields(prepared.header), crc_stored=crc, crc_computed=crc, gcode_size=plain,
        body_size=size, gap=GAP, header_offset=_header_start(container), model=model, notes=prepared.notes,
    )


def write_3w(
    gcode: bytes, model: PrinterModel | str | None = None, *, container: Literal[2, 5] | None = None,
    zipped: bool | None = None, progress: Progress | None = None, filename: str = "temp.3w", force: bool = False,
) -> bytes:
    """The .3w bytes for `gcode` as `model` expects them (container/zipped override the model's defaults)."""
    kind = intake.identify(gcode[:intake.SNIFF], len(gcode))
    if kind is not intake.Kind.GCODE:
        raise intake.refusal(kind, "the data", gcode[:intake.SNIFF])
    out = BytesIO()
    _write(BytesIO(gcode), "the G-code", out, _resolve_model(model), container, zipped, filename, progress,
           force=force)
    return out.getvalue()


def _umask() -> int:
    """The process umask, read without changing it where /proc tells it (os.umask can only set and return)."""
    try:
        with open("/proc/self/status", "rb") as status:
            for line in status:
                if line.startswith(b"Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _lock(fd: int) -> bool:
    """Take the exclusive advisory lock of an open file without waiting; False when another process has it
    (where there are no such locks, as on Windows, an open file cannot be deleted, which serves the same end)."""
    try:
        import fcntl
    except ImportError:
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return False
    return True


_PART = re.compile(r"^\..+\.[a-z0-9_]{8}\.part$")
"""The temporaries `_atomic` makes (tempfile.mkstemp: prefix ".NAME.", eight random characters, ".part")."""


def _sweep_parts(dst: Path) -> None:
    """Remove the temporaries of runs that were killed while writing `dst`, or any other .3w beside it (each
    writer locks its own, so one that can be locked has no writer)."""
    for stale in dst.parent.glob(".*.part"):
        if not _PART.match(stale.name) or not (stale.name.startswith(f".{dst.name}.") or ".3w." in stale.name):
            continue
        with contextlib.suppress(OSError), open(stale, "rb") as handle:
            if _lock(handle.fileno()):
                stale.unlink()


@contextlib.contextmanager
def _atomic(dst: Path, *, replace: bool = True) -> Iterator[BinaryIO]:
    """A temporary file next to `dst` that replaces it, synced, only if the block succeeds; locked while it is
    written, so a run killed half-way leaves a temporary the next run removes. Without `replace`, a `dst` that
    has appeared meanwhile is kept and the result is an InputError (the file is linked in, never renamed over)."""
    dst = Path(dst)
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{dst.name}.", suffix=".part", dir=dst.parent)
    except OSError as exc:
        raise InputError(f"cannot write {dst}: {exc.strerror}") from exc
    tmp = Path(tmp_name)
    try:
        with os.fdopen(fd, "w+b") as handle:
            _lock(handle.fileno())
            _sweep_parts(dst)
            yield handle
            os.fchmod(handle.fileno(), 0o666 & ~_umask())  # mkstemp's 0600 is for the temporary name only
            handle.flush()
            os.fsync(handle.fileno())  # a power cut after the rename must not leave an empty file
            if os.name == "posix":
                _commit(tmp, dst, replace)  # while still locked: no sweeper takes it for a leftover
        if os.name != "posix":
            _commit(tmp, dst, replace)  # Windows renames only closed files (and deletes no open one)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _commit(tmp: Path, dst: Path, replace: bool) -> None:
    if replace:
        os.replace(tmp, dst)
        return
    try:
        os.link(tmp, dst)  # fails if dst exists, however it came to
    except FileExistsError:
        raise InputError(f"{dst} exists already: name it as DST to replace it, or give another DST") from None
    except OSError as exc:
        raise InputError(f"cannot write {dst}: {exc.strerror or exc}") from exc
    tmp.unlink()


def convert_gcode_file(
    src: Path, dst: Path, model: PrinterModel | str | None = None, *, container: Literal[2, 5] | None = None,
    zipped: bool | None = None, progress: Progress | None = None, repair: bool = False, force: bool = False,
    keep_arcs: bool = False, replace: bool = True,
) -> ThreeWInfo:
    """Convert a G-code file to a .3w file; `dst` appears complete or not at all (and without `replace` only if
    no file has that name). A NUL byte inside the G-code is an InputError naming its line, or with `repair`
    dropped and noted in the result's `notes`; so are extrusions beyond the model's build volume, unless `force`.
    G2/G3 arcs become line segments unless `keep_arcs`."""
    target = _resolve_model(model)
    kind, head = intake.sniff(src)
    if kind is not intake.Kind.GCODE:
        raise intake.refusal(kind, str(src), head)
    with intake.open_input(src) as source, _atomic(dst, replace=replace) as out:
        return _write(source, str(src), out, target, container, zipped, Path(dst).name, progress, repair, force,
                      keep_arcs)


# --------------------------------------------------------------------------------------------------------------------
# Reading


@dataclass(frozen=True, slots=True)
class _Layout:
    container: int
    tag: bytes
    gap: int
    header_offset: int
    header_length: int | None
    crc: int


def _u32(data: bytes, at: int) -> int:
    return int.from_bytes(data[at:at + 4], "big")


def _parse_layout(pre: bytes, name: str) -> _Layout:
    if len(pre) < len(MAGIC) or pre[:len(MAGIC)] != MAGIC:
        raise InputError(f"{name} is not a .3w file (no 3DPFNKG13WTW signature)")
    if len(pre) < BODY_OFFSET:
        raise InputError(f"{name} is truncated: {len(pre)} bytes, a .3w has at least {BODY_OFFSET + 16}")
    container = pre[13]
    if container not in (2, 5):
        raise InputError(f"{name}: unsupported .3w container version {container} (known: 2, 5)")
    gap = _u32(pre, 16)
    at = 20 + gap
    fields_end = at + 8 + (16 if container == 5 else 8)
    if fields_end > BODY_OFFSET:
        raise InputError(f"{name} is corrupt: the header gap ({gap} bytes) runs past the body")
    tag = pre[at:at + 8]
    if tag not in (TAG_ECB, TAG_ZIP):
        raise InputError(f"{name} is corrupt: unknown body tag {tag!r} (expected TagEJ256 or TagEa128)")
    at += 8
    length = None
    if container == 5:
        length = _u32(pre, at)
        at += 4
    offset_end = at + 4
    header_offset = offset_end + _u32(pre, at)
    at += 4 + (4 if container == 5 else 0)
    crc = _u32(pre, at)
    if not at + 4 <= header_offset <= BODY_OFFSET or (length is not None and header_offset + length > BODY_OFFSET):
        raise InputError(f"{name} is corrupt: the header lies outside the first {BODY_OFFSET} bytes")
    return _Layout(container, tag, gap, header_offset, length, crc)


def _looks_like_text(data: bytes) -> bool:
    sample = data[:64]
    return bool(sample) and not re.search(rb"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]", sample)


def _read_header(pre: bytes, layout: _Layout, name: str) -> tuple[bytes, bool]:
    """(header text, was it encrypted)."""
    if layout.header_length is not None:
        raw = pre[layout.header_offset:layout.header_offset + layout.header_length]
    else:
        raw = pre[layout.header_offset:BODY_OFFSET]
        if not raw.lstrip().startswith(b";"):
            region = raw[:len(raw) - len(raw) % 16]
            blocks = [region[i:i + 16] for i in range(0, len(region), 16)]
            while blocks and not any(blocks[-1]):
                blocks.pop()
            raw = b"".join(blocks)
        else:
            raw = raw.rstrip(b"\0")
    if not raw or raw.lstrip().startswith(b";"):
        return _unpad(raw)[0], False
    if len(raw) % 16:
        raise InputError(f"{name} is corrupt: encrypted header of {len(raw)} bytes is not a multiple of 16")
    text = _unpad(_cbc128(raw, decrypt=True))[0]
    if not _looks_like_text(text):
        raise InputError(f"{name}: the header does not decrypt to text (wrong key or encryption variant)")
    return text, True


def _fields(header: bytes) -> dict[str, str]:
    found: dict[str, str] = {}
    for key, value in _HEADER_FIELD.findall(header):
        found.setdefault(key.decode("utf-8", "replace").strip(), value.decode("utf-8", "replace"))
    return found


def _refuse_ragged(body_size: int, name: str) -> None:
    if body_size % 16:
        raise InputError(f"{name} is truncated or corrupt: the body is {body_size} bytes, not a multiple of 16")


def _refuse_undecryptable(text: bytes, name: str) -> None:
    if not _looks_like_text(text):
        raise InputError(f"{name}: the body does not decrypt to G-code (wrong key or encryption variant)")


def _refuse_bodiless(body_size: int, name: str) -> None:
    if body_size <= 0:
        raise InputError(f"{name} is truncated: it has no body after its {BODY_OFFSET}-byte header area")


def _decrypt_ecb(
    src: BinaryIO, body_size: int, sink: Callable[[bytes], object], name: str, progress: Progress | None, total: int,
) -> tuple[int, int, bool, bool]:
    """Returns (crc of stored body, plaintext size, pad present, body encrypted)."""
    first = src.read(DECODE_PIECE)
    crc = zlib.crc32(first)
    if first[:1] == b";":
        sink(first)
        plain = len(first)
        while block := src.read(DECODE_PIECE):
            crc = zlib.crc32(block, crc)
            sink(block)
            plain += len(block)
        return crc, plain, True, False
    _refuse_ragged(body_size, name)
    decryptor = _aes(KEY_256).decryptor()
    held = b""
    plain = 0
    block = first
    checked = False
    done = BODY_OFFSET
    while block:
        done += len(block)
        text = held + decryptor.update(block)
        if not checked:
            _refuse_undecryptable(text, name)
            checked = True
        held = text[-16:]
        if len(text) > 16:
            sink(text[:-16])
            plain += len(text) - 16
        if progress is not None:
            progress(done, total)
        block = src.read(DECODE_PIECE)
        crc = zlib.crc32(block, crc)
    last, pad_ok = _unpad(held + decryptor.finalize())
    sink(last)
    return crc, plain + len(last), pad_ok, True


def _decrypt_zip(
    src: BinaryIO, body_size: int, sink: Callable[[bytes], object], name: str, progress: Progress | None, total: int,
) -> tuple[int, int, bool, bool]:
    crc = 0
    pad_ok = True
    done = BODY_OFFSET
    with tempfile.TemporaryFile() as scratch:
        while piece := src.read(ZIP_CIPHER_PIECE):
            crc = zlib.crc32(piece, crc)
            done += len(piece)
            if len(piece) % 16:
                raise InputError(f"{name} is truncated or corrupt: a zipped body piece of {len(piece)} bytes")
            plain, pad_ok = _unpad(_cbc128(piece, decrypt=True))
            if scratch.tell() == 0 and not plain.startswith(b"PK\x03\x04"):
                raise InputError(f"{name}: the body does not decrypt to a zip archive (wrong key or variant)")
            scratch.write(plain)
            if progress is not None:
                progress(done, total)
        scratch.seek(0)
        size = 0
        with _corrupt_zip(name):
            archive = zipfile.ZipFile(scratch)
        with archive:
            members = archive.infolist()
            if len(members) != 1:
                raise InputError(f"{name}: the zipped body holds {len(members)} files, expected exactly one")
            with _corrupt_zip(name):
                member = archive.open(members[0])
            with member:
                while True:
                    with _corrupt_zip(name):
                        data = member.read(DECODE_PIECE)
                    if not data:
                        break
                    sink(data)  # the output's own errors stay what they are
                    size += len(data)
    return crc, size, pad_ok, True


@contextlib.contextmanager
def _corrupt_zip(name: str) -> Iterator[None]:
    """What the zip reader raises on a damaged archive (offsets before its start make seek() fail with EINVAL,
    bad lengths a struct error) as one InputError; it reads only the scratch copy, so these say nothing else."""
    try:
        yield
    except (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError, OSError, ValueError, struct.error) as exc:
        raise InputError(f"{name}: the zipped body is corrupt ({exc})") from exc


def _read(src: BinaryIO, name: str, sink: Callable[[bytes], object], progress: Progress | None) -> ThreeWInfo:
    total = intake.stream_size(src)
    src.seek(0)
    pre = src.read(BODY_OFFSET)
    layout = _parse_layout(pre, name)
    header, header_encrypted = _read_header(pre, layout, name)
    body_size = total - BODY_OFFSET
    _refuse_bodiless(body_size, name)
    decrypt = _decrypt_zip if layout.tag == TAG_ZIP else _decrypt_ecb
    crc, plain, pad_ok, body_encrypted = decrypt(src, body_size, sink, name, progress, total)
    if plain == 0:
        raise InputError(f"{name}: the body holds no G-code")
    fields = _fields(header)
    machine = fields.get("machine")
    return ThreeWInfo(
        container=layout.container, tag=layout.tag.decode(), zipped=layout.tag == TAG_ZIP,
        header_encrypted=header_encrypted, body_encrypted=body_encrypted, header=header, fields=fields,
        crc_stored=layout.crc, crc_computed=crc, gcode_size=plain, body_size=body_size, gap=layout.gap,
        header_offset=layout.header_offset, pad_ok=pad_ok, model=model_for_file_id(machine) if machine else None,
    )


@contextlib.contextmanager
def _source(data_or_path: bytes | str | Path) -> Iterator[tuple[BinaryIO, str]]:
    """The .3w bytes (decoded first when they are base64 text) and how to name them in messages."""
    if isinstance(data_or_path, bytes | bytearray | memoryview):
        yield BytesIO(intake.plain_bytes(bytes(data_or_path), "the data")), "the data"
        return
    path = Path(data_or_path)
    kind, _head = intake.sniff(path)
    with intake.decoded_file(path, kind) as source:
        yield source, str(path)


def read_3w(data_or_path: bytes | str | Path) -> ThreeWFile:
    """Decode a whole .3w (from a path or its bytes) into memory; CRC mismatches are reported, not raised."""
    parts: list[bytes] = []
    with _source(data_or_path) as (source, name):
        info = _read(source, name, parts.append, None)
    values = {f: getattr(info, f) for f in ThreeWInfo.__dataclass_fields__}
    return ThreeWFile(**values, gcode=b"".join(parts))


def inspect_3w(data_or_path: bytes | str | Path, progress: Progress | None = None) -> ThreeWInfo:
    """Everything `read_3w` tells except the G-code, streaming (the body is still decrypted to validate it)."""
    with _source(data_or_path) as (source, name):
        return _read(source, name, lambda _data: None, progress)


@dataclass(frozen=True, slots=True)
class ThreeWCheck:
    """What sending a .3w needs to know first: its header's fields and whether its body matches the stored
    checksum (the printer refuses a file that does not, 0x020D)."""

    fields: dict[str, str]
    crc_stored: int
    crc_computed: int

    @property
    def crc_ok(self) -> bool:
        return self.crc_stored == self.crc_computed

    @property
    def machine(self) -> str | None:
        return self.fields.get("machine")


def check_3w(data_or_path: bytes | str | Path) -> ThreeWCheck:
    """`inspect_3w`'s header fields and checksums, reading the body once without decrypting it all: only its
    first block must decrypt to G-code (the wrong key or variant is refused as there); the rest is only summed,
    as the printer's check does. For a file about to be sent, whose body the printer decrypts. InputError as
    `inspect_3w`."""
    with _source(data_or_path) as (src, name):
        total = intake.stream_size(src)
        src.seek(0)
        pre = src.read(BODY_OFFSET)
        layout = _parse_layout(pre, name)
        if layout.tag == TAG_ZIP:  # its pieces are zipped, then encrypted: read it whole
            info = _read(src, name, lambda _data: None, None)
            return ThreeWCheck(info.fields, info.crc_stored, info.crc_computed)
        header, _ = _read_header(pre, layout, name)
        body_size = total - BODY_OFFSET
        _refuse_bodiless(body_size, name)
        piece = 1 << 20  # summed faster than larger pieces, and memory stays low
        first = src.read(piece)
        if first[:1] != b";":  # an encrypted body (a plain one starts with its header's comments)
            _refuse_ragged(body_size, name)
            start = first[:SNIFF_BLOCK]
            _refuse_undecryptable(_aes(KEY_256).decryptor().update(start), name)
        crc = zlib.crc32(first)
        while block := src.read(piece):
            crc = zlib.crc32(block, crc)
    return ThreeWCheck(_fields(header), layout.crc, crc)


def convert_3w_to_gcode(src: Path, dst: Path, progress: Progress | None = None, *,
                        replace: bool = True) -> ThreeWInfo:
    """Write the processed G-code a .3w carries (header included); `dst` appears complete or not at all (and
    without `replace` only if no file has that name)."""
    with _source(src) as (source, name), _atomic(dst, replace=replace) as out:
        return _read(source, name, out.write, progress)


def is_3w(data_or_path: bytes | bytearray | memoryview | str | Path) -> bool:
    """Whether the bytes (or the file) are a .3w, in binary or base64 text."""
    if isinstance(data_or_path, bytes | bytearray | memoryview):
        kind = intake.identify(bytes(data_or_path[:intake.SNIFF]))
    else:
        try:
            kind = intake.sniff(Path(data_or_path))[0]
        except InputError:
            return False
    return kind in (intake.Kind.THREEW, intake.Kind.THREEW_BASE64)


def is_gcode_path(path: str | Path) -> bool:
    return Path(path).suffix.lower() in GCODE_SUFFIXES
