"""SVG `<text>` in single-stroke letters (and `--svg-text outline`), the CSS cascade and dashes on their own."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.errors import InputError
from fabwire.lineus.plot import parse_svg
from fabwire.lineus.plot.geometry import dashed
from fabwire.lineus.plot.svgtext import CAP_HEIGHT_PER_EM, FONT_FAMILIES, hershey_face

HEAD = '<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200">'


def box(text: str) -> tuple[float, float, float, float]:
    points = np.concatenate(parse_svg(f"{HEAD}{text}</svg>").lines)
    (x0, y0), (x1, y1) = points.min(axis=0), points.max(axis=0)
    return float(x0), float(y0), float(x1), float(y1)


def test_text_sits_on_its_baseline_at_its_size() -> None:
    x0, y0, _, y1 = box('<text x="20" y="100" font-size="40">HI</text>')
    assert x0 == pytest.approx(20, abs=6)  # the letters' side bearing
    assert y1 == pytest.approx(100, abs=0.5)  # capitals stand on the baseline
    assert y1 - y0 == pytest.approx(40 * CAP_HEIGHT_PER_EM, rel=0.05)


@pytest.mark.parametrize(("anchor", "share"), [("start", 0.0), ("middle", 0.5), ("end", 1.0)])
def test_text_anchor_aligns_the_chunk(anchor: str, share: float) -> None:
    x0, _, x1, _ = box(f'<text x="100" y="100" font-size="20" text-anchor="{anchor}">Anchor</text>')
    assert x0 + share * (x1 - x0) == pytest.approx(100, abs=3)


def test_tspans_start_new_chunks_and_transforms_apply() -> None:
    lines = parse_svg(f'{HEAD}<text x="10" y="30" font-size="20">one<tspan x="10" y="80">two</tspan></text>'
                      '</svg>').lines
    bottoms = sorted({round(float(line[:, 1].max())) for line in lines})
    assert bottoms[0] <= 30
    assert bottoms[-1] == 80
    turned = box('<text x="0" y="0" font-size="20" transform="translate(100 100) rotate(90)">I</text>')
    assert turned[2] - turned[0] > 5 * (turned[3] - turned[1])  # the upright I lies along x once turned
    assert turned[0] == pytest.approx(100, abs=1)


@pytest.mark.parametrize(("names", "faces", "width", "space"), FONT_FAMILIES)
def test_every_font_family_row_picks_its_faces(names: tuple[str, ...], faces: tuple[str, ...], width: float,
                                               space: float) -> None:
    for name in names:
        for index, (weight, style) in enumerate([("normal", "normal"), ("bold", "normal"), ("normal", "italic"),
                                                 ("bold", "italic")]):
            chosen = hershey_face({"font-family": f"'{name}', fantasy-unknown", "font-weight": weight,
                                   "font-style": style})
            assert chosen == (faces[index], width, space)


def test_css_cascade_specificity_important_and_inheritance() -> None:
    text = (f'{HEAD}<style>g rect {{ stroke: black }} #a {{ stroke: none }} .k {{ stroke: black !important }}'
            'g > circle { display: none }</style><g fill="none" stroke-width="2">'
            '<rect id="a" x="10" y="10" width="20" height="20"/>'
            '<rect id="b" class="k" x="50" y="10" width="20" height="20" style="stroke: none"/>'
            '<circle cx="100" cy="100" r="10" stroke="black"/></g></svg>')
    (only,) = parse_svg(text).lines
    assert only[:, 0].min() == 50


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(0.0, 30.0), min_size=1, max_size=5).filter(lambda p: sum(p) > 0.5),
       st.floats(-50.0, 50.0), st.integers(2, 6))
def test_dashes_cover_the_pattern_share_of_the_line(pattern: list[float], offset: float, corners: int) -> None:
    line = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 50.0], [30.0, 80.0], [0.0, 10.0], [60.0, 60.0]])[:corners]
    pieces = dashed(line, pattern, offset)
    lengths = [float(np.hypot(*np.diff(p, axis=0).T).sum()) if len(p) > 1 else 0.0 for p in pieces]
    total = float(np.hypot(*np.diff(line, axis=0).T).sum())
    values = pattern * (2 if len(pattern) % 2 else 1)
    period = sum(values)
    share = sum(values[0::2]) / period
    # Whole periods carry exactly the dash share; the part period at either end at most one period more or less.
    assert abs(sum(lengths) - share * total) <= period + 1e-6
    for piece in pieces:  # every dash lies on the line
        for point in piece:
            distances = [((b - a)[0] * (point - a)[1] - (b - a)[1] * (point - a)[0]) / max(np.hypot(*(b - a)), 1e-12)
                         for a, b in itertools.pairwise(line)
                         if -1e-6 <= np.dot(point - a, b - a) <= np.dot(b - a, b - a) + 1e-6]
            assert min(abs(d) for d in distances) < 1e-6


def test_svg_text_option_of_the_cli(tmp_path: Path) -> None:
    drawing = tmp_path / "label.svg"
    drawing.write_text(f'{HEAD}<rect x="10" y="10" width="180" height="180" fill="none" stroke="black"/>'
                       '<text x="100" y="100" text-anchor="middle">Label</text></svg>')
    letters = run_cli("--json", "lineus", "preview", str(drawing), env=cli_env(tmp_path))
    outline = run_cli("--json", "lineus", "preview", str(drawing), "--svg-text", "outline", env=cli_env(tmp_path))
    assert letters.returncode == 0, letters.stderr
    assert outline.returncode == 0, outline.stderr
    assert "single-stroke" in letters.stderr
    assert "left out 1 text element(s)" in outline.stderr
    wrong = run_cli("lineus", "preview", str(drawing), "--svg-text", "glyphs", env=cli_env(tmp_path))
    assert wrong.returncode != 0
    assert "Traceback" not in wrong.stderr


@settings(max_examples=150, deadline=None)
@given(st.text(alphabet="0123456789.-+ ,%empxdgrtunscalerotaeXY()!important;:{}>#.*", max_size=40),
       st.sampled_from(["stroke-dasharray", "stroke-dashoffset", "transform", "transform-origin", "font-size",
                        "x", "r", "fill", "clip-path"]))
def test_any_css_value_reads_or_is_refused_cleanly(value: str, name: str) -> None:
    escaped = value.replace("<", "").replace("&", "")
    text = (f'{HEAD}<style>g > rect {{ {name}: {escaped} }}</style><g><rect x="10" y="10" width="50" height="50" '
            f'stroke="black" style="{name}: {escaped.replace(chr(34), "")}"/><text x="5" y="90">{escaped}</text>'
            '</g></svg>')
    try:
        drawing = parse_svg(text)
    except InputError:
        return
    for line in drawing.lines:
        assert np.isfinite(line).all()


@pytest.mark.parametrize("body", [
    '<text x="1" y="50" font-size="1">' + "W" * 3_000_000 + "</text>",  # one enormous text
    ('<text x="1" y="50" font-size="1">' + "W" * 2_000 + "</text>") * 300,  # many texts, each within the bound
    '<text x="1" y="50">' + '<tspan>' + "W" * 1_000 + "</tspan>" * 1 + "</text>" * 1 + (
        '<text x="1" y="60"><tspan>' + "x" * 900 + "</tspan></text>") * 10,  # spread over tspans
])
def test_text_beyond_what_a_page_holds_is_refused_before_it_is_planned(body: str) -> None:
    from fabwire.lineus.plot.svgtext import MAX_TEXT_CHARS

    with pytest.raises(InputError, match=f"more than {MAX_TEXT_CHARS:,} characters"):
        parse_svg(f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100">{body}</svg>')


def test_text_up_to_the_bound_is_drawn() -> None:
    from fabwire.lineus.plot.svgtext import MAX_TEXT_CHARS

    drawing = parse_svg('<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100"><text x="1" y="50" '
                        f'font-size="1">{"i" * MAX_TEXT_CHARS}</text></svg>')
    assert drawing.lines


def test_a_style_sheet_beyond_any_drawings_is_refused_before_it_is_matched() -> None:
    from fabwire.lineus.plot.svgstyle import MAX_SELECTOR_CHECKS

    rules = "".join(f".c{i} path, .c{i} g, * * * * {{stroke:black}}\n" for i in range(20_000))
    body = "".join(f'<g class="c{i}"><path d="M{i % 90} 1 L{i % 90} 9"/></g>' for i in range(2_000))
    with pytest.raises(InputError, match=f"at most {MAX_SELECTOR_CHECKS:,} pairs"):
        parse_svg(f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100"><style>{rules}</style>{body}</svg>')


def test_a_style_sheet_of_a_real_drawings_size_is_applied() -> None:
    rules = "".join(f".cls-{i}{{stroke:black}}\n" for i in range(200)) + ".hide{display:none}"
    body = "".join(f'<path class="cls-{i % 200}{" hide" if i % 2 else ""}" d="M{i % 90} 1 L{i % 90} 9"/>'
                   for i in range(20_000))
    drawing = parse_svg(f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100"><style>{rules}</style>'
                        f'{body}</svg>')
    assert len(drawing.lines) == 10_000  # every other path hidden by the sheet
