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
