"""A file made ready for a printer: the .3w to upload, on disk, with memory bounded whatever the file's size.

A .3w (binary or base64 text) that suits the printer is sent as it is (decoded to a temporary file when it is
base64); G-code is converted for the printer's model into a temporary .3w by the streaming converter. Any other
kind of file is an InputError saying what it is (fabwire.xyz.intake).
"""

from __future__ import annotations

import contextlib
import re
import shlex
import tempfile
import threading
from collections.abc import Iterator
from concurrent.futures import Future
from pathlib import Path

from fabwire.errors import InputError
from fabwire.xyz import intake, userinput
from fabwire.xyz.models import PrinterModel, model_for_file_id
from fabwire.xyz.threew import ThreeWCheck, ThreeWInfo, check_3w, convert_gcode_file

_MACHINE_LINE = re.compile(rb"^\s*;\s*machine\s*=\s*(\S+)", re.MULTILINE)


def check_source(source: Path | bytes) -> str:
    """How to name `source` in messages, once it is known to be printable (before any printer is disturbed)."""
    with _on_disk(source) as (path, name):
        kind, head = intake.sniff(path, name)
        intake.require_printable(kind, name, head)
    return name


FileCheck = Future[ThreeWCheck | None]
"""The outcome of `check_in_background`."""


def check_in_background(source: Path | bytes) -> FileCheck:
    """Start the checks of `source` that do not depend on the printer on a thread of their own, so that they run
    while the printer is reached (connection, status): for a binary .3w on disk, `check_3w` (its checksum and
    first block). The result is None for any other source (checked as `ready_file` makes it ready). `ready_file`
    takes the result; an InputError the check raises is raised there."""
    done: FileCheck = Future()
    if not isinstance(source, Path):
        done.set_result(None)
        return done

    def work() -> None:
        done.set_running_or_notify_cancel()
        try:
            kind, _ = intake.sniff(source)
            done.set_result(check_3w(source) if kind is intake.Kind.THREEW else None)
        except BaseException as exc:  # handed over to whoever reads the result
            done.set_exception(exc)

    # a daemon thread: Ctrl-C does not wait for the rest of a large file to be summed
    threading.Thread(target=work, name="file-check", daemon=True).start()
    return done


@contextlib.contextmanager
def _on_disk(source: Path | bytes) -> Iterator[tuple[Path, str]]:
    """(a file holding `source`, its name in messages); bytes are written to a temporary file."""
    if isinstance(source, Path):
        yield source, source.name
        return
    with tempfile.TemporaryDirectory() as scratch:
        path = Path(scratch) / "data"
        path.write_bytes(source)
        yield path, "the data"


@contextlib.contextmanager
def ready_file(source: Path | bytes, model: PrinterModel, *, override: bool = False,
               force: bool = False, checked: FileCheck | None = None) -> Iterator[Path]:
    """The .3w file to upload for `model`: the source itself when it is a .3w that suits the model (any .3w with
    `override`), else a temporary one that lasts while the context does (G-code reaching beyond the model's
    build volume is an InputError unless `force`). Memory stays within the intake's and the converter's bounds,
    not the file's size. `checked`: `check_in_background(source)`, whose result stands for checking the file
    again."""
    with _on_disk(source) as (path, name), tempfile.TemporaryDirectory() as scratch:
        kind, head = intake.sniff(path, name)
        intake.require_printable(kind, name, head)
        with intake.decoded_path(path, kind) as plain:
            if kind.decoded is intake.Kind.THREEW:
                info = checked.result() if checked is not None and kind is intake.Kind.THREEW else None
                check_3w_suits(plain, name, model, override=override, info=info)
                yield plain
                return
            _check_gcode(plain, name, model, override)
            target = Path(scratch) / userinput.derived_upload_name(name)
            convert_gcode_file(plain, target, model, force=force)
            yield target


def check_intact(info: ThreeWInfo | ThreeWCheck, name: str) -> None:
    """InputError for a .3w whose body does not match its stored checksum: the printer would take the upload and
    then refuse the file (0x020D)."""
    if not info.crc_ok:
        raise InputError(f"{name} is damaged: its stored checksum 0x{info.crc_stored:08x} does not match its "
                         f"contents (0x{info.crc_computed:08x}); convert the G-code again")


def check_3w_suits(path: Path, name: str, model: PrinterModel, *, override: bool = False,
                   info: ThreeWCheck | None = None) -> None:
    """InputError for a .3w that is damaged (`check_intact`) or made for another model than `model` (unless
    `override`): the printer would take the upload and then refuse to print it. `info`: `check_3w(path)` if it
    was already made."""
    if info is None:
        info = check_3w(path)  # the printer decrypts the body; here its checksum and first block are enough
    check_intact(info, name)
    machine = (info.machine or "").strip()
    target = model_for_file_id(machine, model) if machine else None
    if not override and (target is None or target.file_id.lower() != model.file_id.lower()):
        what = f"{target.name} ({machine})" if target else repr(machine or "no machine")
        raise InputError(f"{name} is a .3w for {what}, but the printer is a {model.name}; convert the G-code for "
                         f"this printer instead (`fabwire xyz convert GCODE --model {shlex.quote(model.name)}`)")


def _check_gcode(path: Path, name: str, model: PrinterModel, override: bool) -> None:
    with intake.open_input(path, name) as handle:
        head = handle.read(16384)
    if m := _MACHINE_LINE.search(intake.normalise(head, first=True)):
        declared = m[1].decode("latin-1")
        other = model_for_file_id(declared, model)
        if not override and other is not None and other.file_id.lower() != model.file_id.lower():
            raise InputError(f"{name} was sliced for {other.name} ({declared}), but the printer is a "
                             f"{model.name}; slice it for this printer or pass --model")
