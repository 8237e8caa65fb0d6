"""Preview pictures: SVG text and PNG images of strokes, travel and the reachable area."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from fabwire.errors import InputError
from fabwire.lineus import kinematics as kin
from fabwire.lineus.render import BACKGROUND, STROKE_COLOUR, TRAVEL_COLOUR, png_size, write_drawing

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
    assert x < 500
    assert x + w > 1950
    assert y < -kin.BOUNDS[3]
    assert y + h > kin.BOUNDS[3]


def test_png_preview(tmp_path: Path) -> None:
    out = write_drawing(tmp_path / "plan.png", STROKES, TRAVEL)
    with Image.open(out) as image:
        assert image.format == "PNG"
        assert image.size == png_size()
        pixels = np.asarray(image.convert("RGB")).reshape(-1, 3)
    colours = {tuple(p) for p in np.unique(pixels, axis=0)}
    assert BACKGROUND in colours
    assert STROKE_COLOUR in colours
    assert TRAVEL_COLOUR in colours
    dark = np.count_nonzero((pixels == STROKE_COLOUR).all(axis=1))
    assert dark > 300  # about 1400 units of stroke at 0.3 px per unit, 2 px wide


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
