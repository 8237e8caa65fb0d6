"""The SVG reader against the distribution's Chromium over a broad set of SVG features (tests/lineus_svg_cases.py):
each case is rendered by the browser and the plan's lines are rasterised at the same scale; the ink must agree.

What a pen draws of a browser's ink is its border: the centre line of a thin stroke, the outline of a fill. Ink is
any pixel a browser shows darker than the paper, however light or translucent its paint (one pen draws every
colour). So the browser's painted pixels are reduced to their edge (pixels with an unpainted neighbour), and the
comparison asks both ways: the plan covers the edge (recall), and the plan lies on it or where two colours meet
(precision: one pen outlines each colour's region, as it outlines an orange shape on a green one), each within
TOLERANCE_PX. Where the picture is uniform, a plan line is wrong.
Text is drawn in Hershey letters, not the browser's font: text cases compare the box the ink covers.
"""

from __future__ import annotations

import io
import os
import shutil
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageDraw, ImageFilter
from playwright.sync_api import Page, sync_playwright

from fabwire.lineus.plot import parse_svg
from fabwire.lineus.plot.svg import FEATURES
from lineus_svg_cases import CASES, TEXT_CASES

SIZE = 200
TOLERANCE_PX = 3
"""How far apart the browser's and the plan's ink may lie: anti-aliasing, line width and the chord tolerance."""
AGREEMENT = 0.95
"""The share of ink that must agree both ways for a case to match."""
VISIBLE = 8
"""A pixel darker than the paper (white) by more than this in a channel, of 255, is ink."""
COLOUR_STEP = 40
"""Neighbouring pixels whose colours differ by more than this in a channel lie where two colours meet."""


def chromium() -> str:
    found = shutil.which("chromium") or ("/usr/bin/chromium" if os.path.exists("/usr/bin/chromium") else None)
    if found is None:
        pytest.fail("the browser comparison needs Debian's chromium: run scripts/ensure-system-packages")
    return found


@pytest.fixture(scope="module")
def page() -> Iterator[Page]:
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=chromium(), args=["--no-sandbox", "--lang=en-US"])
        opened = browser.new_page(viewport={"width": SIZE, "height": SIZE}, locale="en-US")
        yield opened
        browser.close()


PAD = 2 * TOLERANCE_PX
"""Pixels around the page in both pictures: a line along the page's edge is drawn just beyond it."""


@dataclass(frozen=True)
class Picture:
    """What the browser shows, on a grid with PAD unpainted pixels around the page: `ink`, the painted pixels, and
    `meeting`, the pixels where two colours meet."""

    ink: np.ndarray
    meeting: np.ndarray


def picture(rgb: np.ndarray) -> Picture:
    """The Picture of an RGB screenshot (height x width x 3, 0..255)."""
    padded = np.pad(rgb.astype(int), ((PAD, PAD), (PAD, PAD), (0, 0)), constant_values=255)
    ink = (255 - padded).max(axis=2) > VISIBLE
    meeting = np.zeros(ink.shape, dtype=bool)
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        step = np.abs(padded - np.roll(padded, (dy, dx), axis=(0, 1))).max(axis=2) > COLOUR_STEP
        meeting |= step | np.roll(step, (-dy, -dx), axis=(0, 1))
    return Picture(ink, meeting)


def browser_ink(page: Page, tmp_path: Path, text: str) -> Picture:
    """The browser's picture of an SVG document on a SIZE x SIZE page."""
    path = tmp_path / "case.svg"
    path.write_text(text)
    page.goto(path.as_uri())
    shot = Image.open(io.BytesIO(page.screenshot())).convert("RGB")
    return picture(np.asarray(shot)[:SIZE, :SIZE])


def plan_ink(text: str) -> np.ndarray:
    """The plan's lines drawn 2 px wide, dots as 3 px discs, on the same grid as `browser_ink`."""
    image = Image.new("L", (SIZE + 2 * PAD, SIZE + 2 * PAD), 0)
    draw = ImageDraw.Draw(image)
    for line in parse_svg(text).lines:
        placed = line + PAD
        if len(placed) == 1:
            x, y = placed[0]
            draw.ellipse([x - 1.5, y - 1.5, x + 1.5, y + 1.5], fill=255)
        else:
            draw.line([tuple(p) for p in placed.tolist()], fill=255, width=2)
    return np.asarray(image) > 0


def _filter(mask: np.ndarray, kind: type[ImageFilter.MaxFilter] | type[ImageFilter.MinFilter],
            size: int) -> np.ndarray:
    image = Image.fromarray((mask * 255).astype(np.uint8))
    return np.asarray(image.filter(kind(size))) > 0


def edge(mask: np.ndarray) -> np.ndarray:
    """Painted pixels with an unpainted neighbour: the border of fills, all of a thin stroke (beyond the page is
    unpainted, so a fill the page cuts has its border along the cut)."""
    return mask & ~_filter(mask, ImageFilter.MinFilter, 3)


def near(mask: np.ndarray) -> np.ndarray:
    return _filter(mask, ImageFilter.MaxFilter, 2 * TOLERANCE_PX + 1)


def agreement(browser: Picture, plan: np.ndarray) -> tuple[float, float]:
    """(recall, precision): the share of the browser's ink edge the plan comes near, and of the plan's ink near
    that edge or where two colours meet. Both 1 when neither has ink."""
    border = edge(browser.ink)
    if not border.any() or not plan.any():
        same = float(border.any() == plan.any())
        return same, same
    recall = float((border & near(plan)).sum() / border.sum())
    precision = float((plan & near(border | browser.meeting)).sum() / plan.sum())
    return recall, precision


def test_every_feature_class_has_browser_cases() -> None:
    classes = {feature for _, feature in CASES.values()} | {"text"}
    for feature, source, case in FEATURES:
        assert case in CASES or case in TEXT_CASES, f"{feature} ({source}): no case named {case!r}"
    assert len(FEATURES) >= 20
    assert len(classes) >= 15


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_plan_draws_the_ink_chromium_shows(page: Page, tmp_path: Path, name: str) -> None:
    text, _ = CASES[name]
    recall, precision = agreement(browser_ink(page, tmp_path, text), plan_ink(text))
    assert min(recall, precision) >= AGREEMENT, f"recall {recall:.3f}, precision {precision:.3f}"


@pytest.mark.parametrize("name", sorted(TEXT_CASES))
def test_svg_text_lands_where_chromium_writes_it(page: Page, tmp_path: Path, name: str) -> None:
    text = TEXT_CASES[name]
    browser = browser_ink(page, tmp_path, text).ink
    plan = plan_ink(text)
    assert browser.any()
    assert plan.any()
    ys, xs = np.nonzero(browser)
    py, px = np.nonzero(plan)
    seen = np.array([xs.min(), ys.min(), xs.max(), ys.max()], dtype=float)
    drawn = np.array([px.min(), py.min(), px.max(), py.max()], dtype=float)
    height = seen[3] - seen[1]
    # Same place and size within a third of the letters' height; the Hershey advance may differ by a fifth.
    assert abs((drawn[1] + drawn[3]) / 2 - (seen[1] + seen[3]) / 2) < height / 3, (seen, drawn)
    assert abs((drawn[0] + drawn[2]) / 2 - (seen[0] + seen[2]) / 2) < 0.15 * (seen[2] - seen[0]) + height / 3, \
        (seen, drawn)
    assert 0.75 < (drawn[2] - drawn[0]) / (seen[2] - seen[0]) < 1.25, (seen, drawn)
