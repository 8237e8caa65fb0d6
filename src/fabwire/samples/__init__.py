"""Sample files bundled with fabwire: a small print and a drawing, used by the demo and the docs."""

from __future__ import annotations

from importlib.resources import as_file, files
from pathlib import Path

SAMPLE_GCODE = "calibration-square.gcode"
SAMPLE_SVG = "fabwire-logo.svg"


def sample_path(name: str) -> Path:
    """The bundled file's path on disk (samples ship as plain files inside the package)."""
    with as_file(files(__name__) / name) as path:
        return Path(path)


SAMPLES = (SAMPLE_GCODE, SAMPLE_SVG)
"""Every file the README's tour uses."""


def write_samples(directory: Path, *, overwrite: bool = False) -> list[Path]:
    """Copy every sample into `directory` (created if needed); returns the paths written.

    Raises InputError when a file of that name with other content is there and `overwrite` is false.
    """
    from fabwire.errors import InputError

    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create {directory}: {exc.strerror}") from exc
    written = []
    for name in SAMPLES:
        data = (files(__name__) / name).read_bytes()
        target = directory / name
        if target.exists() and not overwrite and target.read_bytes() != data:
            raise InputError(f"{target} exists with other content: add --force to replace it")
        try:
            target.write_bytes(data)
        except OSError as exc:
            raise InputError(f"cannot write {target}: {exc.strerror}") from exc
        written.append(target)
    return written
