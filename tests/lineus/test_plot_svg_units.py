"""SVG lengths in every CSS unit (svgunits.length): font-relative units against the faces Chromium uses for each
FONT_METRICS row (measured in the browser with getBBox), viewport units of the page, lengths in error; and paint
servers that are not rendered, and the bounding box of children that show nothing, through parse_svg."""

from __future__ import annotations

import math
import os
import shutil
from collections.abc import Iterator

import pytest
from hypothesis import example, given
from hypothesis import strategies as st
from playwright.sync_api import Page, sync_playwright

from fabwire.lineus.plot import parse_svg
from fabwire.lineus.plot.svgunits import (
    ABSOLUTE_UNITS,
    FONT_METRICS,
    Font,
    css_transform,
    font_metrics,
    length,
    line_height,
)

FONT_UNITS = ("ex", "ch", "cap", "lh", "ic")
VIEWPORT_UNITS = {"vw": 3.0, "vi": 3.0, "vh": 1.0, "vb": 1.0, "vmin": 1.0, "vmax": 3.0}
"""px per unit on a 300 x 100 px page."""
FAMILIES = [(name, row) for row in FONT_METRICS for name in row[0]]
HINTED_BELOW_PX = 100
"""Below this size Chromium grid-fits the x-height and cap height of the hinted DejaVu faces to whole px (within
1 px of the table's value); the unhinted Noto faces follow the table at every size."""


def font_metrics_row(family: str) -> tuple[str, ...]:
    return next((row[0] for row in FONT_METRICS if family in row[0]), ())


def chromium() -> str:
    found = shutil.which("chromium") or ("/usr/bin/chromium" if os.path.exists("/usr/bin/chromium") else None)
    if found is None:
        pytest.fail("the unit measurements need Debian's chromium: run scripts/ensure-system-packages")
    return found


@pytest.fixture(scope="module")
def page() -> Iterator[Page]:
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=chromium(), args=["--no-sandbox", "--lang=en-US"])
        yield browser.new_page(viewport={"width": 300, "height": 100}, locale="en-US")
        browser.close()


@pytest.mark.parametrize(("family", "row"), FAMILIES, ids=[name for name, _ in FAMILIES])
def test_font_units_are_the_metrics_chromium_uses_for_the_family(page: Page, family: str,
                                                                 row: tuple[object, ...]) -> None:
    rects = "".join(f'<rect id="{u}" width="100{u}" height="1"/>' for u in FONT_UNITS)
    for size in (13, 32, 64, 100):
        page.set_content(f'<svg xmlns="http://www.w3.org/2000/svg" width="300" height="100" font-size="{size}" '
                         f'font-family="{family}">{rects}</svg>')
        for unit in FONT_UNITS:
            measured = page.evaluate(f"document.getElementById('{unit}').getBBox().width") / 100
            ours = length(f"1{unit}", 0.0, font_size=Font(float(size), family))
            if size < HINTED_BELOW_PX and unit in ("ex", "cap") and "dejavu" in str(font_metrics_row(family)):
                assert abs(ours - measured) <= 1.0, (family, size, unit)  # grid-fitted by the face's hinting
            else:
                assert ours == pytest.approx(measured, rel=0.005), (family, size, unit)
    assert list(font_metrics(family).values()) == list(row[1:])


def test_an_unknown_family_falls_back_to_the_first_row_and_a_list_takes_its_first_known_face() -> None:
    assert font_metrics("No Such Face") == font_metrics(FONT_METRICS[0][0][0])
    assert font_metrics("'No Such Face', \"DejaVu Sans Mono\", serif") == font_metrics("monospace")


@pytest.mark.parametrize(("unit", "px"), sorted(VIEWPORT_UNITS.items()))
def test_viewport_units_are_of_the_page(unit: str, px: float) -> None:
    drawing = parse_svg(f'<svg xmlns="http://www.w3.org/2000/svg" width="300" height="100">'
                        f'<line x1="0" y1="1" x2="10{unit}" y2="1" stroke="black"/></svg>')
    assert drawing.lines[0][-1, 0] == pytest.approx(10 * px)


def test_rem_and_rlh_are_of_the_root_font() -> None:
    drawing = parse_svg('<svg xmlns="http://www.w3.org/2000/svg" width="300" height="300" font-size="20" '
                        'font-family="DejaVu Sans"><g font-size="50" font-family="serif">'
                        '<line x1="1rem" y1="1rlh" x2="2em" y2="1lh" stroke="black"/></g></svg>')
    (x1, y1), (x2, y2) = drawing.lines[0]
    assert (x1, y1) == pytest.approx((20, line_height(20, "DejaVu Sans")))
    assert (x2, y2) == pytest.approx((100, line_height(50, "serif")))


@pytest.mark.parametrize("unit", sorted(ABSOLUTE_UNITS))
def test_absolute_units(unit: str) -> None:
    assert length(f" 2.5{unit.upper()} ", 0.0) == pytest.approx(2.5 * ABSOLUTE_UNITS[unit])


