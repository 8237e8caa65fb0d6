"""What the simulated printer keeps across power cycles, and its `--state FILE`: read with the limits the printer's
own commands have, so no file can make the simulator answer with something a printer could never hold."""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Annotated, Literal

import msgspec

from fabwire.errors import InputError
from fabwire.files import read_bounded
from fabwire.xyz.userinput import LANGUAGES, PRINTER_NAME_LIMIT, SSID_LIMIT

MAX_STATE_BYTES = 1 << 16
"""A state file is a few hundred bytes; a larger one is refused unread."""

_Count = Annotated[int, msgspec.Meta(ge=0, le=2**31 - 1)]
_Reading = Annotated[int, msgspec.Meta(ge=0, le=65_535)]
_Language = Literal[LANGUAGES]  # type: ignore[valid-type]


class _Stored(msgspec.Struct, forbid_unknown_fields=False):
    """The file's fields, each optional and held to what the wire commands allow (`config=name:[…]` takes 16
    printable ASCII characters, `energy` 0-9 minutes, `zoffset:set` up to 6 digits; see fabwire.xyz.userinput)."""

    name: Annotated[str, msgspec.Meta(max_length=PRINTER_NAME_LIMIT, pattern=r"^[ -Z\\^-~]*\Z")] | msgspec.UnsetType = (
        msgspec.UNSET)
    language: _Language | msgspec.UnsetType = msgspec.UNSET
    energy: Annotated[int, msgspec.Meta(ge=0, le=9)] | msgspec.UnsetType = msgspec.UNSET
    buzzer: bool | msgspec.UnsetType = msgspec.UNSET
    autolevel: bool | msgspec.UnsetType = msgspec.UNSET
    zoffset: Annotated[int, msgspec.Meta(ge=-999_999, le=999_999)] | msgspec.UnsetType = msgspec.UNSET
    calibration: Annotated[list[_Reading], msgspec.Meta(min_length=9, max_length=9)] | msgspec.UnsetType = (
        msgspec.UNSET)
    machine_min: _Count | msgspec.UnsetType = msgspec.UNSET
    extruder_min: _Count | msgspec.UnsetType = msgspec.UNSET
    filament_mm: _Count | msgspec.UnsetType = msgspec.UNSET
    filament2_mm: _Count | msgspec.UnsetType = msgspec.UNSET
    ssid: Annotated[str, msgspec.Meta(max_length=SSID_LIMIT, pattern=r"^[^,\[\]\x00-\x1f\x7f\ud800-\udfff]*\Z")] | (
        msgspec.UnsetType) = msgspec.UNSET
    ip: Annotated[str, msgspec.Meta(max_length=45, pattern=r"^[0-9A-Fa-f.:]*\Z")] | msgspec.UnsetType = msgspec.UNSET


@dataclass
class Settings:
    """What a real printer keeps across power cycles (and the simulator in `--state FILE`)."""

    name: str = ""
    language: str = "en"
    energy: int = 3
    buzzer: bool = True
    autolevel: bool = True
    zoffset: int = 245
    calibration: list[int] = field(default_factory=lambda: [336, 374, 377, 355, 373, 371, 364, 377, 356])
    machine_min: int = 301080
    extruder_min: int = 28581
    filament_mm: int = 200000
    filament2_mm: int = 120000
    """The second spool of a two-spool model (Jr. 2.0 Mix)."""
    ssid: str = "TUCKER_HOME"
    ip: str = "192.168.1.118"

    @classmethod
    def load(cls, path: Path | None, defaults: Settings) -> Settings:
        """`defaults` with what the state file at `path` holds (a missing file holds nothing); anything else than
        a JSON object of valid settings, at most MAX_STATE_BYTES, is an InputError naming the file."""
        if path is None:
            return defaults
        if "\0" in os.fspath(path):
            raise InputError(f"simulator state file {str(path)!r}: a file name cannot hold a NUL character")
        if not path.exists():
            return defaults
        try:
            raw = read_bounded(path, MAX_STATE_BYTES)
        except OSError as exc:
            raise InputError(f"cannot read simulator state {path}: {exc.strerror or exc}") from exc
        if raw is None:
            raise InputError(f"simulator state {path} is over {MAX_STATE_BYTES} bytes: not a state file")
        try:
            stored = msgspec.json.decode(raw, type=_Stored)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            raise InputError(f"simulator state {path} is not usable: {exc}") from None
        except RecursionError:
            raise InputError(f"simulator state {path} is not usable: nested too deeply") from None
        given = {f.name: getattr(stored, f.name) for f in fields(cls)
                 if getattr(stored, f.name) is not msgspec.UNSET}
        return replace(defaults, **given)

    def save(self, path: Path | None) -> None:
        if path is None:
            return
        tmp = path.with_suffix(path.suffix + ".tmp")
        tmp.write_text(msgspec.json.format(msgspec.json.encode(asdict(self)).decode(), indent=1))
        tmp.replace(path)
