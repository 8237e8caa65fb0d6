"""A corpus of real slicer output: models made here (boxes, cylinders, stars with many short edges), sliced by
Debian's `prusa-slicer` from the command line at several layer heights and speeds, solid and in spiral vase mode,
each file carrying PrusaSlicer's own time estimate. Used by the estimator's tests and by `make bench`."""

from __future__ import annotations

import math
import re
import subprocess
from dataclasses import dataclass
from pathlib import Path

SLICER = "prusa-slicer"
Point = tuple[float, float]
Triangle = tuple[tuple[float, float, float], ...]


def prism(outline: list[Point], height: float) -> list[Triangle]:
    """A closed solid: the outline (counter-clockwise, star-shaped about its centroid) extruded to `height`."""
    n = len(outline)
    cx, cy = sum(p[0] for p in outline) / n, sum(p[1] for p in outline) / n
    triangles: list[Triangle] = []
    for k in range(n):
        (ax, ay), (bx, by) = outline[k], outline[(k + 1) % n]
        triangles += [((cx, cy, 0), (bx, by, 0), (ax, ay, 0)), ((cx, cy, height), (ax, ay, height), (bx, by, height)),
                      ((ax, ay, 0), (bx, by, 0), (bx, by, height)), ((ax, ay, 0), (bx, by, height), (ax, ay, height))]
    return triangles


def circle(radius: float, sides: int) -> list[Point]:
    return [(radius * math.cos(2 * math.pi * k / sides), radius * math.sin(2 * math.pi * k / sides))
            for k in range(sides)]


def star(outer: float, inner: float, points: int) -> list[Point]:
    return [((outer if k % 2 == 0 else inner) * math.cos(math.pi * k / points),
             (outer if k % 2 == 0 else inner) * math.sin(math.pi * k / points)) for k in range(2 * points)]


def write_stl(path: Path, triangles: list[Triangle]) -> None:
    facets = "".join(" facet normal 0 0 0\n  outer loop\n" + "".join(f"   vertex {x:.4f} {y:.4f} {z:.4f}\n"
                                                                     for x, y, z in t) + "  endloop\n endfacet\n"
                     for t in triangles)
    path.write_text(f"solid model\n{facets}endsolid model\n")


MODELS = {
    "box": prism([(0, 0), (20, 0), (20, 20), (0, 20)], 10),
    "cylinder": prism(circle(12, 96), 12),
    "star24": prism(star(20, 10, 24), 6),
    "star60": prism(star(25, 20, 60), 5),
}
SPEEDS = {
    "normal": [],
    "fast": ["--perimeter-speed", "80", "--infill-speed", "120", "--travel-speed", "200"],
    "slow": ["--perimeter-speed", "25", "--infill-speed", "40", "--travel-speed", "100"],
}


@dataclass(frozen=True)
class Case:
    model: str
    layer_mm: float
    speed: str
    vase: bool = False
    limits: bool = True
    """Write the machine limits into the file (M201-M205), else PrusaSlicer estimates with them unstated."""

    @property
    def name(self) -> str:
        return (f"{self.model}-{self.layer_mm}mm-{self.speed}{'-vase' if self.vase else ''}"
                f"{'' if self.limits else '-nolimits'}")


CASES = (
    *(Case(model, layer, speed) for model in MODELS for layer, speed in ((0.2, "normal"), (0.3, "fast"),
                                                                         (0.1, "slow"))),
    Case("cylinder", 0.2, "normal", vase=True), Case("star24", 0.2, "normal", vase=True),
    Case("box", 0.2, "normal", limits=False), Case("star24", 0.15, "fast", limits=False),
)


def slice_case(case: Case, folder: Path) -> Path:
    """The G-code PrusaSlicer writes for `case` (the model's STL made in `folder` first)."""
    stl = folder / f"{case.model}.stl"
    if not stl.exists():
        write_stl(stl, MODELS[case.model])
    out = folder / f"{case.name}.gcode"
    args = [SLICER, "--export-gcode", str(stl), "--output", str(out), "--layer-height", str(case.layer_mm),
            "--first-layer-height", str(max(case.layer_mm, 0.2)), *SPEEDS[case.speed]]
    if case.limits:
        args += ["--gcode-flavor", "marlin2", "--machine-limits-usage", "emit_to_gcode"]
    if case.vase:
        args += ["--spiral-vase", "--perimeters", "1", "--top-solid-layers", "0", "--fill-density", "0"]
    subprocess.run(args, check=True, capture_output=True, timeout=120)
    return out


_ESTIMATE = re.compile(rb"^; estimated printing time \(normal mode\) = ([^\n]+)$", re.MULTILINE)
_STATED = re.compile(rb"^; (?:estimated (?:first layer )?printing time|filament used|total filament)[^\n]*\n",
                     re.MULTILINE)


def prusaslicer_estimate(gcode: bytes) -> str:
    """PrusaSlicer's own time estimate as it wrote it (`1h 2m 3s`)."""
    found = _ESTIMATE.search(gcode)
    if found is None:
        raise ValueError("no PrusaSlicer estimate in the file")
    return found.group(1).decode()


def without_stated_figures(gcode: bytes) -> bytes:
    """The file with the lines that state its time and filament removed."""
    return _STATED.sub(b"", gcode)
