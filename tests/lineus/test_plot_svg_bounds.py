"""Hostile SVG whose clipping or dashing would cost unbounded time and memory: planned within a memory cap, or
refused with one clear line before the work is done."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.errors import InputError
from fabwire.lineus.plot import clip as clip_module
from fabwire.lineus.plot import parse_svg
from fabwire.lineus.plot import svg as svg_module
from fabwire.lineus.plot.clip import CLIP_PIECE_POINTS, MAX_CROSSING_RING_POINTS, cut
from fabwire.lineus.plot.svg import MAX_DRAWING_DASHES

HEAD = '<svg xmlns="http://www.w3.org/2000/svg" width="100mm" height="100mm" viewBox="0 0 100 100">'
MEMORY_CAP = 1_500_000_000
"""Address space the planning subprocess may use (the unbounded clip needed about 3 GB for 400 retraced circles)."""

RETRACED = {
    # SVG 1.1 §8.3.8 elliptical arcs: one path circling the same ring thousands of times, partly off the page.
    "arcs retracing one circle": 'M0 0 ' + ' '.join('A 50 50 0 1 1 0.001 0 A 50 50 0 1 1 0 0' for _ in range(1500)),
    # SVG 1.1 §8.3.3/§8.3.4 moveto/lineto: a zigzag over the page edge drawn back and forth.
    "lines retracing a zigzag": 'M-10 0 ' + ' '.join(f'L{x % 120 - 10} {(x * 7) % 100}' for x in range(60_000)),
    # SVG 1.1 §8.3.6 cubic Béziers: a loop across the page corner repeated.
    "curves retracing a loop": 'M-5 -5 ' + ' '.join('C 60 -40 60 60 -5 -5' for _ in range(3000)),
}


def _run_capped(code: str, source: str) -> subprocess.CompletedProcess[str]:
    """Run `code` in a Python limited to MEMORY_CAP of address space, `source` on its standard input."""
    prelude = ("import resource, sys\n"
               f"resource.setrlimit(resource.RLIMIT_AS, ({MEMORY_CAP}, {MEMORY_CAP}))\nsource = sys.stdin.read()\n")
    return subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)], input=source,
                          capture_output=True, text=True, timeout=600, check=False)


@pytest.mark.parametrize("name", sorted(RETRACED))
def test_self_retracing_stroke_is_clipped_within_a_memory_cap(name: str) -> None:
    source = f'{HEAD}<path fill="none" stroke="black" d="{RETRACED[name]}"/></svg>'
    done = _run_capped("""
        from fabwire.lineus.plot import parse_svg
        drawing = parse_svg(source)
        print(len(drawing.lines), len(drawing.hidden), max(abs(line).max() for line in drawing.lines))
    """, source)
    assert done.returncode == 0, done.stderr[-2000:]
    kept, hidden, reach = done.stdout.split()
    assert int(kept) > 0
    assert int(hidden) > 0
    width = parse_svg(f'{HEAD}<path fill="none" stroke="black" d="M0 0"/></svg>').size[0]
    assert float(reach) <= width + 1e-6


@settings(max_examples=60, deadline=None)
@given(st.integers(CLIP_PIECE_POINTS + 2, 4 * CLIP_PIECE_POINTS), st.integers(0, 2**32 - 1))
def test_cutting_long_lines_piecewise_keeps_what_one_cut_keeps(points: int, seed: int) -> None:
    steps = np.random.default_rng(seed).normal(0.0, 4.0, size=(points, 2))
    line = np.cumsum(steps, axis=0)
    region = shapely.box(-10.0, -10.0, 10.0, 10.0)
    kept, hidden = cut([line], region)
    whole = shapely.LineString(line)
    assert sum(shapely.LineString(k).length for k in kept if len(k) > 1) == pytest.approx(
        shapely.intersection(whole, region).length, rel=1e-9, abs=1e-9)
    assert sum(shapely.LineString(h).length for h in hidden if len(h) > 1) == pytest.approx(
        shapely.difference(whole, region).length, rel=1e-9, abs=1e-9)
    grown = region.buffer(1e-9)
    assert all(shapely.covers(grown, shapely.LineString(k)) for k in kept if len(k) > 1)


def test_pieces_of_one_cut_are_rejoined_at_their_seams() -> None:
    line = np.column_stack([np.linspace(1.0, 9.0, 5 * CLIP_PIECE_POINTS), np.full(5 * CLIP_PIECE_POINTS, 5.0)])
    line = np.vstack([line, [[20.0, 5.0]]])  # one step out of the region at the end
    kept, hidden = cut([line], shapely.box(0.0, 0.0, 10.0, 10.0))
    assert len(kept) == 1
    assert len(hidden) == 1
    assert kept[0][0].tolist() == [1.0, 5.0]
    assert kept[0][-1].tolist() == pytest.approx([10.0, 5.0])


DASHED = {
    # SVG 1.1 §11.4 stroke-dasharray: a tiny pattern on 49 circles (tens of millions of dashes).
    "circles": ('<g stroke="black" fill="none" stroke-dasharray="0.0001 0.0001">'
                + ''.join(f'<circle cx="50" cy="50" r="{r}"/>' for r in range(1, 50)) + '</g>', "a <circle>"),
    # The same on one line with an id, an odd count of lengths (repeated, SVG 1.1 §11.4) and a dash offset.
    "line": ('<line id="edge" x1="0" y1="50" x2="100" y2="50" stroke="black" stroke-dasharray="0.0001"'
             ' stroke-dashoffset="0.00005"/>', "<line id='edge'>"),
    # Dashes as CSS (SVG 2 §6.2 presentation attributes as properties) on a path through a scaling transform.
    "css path": ('<style>path { stroke-dasharray: 0.001px 0.001px }</style><path transform="scale(0.1)" '
                 'stroke="black" fill="none" d="M0 0 H900 V900 H0 Z"/>', "a <path>"),
}


@pytest.mark.parametrize("name", sorted(DASHED))
def test_dash_count_past_the_limit_is_refused_before_dashing(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    body, element = DASHED[name]

    def forbidden(*_: object, **__: object) -> object:
        raise AssertionError("dashes were cut although the drawing is refused")

    if name != "circles":  # one element past the limit: refused before any dash is made
        monkeypatch.setattr(svg_module, "dashed", forbidden)
    with pytest.raises(InputError) as caught:
        parse_svg(f"{HEAD}{body}</svg>")
    message = str(caught.value)
    assert element in message
    assert f"{MAX_DRAWING_DASHES:,}" in message
    assert "dashes" in message
    assert "\n" not in message


PRINT_REFUSAL = """
    from fabwire.errors import InputError
    from fabwire.lineus.plot import parse_svg
    try:
        parse_svg(source)
    except InputError as exc:
        print(exc)
