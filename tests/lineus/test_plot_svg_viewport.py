"""SVG viewport geometry as a browser renders it: viewBox, width and height in any unit, preserveAspectRatio,
transform lists, nested viewports, <use> placement and hiding. A value in error is ignored (the attribute's
initial value applies), a size of zero shows nothing, and a plan holds only what lies on the page."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.errors import InputError
from fabwire.lineus.plot import parse_svg
from fabwire.lineus.plot.svgunits import FLOAT32_MAX, read_view_box, transform

HEAD = '<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" '
CROSS = '<path d="M10 10 L90 90 M10 90 L90 10" stroke="black" fill="none"/>'


def drawn_box(text: str) -> tuple[float, ...] | None:
    lines = parse_svg(text).lines
    if not lines:
        return None
    points = np.concatenate(lines)
    return tuple(round(float(v), 6) for v in (*points.min(axis=0), *points.max(axis=0)))


# -- the classes, one example each beyond the obvious -----------------------------------------------------------


@pytest.mark.parametrize(("attrs", "reason"), [
    ('width="0%" height="100"', "its width is 0"), ('width="100" height="0mm"', "its height is 0"),
    ('width="0em" height="0in"', "its width is 0"), ('width="1e-60" height="100"', "its width is 0"),
    ('width="100" height="100" viewBox="0 0 100 -0"', "its viewBox height is 0"),
    ('width="100" height="100" viewBox="0,0,1e-50,100"', "its viewBox width is 0"),
])
def test_a_size_of_zero_in_any_unit_shows_nothing_and_says_which(attrs: str, reason: str) -> None:
    drawing = parse_svg(f"{HEAD}{attrs}>{CROSS}</svg>")
    assert drawing.lines == []
    assert drawing.empty_reason == f"{reason}, which disables rendering: a browser shows nothing"


@pytest.mark.parametrize(("view_box", "why"), [
    ("0 0 -10 1e400", "a number in it is beyond what a browser can hold"),
    ("0 0 -10 100", "its width is negative"), ("0 0 100 -5", "its height is negative"),
    ("0 0 1e39 100", "a number in it is beyond what a browser can hold"),
    ("0 0 0px 100", "it is not four plain numbers"), ("0 0 100", "it is not four plain numbers"),
    ("0 0 NaN 100", "it is not four plain numbers"), ("0 0 100 100 5", "it is not four plain numbers"),
])
def test_a_viewbox_in_error_is_ignored_and_named(view_box: str, why: str) -> None:
    drawing = parse_svg(f'{HEAD}width="100" height="100" viewBox="{view_box}">{CROSS}</svg>')
    assert drawn_box(f'{HEAD}width="100" height="100" viewBox="{view_box}">{CROSS}</svg>') == (10, 10, 90, 90)
    assert drawing.notes == [f"the viewBox {view_box!r} is in error ({why}): ignored, as browsers do"]


@pytest.mark.parametrize("value", ["scale(0)", "scale(1 0)", "matrix(0 0 0 0 5 5)", "matrix(1 2 2 4 0 0)",
                                   "translate(5) scale(0 3)"])
@pytest.mark.parametrize("where", ["g", "path", "use", "nested svg"])
def test_a_transform_that_flattens_the_plane_hides_the_element(value: str, where: str) -> None:
    shape = '<path id="p" d="M10 10 L40 40" stroke="black"/>'
    body = {"g": f'<g transform="{value}">{shape}</g>',
            "path": shape.replace("<path ", f'<path transform="{value}" '),
            "use": f'<defs>{shape}</defs><use href="#p" transform="{value}"/>',
            "nested svg": f'<g transform="{value}"><svg width="50" height="50">{shape}</svg></g>'}[where]
    text = f'{HEAD}width="100" height="100">{body}<path d="M60 60 H90" stroke="black"/></svg>'
    assert drawn_box(text) == (60, 60, 90, 60)


@pytest.mark.parametrize("value", ["scale(1e400)", "scale(1e39)", "scale(2) foo", "translate(5,5) , ",
                                   "rotate(90 50)", "rotate(90deg)", "translate(5px 5px)", "Translate(5 5)",
                                   "translate()", "rotate(NaN)", "matrix(1 0 0 1 0)"])
def test_a_transform_in_error_is_ignored_and_named(value: str) -> None:
    drawing = parse_svg(f'{HEAD}width="100" height="100"><g transform="{value}">'
                        '<path d="M10 10 L40 40" stroke="black"/></g></svg>')
    assert [line.tolist() for line in drawing.lines] == [[[10, 10], [40, 40]]]
    assert len(drawing.notes) == 1
    assert drawing.notes[0].startswith(f"the transform {value!r} on <g> is in error (")


@pytest.mark.parametrize(("value", "expected"), [
    ("translate(50,50),scale(2)", [[2, 0, 50], [0, 2, 50]]), ("translate (5 6)", [[1, 0, 5], [0, 1, 6]]),
    ("scale(2)scale(3)", [[6, 0, 0], [0, 6, 0]]), ("translate(1-2)", [[1, 0, 1], [0, 1, -2]]),
    ("rotate(90,50,50)", [[0, -1, 100], [1, 0, 0]]), ("skewX(45)", [[1, 1, 0], [0, 1, 0]]),
    ("matrix(1,2,3,4,5,6)", [[1, 3, 5], [2, 4, 6]]), (" none ", [[1, 0, 0], [0, 1, 0]]),
])
def test_transform_lists_in_the_grammar(value: str, expected: list[list[float]]) -> None:
    assert np.allclose(transform(value), expected)


@pytest.mark.parametrize("value", ["scale(" + "1" * 20_000 + " x)", "translate(1" + " " * 20_000 + ",)",
                                   "scale(1)" + " ," * 10_000 + " x"])
def test_transform_lists_that_never_parse_are_refused_in_linear_time(value: str) -> None:
    with pytest.raises(ValueError, match="grammar"):
        transform(value)


@pytest.mark.parametrize(("aspect", "expected"), [
    ("foo", (30, 5, 70, 45)), ("defer xMaxYMax", (30, 5, 70, 45)), ("XMAXYMAX", (30, 5, 70, 45)),
    ("xMaxYMax meet slice", (30, 5, 70, 45)), ("xMaxYMax", (55, 5, 95, 45)), (" xMinYMax  meet ", (5, 5, 45, 45)),
])
def test_preserve_aspect_ratio_in_error_is_the_initial_value(aspect: str, expected: tuple[float, ...]) -> None:
    text = f'{HEAD}width="100" height="50" viewBox="0 0 100 100" preserveAspectRatio="{aspect}">{CROSS}</svg>'
    assert drawn_box(text) == expected


@pytest.mark.parametrize(("body", "expected"), [
    ('<path d="M50 50 L150 150" stroke="black"/>', (50, 50, 100, 100)),  # cut at the page edge
    ('<path d="M150 150 L190 190" stroke="black"/>', None),  # all beyond the page
    ('<g transform="skewX(90)"><path d="M10 10 L40 40" stroke="black"/></g>', None),  # sheared far away
    ('<defs><path id="p" d="M10 10 L40 40" stroke="black"/></defs><use href="#p" x="1e38"/>', None),
    ('<defs><path id="p" d="M10 10 L40 40" stroke="black"/></defs><use href="#p" x="1e400"/>'
     '<use href="#p" y="-1e39mm"/><path d="M0 0 L200 200" stroke="black"/>', (0, 0, 100, 100)),
])
def test_the_page_shows_no_more_than_its_box(body: str, expected: tuple[float, ...] | None) -> None:
    text = f'{HEAD}width="100" height="100" overflow="visible">{body}</svg>'
    drawing = parse_svg(text)
    assert drawn_box(text) == expected
    assert drawing.hidden  # kept apart for a preview
    assert any("outside the 100 x 100 px page are hidden" in note for note in drawing.notes)


def test_a_page_sized_by_a_percentage_is_not_cut() -> None:
    text = f'{HEAD}width="50%" height="100"><path d="M50 50 L390 90" stroke="black"/></svg>'
    assert drawn_box(text) == (50, 50, 390, 90)


@pytest.mark.parametrize(("body", "expected"), [
    ('<path d="M10 10 L40 40" fill="black"/>', None),  # a fill without area
    ('<path d="M10 10 L40 40 L70 70 Z" fill="black"/>', None),
    ('<path d="M10 10 L40 40 L10 40 Z" fill="black"/>', (10, 10, 40, 40)),
    ('<path d="M10 10 L40 40" stroke="black" stroke-width="0%"/>', None),
    ('<path d="M10 10 L40 40" stroke="black" stroke-width="-1"/>', (10, 10, 40, 40)),  # in error: width 1
    ('<g opacity="0%"><path d="M10 10 L40 40" stroke="black"/></g>', None),
    ('<path d="M10 10 L40 40" stroke="black" stroke-opacity="0%"/>', None),
    ('<path d="M10 10 L40 40 L1e39 5" stroke="black"/>', (10, 10, 40, 40)),  # drawn up to the error
])
def test_paint_and_numbers_hide_as_in_a_browser(body: str, expected: tuple[float, ...] | None) -> None:
    assert drawn_box(f'{HEAD}width="100" height="100">{body}</svg>') == expected


# -- properties over the root viewport ---------------------------------------------------------------------------

UNITS = ["", "px", "mm", "in", "em", "%", " px", "foo"]
SIZES = ["0", "-0", "0.0", "0e5", "1e-60", "-5", "7.5", "50", "150", "1e39", "1e400", "abc", "auto", ""]
VB_NUMBERS = ["0", "-0", "1e-60", "-10", "2", "10", "50", "400", "1e39", "1e400", "NaN", "5px", "50%"]


def single(text: str) -> float:
    """A number as a browser holds it (single precision); nan when it is no number."""
    try:
        value = float(text)
    except ValueError:
        return math.nan
    if not re.fullmatch(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?", text) or abs(value) > FLOAT32_MAX:
        return math.nan
    return float(np.float32(value))


def zero_length(text: str | None) -> bool:
    if text is None:
        return False
    match = re.fullmatch(r"(.*?)(px|mm|in|em|%)?", text)
    return match is not None and single(match.group(1)) == 0


def valid_view_box(parts: list[str]) -> tuple[float, ...] | None:
    numbers = [single(p) for p in parts]
    return tuple(numbers) if all(math.isfinite(n) for n in numbers) and min(numbers[2:]) >= 0 else None


@settings(max_examples=300, deadline=None)
@given(width=st.none() | st.tuples(st.sampled_from(SIZES), st.sampled_from(UNITS)).map("".join),
       height=st.none() | st.tuples(st.sampled_from(SIZES), st.sampled_from(UNITS)).map("".join),
       box=st.none() | st.lists(st.sampled_from(VB_NUMBERS), min_size=4, max_size=4),
       separator=st.sampled_from([" ", ",", " , ", "  "]))
def test_root_viewport_values_show_what_a_browser_shows(width: str | None, height: str | None,
                                                         box: list[str] | None, separator: str) -> None:
    attrs = "".join(f' {name}="{value}"' for name, value in (("width", width), ("height", height),
                                                              ("viewBox", separator.join(box) if box else None))
                    if value is not None)
    usable = valid_view_box(box) if box else None
    # Content covering the middle of the viewBox when it is usable, else of the page's user space.
    if usable and min(usable[2:]) > 0:
        x, y, w, h = usable
    else:
        x, y, w, h = 0.0, 0.0, 100.0, 100.0
    cross = (f'<path d="M{x + w / 4} {y + h / 4} L{x + 3 * w / 4} {y + 3 * h / 4}" stroke="black"/>'
             if all(map(math.isfinite, (x + w, y + h))) else "")
    try:
        drawing = parse_svg(f"<svg xmlns='http://www.w3.org/2000/svg'{attrs}>{cross}</svg>")
    except InputError:  # only for content no page can hold
        assert not cross or not math.isfinite(w * h)
        return
    nothing = zero_length(width) or zero_length(height) or bool(usable and min(usable[2:]) == 0)
    assert bool(drawing.empty_reason) == nothing
    if nothing:
        assert drawing.lines == []
        return
    for line in drawing.lines:
        assert np.isfinite(line).all()
    assert any("viewBox" in note for note in drawing.notes) == bool(box and not usable)
    page_w, page_h = drawing.size
    for line in drawing.lines:  # what is drawn lies on the page (a little slack for float rounding)
        assert (line >= -1e-6 * page_w).all()
        assert (line[:, 0] <= page_w * (1 + 1e-9)).all()
        assert (line[:, 1] <= page_h * (1 + 1e-9)).all()


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from([*VB_NUMBERS, "1", "-1", "3.5", ".5", "1e3"]), min_size=0, max_size=6),
       st.sampled_from([" ", ",", " ,", ", ", "\t"]))
def test_view_box_reading_agrees_with_a_plain_model(parts: list[str], separator: str) -> None:
    read = read_view_box(separator.join(parts))
    model = valid_view_box(parts) if len(parts) == 4 else None
    if model is None:
        assert read.box is None
        assert read.error
        assert not read.empty
    elif min(model[2:]) == 0:
        assert read.empty
        assert read.box is None
    else:
        assert read.box == model
        assert not read.error


# -- the command line -------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("attrs", "message"), [
    ('width="100" height="100" viewBox="0 0 0 100"', "nothing to draw: its viewBox width is 0, which disables "
                                                     "rendering: a browser shows nothing"),
    ('width="0mm" height="100mm"', "nothing to draw: its width is 0, which disables rendering: a browser shows "
                                   "nothing"),
])
def test_the_cli_says_why_nothing_is_drawn_in_one_line(tmp_path: Path, attrs: str, message: str) -> None:
    path = tmp_path / "drawing.svg"
    path.write_text(f"{HEAD}{attrs}>{CROSS}</svg>")
    result = run_cli("lineus", "preview", str(path), env=cli_env(tmp_path))
    assert result.returncode == 4
    assert result.stderr == f"fabwire: error: {path}: {message}\n"


def test_the_cli_draws_a_file_whose_viewbox_is_in_error_and_says_so(tmp_path: Path) -> None:
    path = tmp_path / "drawing.svg"
    path.write_text(f'{HEAD}width="100" height="100" viewBox="0 0 -10 1e400">{CROSS}</svg>')
    result = run_cli("lineus", "preview", str(path), "--json", env=cli_env(tmp_path))
    assert result.returncode == 0, result.stderr
    assert '"strokes": 2' in result.stdout
    assert "the viewBox '0 0 -10 1e400' is in error" in result.stderr

