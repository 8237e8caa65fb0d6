"""The print time estimator against PrusaSlicer's own estimate, on a corpus Debian's `prusa-slicer` slices here
(the stated figures removed first, so the estimate is fabwire's own)."""

from __future__ import annotations

import io
import statistics
import sys
import tempfile
from pathlib import Path

from common import Figure

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from fabwire.xyz import intake
from fabwire.xyz.slicerfigures import read_value
from prusaslicer_corpus import CASES, prusaslicer_estimate, slice_case, without_stated_figures

TARGET_PERCENT = 5.0


def run() -> list[Figure]:
    errors: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as scratch:
        for case in CASES:
            sliced = slice_case(case, Path(scratch)).read_bytes()
            theirs = read_value(prusaslicer_estimate(sliced).encode(), "duration")
            _stated, computed = intake.stream_metadata(io.BytesIO(without_stated_figures(sliced)), case.name)
            if theirs is None or computed is None or computed.print_time_s is None:
                raise RuntimeError(f"{case.name}: no estimate to compare")
            errors[case.name] = 100.0 * abs(computed.print_time_s - theirs) / theirs
    worst = max(errors, key=errors.__getitem__)
    median = statistics.median(errors.values())
    return [
        Figure(f"time estimate vs PrusaSlicer, worst of {len(errors)} files ({worst})", errors[worst], "%",
               f"<= {TARGET_PERCENT:.0f}", errors[worst] <= TARGET_PERCENT),
        Figure(f"time estimate vs PrusaSlicer, median of {len(errors)} files", median, "%",
               f"<= {TARGET_PERCENT:.0f}", median <= TARGET_PERCENT),
    ]


if __name__ == "__main__":
    for figure in run():
        print(f"{figure.name:70s} {figure.value:8.2f} {figure.unit} {figure.target}")