"""
"""Run under the memory cap: the refusal's words on stdout (nothing when the drawing is accepted)."""


def test_dashed_circles_are_refused_within_a_memory_cap() -> None:
    body = DASHED["circles"][0]
    done = _run_capped(PRINT_REFUSAL, f"{HEAD}{body}</svg>")
    assert done.returncode == 0, done.stderr[-2000:]
    assert "dashes" in done.stdout
    assert f"{MAX_DRAWING_DASHES:,}" in done.stdout


def test_dashes_up_to_the_limit_are_drawn() -> None:
    drawing = parse_svg(f'{HEAD}<line x1="0" y1="50" x2="100" y2="50" stroke="black" stroke-dasharray="0.5 0.5"/>'
                        '</svg>')
    assert len(drawing.lines) == 100


def test_cut_into_too_many_pieces_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(clip_module, "MAX_CLIP_PARTS", 50)
    zigzag = ' '.join(f'L{x} {-10 if x % 2 else 10}' for x in range(1, 80))  # crosses the page's top edge 79 times
    with pytest.raises(InputError, match=r"^SVG text: lines too complex to clip: .* more than 50 pieces$"):
        parse_svg(f'{HEAD}<path fill="none" stroke="black" d="M0 10 {zigzag}"/></svg>')


def test_cli_refuses_hostile_dashes_in_one_line(tmp_path: Path) -> None:
    drawing = tmp_path / "dash.svg"
    drawing.write_text(f"{HEAD}{DASHED['circles'][0]}</svg>")
    done = run_cli("lineus", "preview", str(drawing), env=cli_env(tmp_path))
    assert done.returncode == InputError.exit_code
    assert "Traceback" not in done.stderr
    assert f"more than the {MAX_DRAWING_DASHES:,} allowed" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("name", sorted(RETRACED))
def test_filled_self_retracing_ring_is_refused_within_a_memory_cap(name: str) -> None:
    source = f'{HEAD}<path fill="black" stroke="black" d="{RETRACED[name]}"/></svg>'
    done = _run_capped(PRINT_REFUSAL, source)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("SVG text: a filled shape too complex to fill: a ring of ")
    assert f"(at most {MAX_CROSSING_RING_POINTS:,})" in done.stdout
