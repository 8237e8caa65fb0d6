"""Preview pictures: SVG text and PNG images of strokes, travel and the reachable area."""

from __future__ import annotations

import itertools
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from fabwire.errors import InputError
from fabwire.lineus import kinematics as kin
from fabwire.lineus.render import (
    BACKGROUND,
    HIDDEN_COLOUR,
    PNG_SCALE,
    STROKE_COLOUR,
    TRAVEL_COLOUR,
    dpi_scale,
    frame,
    png_size,
    write_drawing,
)

NS = {"svg": "http://www.w3.org/2000/svg"}
STROKES = [[(900.0, -200.0), (1500.0, -200.0), (1500.0, 400.0)], np.array([[1000.0, 800.0], [1200.0, 900.0]]),
           [(1300.0, 0.0)]]
TRAVEL = [[(1000.0, 1000.0), (900.0, -200.0)], [(1500.0, 400.0), (1000.0, 800.0)]]


def test_svg_preview(tmp_path: Path) -> None:
    out = write_drawing(tmp_path / "plan.svg", STROKES, TRAVEL, title="A & B <test>")
    root = ET.parse(out).getroot()
    assert root.tag == "{http://www.w3.org/2000/svg}svg"
    assert root.find("svg:title", NS).text == "A & B <test>"  # type: ignore[union-attr]
    strokes = root.find("svg:g[@id='strokes']", NS)
    assert strokes is not None
    polylines = strokes.findall("svg:polyline", NS)
    assert len(polylines) == 2
    assert len(strokes.findall("svg:circle", NS)) == 1
    first = [tuple(map(float, p.split(","))) for p in polylines[0].get("points", "").split()]
    assert first == [(900.0, 200.0), (1500.0, 200.0), (1500.0, -400.0)]  # y flipped: +Y is up on the page
    travel = root.find("svg:g[@id='travel']", NS)
    assert travel is not None
    assert travel.get("stroke-dasharray")
    assert len(travel.findall("svg:polyline", NS)) == 2
    area = root.find("svg:polygon[@id='reachable-area']", NS)
    assert area is not None
    outline = np.array([tuple(map(float, p.split(","))) for p in area.get("points", "").split()])
    assert outline[:, 0].min() == pytest.approx(500, abs=0.1)
    assert outline[:, 0].max() == pytest.approx(1950, abs=0.5)
    x, y, w, h = map(float, root.get("viewBox", "").split())
    assert x < kin.BODY[0]
    assert x + w > 1950
    assert y < -kin.BOUNDS[3]
    assert y + h > kin.BOUNDS[3]


def _pixel(x: float, y: float, scale: float = PNG_SCALE) -> tuple[int, int]:
    fx, fy, _, fh = frame()
    return (int((x - fx) * scale), int((fy + fh - y) * scale))


def test_png_preview(tmp_path: Path) -> None:
    out = write_drawing(tmp_path / "plan.png", STROKES, TRAVEL, hidden=[[(1600.0, -600.0), (1600.0, 600.0)]])
    with Image.open(out) as image:
        assert image.format == "PNG"
        assert image.size == png_size()
        rgb = np.asarray(image.convert("RGB")).astype(int)
    pixels = rgb.reshape(-1, 3)
    colours = {tuple(int(c) for c in p) for p in np.unique(pixels, axis=0)}
    assert BACKGROUND in colours
    assert STROKE_COLOUR in colours
    assert TRAVEL_COLOUR in colours
    # Anti-aliased: the slanting pen line (1000, 800) -> (1200, 900) fades through greys into the paper.
    px, py = _pixel(1100.0, 850.0)
    edge = rgb[py - 6 : py + 7, px, 0]
    assert edge.min() <= STROKE_COLOUR[0] + 5
    assert any(40 < v < 200 for v in edge)
    # Dashed travel: along the hop (1500, 400) -> (1000, 800) the colour switches between dash and gap.
    samples = []
    for t in np.linspace(0.05, 0.95, 200):
        x, y = 1500 + (1000 - 1500) * t, 400 + (800 - 400) * t
        px, py = _pixel(x, y)
        samples.append(tuple(rgb[py, px]))
    on = [abs(s[0] - TRAVEL_COLOUR[0]) + abs(s[2] - TRAVEL_COLOUR[2]) < 60 for s in samples]
    switches = sum(1 for a, b in itertools.pairwise(on) if a != b)
    assert switches >= 10  # about 640 units of hop in 50-unit dash periods
    assert 0.3 < sum(on) / len(on) < 0.9
    # Hidden (clipped) lines are faint grey, never ink.
    hx, hy = _pixel(1600.0, 0.0)
    darkest = rgb[hy - 2 : hy + 3, hx - 2 : hx + 3].sum(axis=2).min()
    assert sum(HIDDEN_COLOUR) - 30 <= darkest < sum((235, 242, 250)) - 30
    # The body and the scale bar are drawn.
    bx, by = _pixel(0.0, 0.0)
    assert tuple(rgb[by, bx]) != BACKGROUND
    dark_rows = np.nonzero((rgb[:, :40] < 40).all(axis=2).any(axis=1))[0]
    assert len(dark_rows) > 0  # the scale bar's start, at the left edge


def test_png_resolution_follows_dpi(tmp_path: Path) -> None:
    low = write_drawing(tmp_path / "low.png", STROKES, scale=dpi_scale(75))
    high = write_drawing(tmp_path / "high.png", STROKES, scale=dpi_scale(300))
    with Image.open(low) as a, Image.open(high) as b:
        assert b.size[0] == pytest.approx(4 * a.size[0], abs=4)
        assert b.size[1] == pytest.approx(4 * a.size[1], abs=4)
    _, _, w, _ = frame()
    assert high.stat().st_size > low.stat().st_size
    assert Image.open(high).size[0] == pytest.approx(w / 20 / 25.4 * 300, abs=1)
    with pytest.raises(InputError, match="dpi"):
        dpi_scale(5000)


def test_svg_preview_outlines_body_app_area_and_hidden_parts(tmp_path: Path) -> None:
    out = write_drawing(tmp_path / "plan.svg", STROKES, TRAVEL, hidden=[[(1600.0, -600.0), (1600.0, 600.0)]])
    root = ET.parse(out).getroot()
    for ident in ("body", "app-area", "hidden", "scale-bar"):
        assert root.find(f".//*[@id='{ident}']", NS) is not None, ident
    app = root.find("svg:polyline[@id='app-area']", NS)
    assert app is not None
    corners = {tuple(map(float, p.split(","))) for p in app.get("points", "").split()}
    assert corners == {(650.0, 1000.0), (1775.0, 1000.0), (1775.0, -1000.0), (650.0, -1000.0)}
    x = float(root.get("viewBox", "").split()[0])
    assert x < kin.BODY[0]


def test_png_scale_and_empty_drawing(tmp_path: Path) -> None:
    out = write_drawing(tmp_path / "big.png", [], scale=0.5)
    with Image.open(out) as image:
        assert image.size == png_size(0.5)
        assert image.size[0] > png_size()[0]


def test_bad_preview_paths(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"\.svg or \.png"):
        write_drawing(tmp_path / "plan.pdf", STROKES)
    with pytest.raises(InputError, match="cannot write"):
        write_drawing(tmp_path / "missing-dir" / "plan.svg", STROKES)
