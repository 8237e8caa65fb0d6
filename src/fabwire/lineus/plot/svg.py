"""SVG files to polylines: every visible shape's outline (paths, basic shapes, `<use>` copies), with all
transforms applied and curves flattened to a chord tolerance. Output is in SVG user units, y down."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import svgelements as se

from fabwire.errors import InputError
from fabwire.lineus.plot.geometry import Polylines

RELATIVE_TOLERANCE = 2e-4
"""Chord tolerance, as a share of the page diagonal, when none is given: about 0.7 machine units once a page
is fitted into the drawing area."""
MAX_CURVE_POINTS = 4096


@dataclass
class SvgDrawing:
    lines: Polylines
    skipped: dict[str, int] = field(default_factory=dict)
    """Elements that hold nothing a pen can draw (text, images), by tag."""


def _visible(element: se.Shape) -> bool:
    values = element.values
    if str(values.get("visibility", "visible")) in ("hidden", "collapse"):
        return False
    if str(values.get("display", "inline")) == "none":
        return False
    stroke = element.stroke
    fill = element.fill
    has_stroke = stroke is not None and stroke.value is not None and stroke.alpha != 0
    has_fill = fill is not None and fill.value is not None and fill.alpha != 0
    return has_stroke or has_fill


def _curve_steps(seg: se.PathSegment, tolerance: float) -> int:
    """Subdivisions keeping the chord error under `tolerance` (Wang's bound for Béziers, sagitta for arcs)."""
    if isinstance(seg, se.CubicBezier):
        p = [complex(q.x, q.y) for q in (seg.start, seg.control1, seg.control2, seg.end)]
        m = max(abs(p[0] - 2 * p[1] + p[2]), abs(p[1] - 2 * p[2] + p[3]))
        n = math.sqrt(0.75 * m / tolerance)
    elif isinstance(seg, se.QuadraticBezier):
        p = [complex(q.x, q.y) for q in (seg.start, seg.control, seg.end)]
        n = math.sqrt(0.25 * abs(p[0] - 2 * p[1] + p[2]) / tolerance)
    elif isinstance(seg, se.Arc):
        radius = max(abs(seg.rx), abs(seg.ry), 1e-12)
        n = 2.0 if tolerance >= radius else abs(seg.sweep) / (2 * math.acos(1 - tolerance / radius))
    else:
        n = 16.0
    if not math.isfinite(n):
        n = 1.0
    return max(1, min(MAX_CURVE_POINTS, math.ceil(n)))


def _path_lines(path: se.Path, tolerance: float) -> Polylines:
    out: Polylines = []
    current: list[tuple[float, float]] = []
    start: tuple[float, float] | None = None

    def flush() -> None:
        nonlocal current
        if current:
            out.append(np.asarray(current, dtype=float))
        current = []

    for seg in path:
        if isinstance(seg, se.Move):
            flush()
            if seg.end is not None:
                start = (float(seg.end.x), float(seg.end.y))
                current = [start]
            continue
        if seg.start is None or seg.end is None:
            continue
        if not current:
            current = [(float(seg.start.x), float(seg.start.y))]
            start = current[0]
        if isinstance(seg, se.Close):
            if start is not None:
                current.append(start)
            flush()
            continue
        if isinstance(seg, se.Line):
            current.append((float(seg.end.x), float(seg.end.y)))
            continue
        n = _curve_steps(seg, tolerance)
        pts = seg.npoint(np.linspace(0.0, 1.0, n + 1)[1:])
        current.extend((float(x), float(y)) for x, y in np.asarray(pts, dtype=float))
    flush()
    return [line for line in out if np.all(np.isfinite(line))]


def parse_svg(source: str | Path, *, tolerance: float | None = None) -> SvgDrawing:
    """Read an SVG file (or text starting with '<') into outline polylines in user units."""
    if tolerance is not None and not tolerance > 0:
        raise InputError(f"curve tolerance must be positive, got {tolerance}")
    name = "SVG text" if isinstance(source, str) and source.lstrip().startswith("<") else str(source)
    try:
        if name == "SVG text":
            import io

            stream: object = io.StringIO(str(source))
        else:
            stream = str(source)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            svg = se.SVG.parse(stream, reify=True, ppi=se.DEFAULT_PPI)
    except FileNotFoundError as exc:
        raise InputError(f"{name}: no such file") from exc
    except OSError as exc:
        raise InputError(f"{name}: cannot read ({exc.strerror or exc})") from exc
    except Exception as exc:  # svgelements surfaces XML and attribute errors as assorted exception types
        raise InputError(f"{name}: not a readable SVG ({type(exc).__name__}: {exc})") from exc
    drawing = SvgDrawing([])
    if tolerance is None:
        width = _length(getattr(svg, "width", None))
        height = _length(getattr(svg, "height", None))
        tolerance = RELATIVE_TOLERANCE * (math.hypot(width, height) or 1000.0)
    try:
        for element in svg.elements():
            if isinstance(element, se.Shape):
                if not _visible(element):
                    continue
                if isinstance(element, se.Path):
                    path = element  # parsed with reify=True: the transform is already in the points
                    if not path.transform.is_identity():
                        path = se.Path(element)
                        path.reify()
                else:
                    path = se.Path(element)
                    path.reify()
                drawing.lines.extend(_path_lines(path, tolerance))
            elif isinstance(element, se.Text | se.Image):
                tag = "text" if isinstance(element, se.Text) else "image"
                drawing.skipped[tag] = drawing.skipped.get(tag, 0) + 1
    except (ValueError, TypeError, ZeroDivisionError, AttributeError) as exc:
        raise InputError(f"{name}: malformed SVG geometry ({exc})") from exc
    return drawing


def _length(value: object) -> float:
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return 0.0
    return number if math.isfinite(number) and number > 0 else 0.0