@given(st.from_regex(r"[a-zA-Z]{1,5}", fullmatch=True))
def test_a_length_with_an_unknown_unit_is_in_error(unit: str) -> None:
    known = {*ABSOLUTE_UNITS, *FONT_UNITS, *VIEWPORT_UNITS, "em", "rem", "rlh"}
    value = length(f"12{unit}", 50.0, default=-7.0, font_size=Font(10.0, viewport=(300.0, 100.0)))
    assert (value == -7.0) == (unit.lower() not in known)


@pytest.mark.parametrize("text", ["44mmx", "4 0", "1e", "px", "10 px", "--3", "3%%", "", "nan", "1e999"])
def test_lengths_in_error_take_the_default(text: str) -> None:
    assert length(text, 100.0, default=-1.0) == -1.0


def test_viewport_units_without_a_page_are_in_error() -> None:
    assert math.isnan(length("10vw", 0.0, default=math.nan))


@pytest.mark.parametrize("where", ['<defs display="none">{}</defs>', '<g style="display: none">{}</g>',
                                   '<g systemLanguage="x-none">{}</g>', '<defs requiredExtensions="x">{}</defs>',
                                   '<defs><g><g display="none"><g>{}</g></g></g></defs>', "its own display"])
@pytest.mark.parametrize("server", ['<linearGradient id="p"{}><stop/></linearGradient>',
                                    '<radialGradient id="p"{}><stop/></radialGradient>',
                                    '<pattern id="p" width="5" height="5"{}><rect width="2" height="2"/></pattern>'])
@pytest.mark.parametrize("fallback", ["", " black"])
def test_a_paint_server_that_is_not_rendered_paints_only_the_fallback(where: str, server: str,
                                                                      fallback: str) -> None:
    body = server.format(' display="none"') if where == "its own display" else where.format(server.format(""))
    drawing = parse_svg(f'<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">{body}'
                        f'<rect x="10" y="10" width="50" height="50" fill="url(#p){fallback}"/></svg>')
    assert len(drawing.lines) == (1 if fallback else 0)


def test_conditions_on_the_paint_server_itself_are_not_processed() -> None:
    drawing = parse_svg('<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">'
                        '<linearGradient id="p" systemLanguage="x-none"><stop/></linearGradient>'
                        '<rect x="10" y="10" width="50" height="50" fill="url(#p)"/></svg>')
    assert len(drawing.lines) == 1


@pytest.mark.parametrize("ghost", ['visibility="hidden"', 'opacity="0"', 'fill="none"', 'visibility="collapse"',
                                   'style="opacity: 0"'])
def test_children_that_show_nothing_count_for_the_bounding_box(ghost: str) -> None:
    drawing = parse_svg('<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200">'
                        '<clipPath id="c" clipPathUnits="objectBoundingBox"><rect width="0.5" height="1"/>'
                        f'</clipPath><g clip-path="url(#c)"><rect x="0" y="0" width="200" height="200" {ghost}/>'
                        '<line x1="0" y1="100" x2="200" y2="100" stroke="black"/></g></svg>')
    assert drawing.lines[0][:, 0].max() == pytest.approx(100)


def test_a_fill_in_a_translucent_group_hides_the_groups_lines_not_those_under_the_group() -> None:
    drawing = parse_svg('<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200">'
                        '<line x1="0" y1="50" x2="200" y2="50" stroke="black"/>'
                        '<g opacity="0.5"><line x1="0" y1="150" x2="200" y2="150" stroke="black"/>'
                        '<rect x="50" y="0" width="100" height="200"/></g></svg>')
    on = {y: sorted(round(float(x)) for line in drawing.lines for x, yy in line if round(float(yy)) == y)
          for y in (50, 150)}
    assert on[50] == [0, 200]  # painted before the group: shows through it
    assert on[150] == [0, 50, 150, 200]  # painted in the group before the fill: hidden under it


@pytest.mark.parametrize(("transform", "origin", "box"), [
    ("translate(20 10)", "", (60, 50, 120, 110)),
    ("scale(2)", "", (80, 80, 160, 160)),
    ("scale(2)", "center", (40, 40, 100, 100)),  # about the centre of the viewport, its reference box
])
def test_a_clip_path_transform_is_in_user_space_outside_bounding_box_units(transform: str, origin: str,
                                                                           box: tuple[int, ...]) -> None:
    drawing = parse_svg('<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200">'
                        f'<clipPath id="c" clipPathUnits="objectBoundingBox" transform="{transform}" '
                        f'transform-origin="{origin}"><rect x="0" y="0" width="0.5" height="0.5"/></clipPath>'
                        '<rect x="40" y="40" width="120" height="120" clip-path="url(#c)"/></svg>')
    points = [p for line in drawing.lines for p in line.tolist()]
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    assert (min(xs), min(ys), max(xs), max(ys)) == pytest.approx(box)


@given(st.sampled_from(["rotate", "translate", "scale", "skewX", "matrix"]),
       st.tuples(st.text(alphabet="1a.e-xpdgt ,", min_size=1, max_size=6), st.integers(1, 3000)).map(
           lambda t: t[0] * t[1]))
@example("rotate", "a" * 5000)
@example("translate", "1px" * 2000)
def test_a_css_transform_in_error_is_told_in_one_short_line(name: str, args: str) -> None:
    message = ""
    try:
        css_transform(f"{name}({args})", (100.0, 100.0))
    except ValueError as e:
        message = str(e)
    assert len(message) <= 120
