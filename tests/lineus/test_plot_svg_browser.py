"""The SVG reader against the distribution's Chromium: for viewport, transform and hiding cases, the plan draws
where the browser paints and nothing where it paints nothing (compared by the painted pixels' bounding box)."""

from __future__ import annotations

import io
import os
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from playwright.sync_api import Page, sync_playwright

from fabwire.lineus.plot import parse_svg

HEAD = '<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" '
LINE = '<path d="M10 10 L40 40" stroke="black" stroke-width="2"/>'
CASES = {
    "viewBox negative and beyond a float": ('width="100" height="100" viewBox="0 0 -10 1e400"', LINE),
    "viewBox width 0": ('width="100" height="100" viewBox="0 0 0 100"', LINE),
    "viewBox with units": ('width="100" height="100" viewBox="0 0 0px 100"', LINE),
    "width 0 %": ('width="0%" height="100"', LINE),
    "height 0 mm": ('width="100" height="0mm"', LINE),
    "scale(1 0)": ('width="100" height="100"', f'<g transform="scale(1 0)">{LINE}</g>'),
    "singular matrix": ('width="100" height="100"', f'<g transform="matrix(1 1 1 1 0 0)">{LINE}</g>'),
    "transform in error": ('width="100" height="100"', f'<g transform="scale(2) foo">{LINE}</g>'),
    "transform beyond a float": ('width="100" height="100"', f'<g transform="scale(1e39)">{LINE}</g>'),
    "aspect in error": ('width="100" height="50" viewBox="0 0 100 100" preserveAspectRatio="defer xMaxYMax"',
                        LINE),
    "slice cut by the page": ('width="100" height="50" viewBox="0 0 100 100" preserveAspectRatio="xMinYMin slice"',
                              '<path d="M10 10 L90 90" stroke="black" stroke-width="2"/>'),
    "beyond the page": ('width="100" height="100" overflow="visible"',
                        '<path d="M50 50 L190 190" stroke="black" stroke-width="2"/>'),
    "nested viewport in %": ('width="200" height="200"',
                             f'<svg x="50%" y="25%" width="25%" height="25%" viewBox="0 0 50 50">{LINE}</svg>'),
    "use x beyond a float": ('width="200" height="200"',
                             f'<defs><g id="p">{LINE}</g></defs><use href="#p" x="1e400"/><use href="#p" y="-1e39"/>'),
    "use x y": ('width="200" height="200"', f'<defs><g id="p">{LINE}</g></defs><use href="#p" x="50" y="60"/>'),
    "fill without area": ('width="100" height="100"', '<path d="M10 10 L40 40" fill="black"/>'),
    "opacity 0 %": ('width="100" height="100"', f'<g opacity="0%">{LINE}</g>'),
    "path number beyond a float": ('width="100" height="100"',
                                   '<path d="M10 10 L40 40 L1e39 5" stroke="black" stroke-width="2"/>'),
}


def chromium() -> str:
    found = shutil.which("chromium") or ("/usr/bin/chromium" if os.path.exists("/usr/bin/chromium") else None)
    if found is None:
        pytest.fail("the browser comparison needs Debian's chromium: run scripts/ensure-system-packages")
    return found


@pytest.fixture(scope="module")
def page() -> Iterator[Page]:
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=chromium(), args=["--no-sandbox"])
        opened = browser.new_page(viewport={"width": 300, "height": 300})
        yield opened
        browser.close()


def painted_box(page: Page, path: Path) -> tuple[int, ...] | None:
    page.goto(path.as_uri())
    dark = np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("L")) < 160
    ys, xs = np.nonzero(dark)
    return (int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max())) if len(xs) else None


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_plan_draws_where_chromium_paints(page: Page, tmp_path: Path, name: str) -> None:
    attrs, body = CASES[name]
    text = f"{HEAD}{attrs}>{body}</svg>"
    path = tmp_path / "case.svg"
    path.write_text(text)
    painted = painted_box(page, path)
    lines = parse_svg(text).lines
    if painted is None or not lines:
        assert painted is None, f"Chromium paints {painted}, the plan has nothing"
        assert not lines, "Chromium paints nothing, the plan has lines"
        return
    points = np.concatenate(lines)
    planned = (*points.min(axis=0), *points.max(axis=0))
    # The pen follows the stroke's centre line; the browser paints 1 px either side of it and rounds to pixels.
    assert np.allclose(planned, painted, atol=2.0), (planned, painted)
