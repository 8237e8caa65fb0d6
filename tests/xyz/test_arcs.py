"""G2/G3 arcs written as G1 segments within 0.01 mm of the arc when converting (Marlin's arc rules), or kept."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.xyz.arcwork import MOST_SEGMENTS, TOLERANCE_MM, ArcExpander, segments
from fabwire.xyz.threew import convert_gcode_file, read_3w

MOVE = re.compile(r"G1 X(-?[0-9.]+) Y(-?[0-9.]+)(?: Z(-?[0-9.]+))?(?: E(-?[0-9.]+))?")


def points(lines: list[str]) -> list[tuple[float, ...]]:
    out = []
    for line in lines:
        found = MOVE.match(line)
        assert found, line
        out.append(tuple(float(v) if v is not None else math.nan for v in found.groups()))
    return out


def sagitta_ok(start: tuple[float, float], pts: list[tuple[float, ...]], centre: tuple[float, float],
               radius: float) -> None:
    """Every vertex on the circle, every chord within the tolerance of it."""
    previous = start
    for p in pts:
        assert math.hypot(p[0] - centre[0], p[1] - centre[1]) == pytest.approx(radius, abs=1e-3)
        chord = math.hypot(p[0] - previous[0], p[1] - previous[1])
        assert radius - math.sqrt(max(0.0, radius * radius - chord * chord / 4)) <= TOLERANCE_MM + 1e-4
        previous = (p[0], p[1])


@settings(max_examples=100, deadline=None)
@given(radius=st.floats(0.5, 120), start=st.floats(0, 2 * math.pi), sweep=st.floats(0.05, 2 * math.pi - 0.05),
       clockwise=st.booleans())
def test_segments_stay_within_the_tolerance(radius: float, start: float, sweep: float, clockwise: bool) -> None:
    cx, cy = 100.0, 100.0
    x0, y0 = cx + radius * math.cos(start), cy + radius * math.sin(start)
    end = start - sweep if clockwise else start + sweep
    x1, y1 = cx + radius * math.cos(end), cy + radius * math.sin(end)
    lines = segments((x0, y0, 0.2, 5.0), {b"X": x1, b"Y": y1, b"I": cx - x0, b"J": cy - y0, b"E": 6.0}, clockwise)
    assert lines is not None
    pts = points(lines)
    sagitta_ok((x0, y0), pts, (cx, cy), radius)
    assert pts[-1][:2] == pytest.approx((x1, y1), abs=1e-4)
    assert pts[-1][3] == pytest.approx(6.0)
    travelled = sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip([(x0, y0), *pts], pts, strict=False))
    half = math.acos(max(-1.0, 1 - TOLERANCE_MM / radius))  # chords are this much shorter at most
    rounding = len(pts) * 2e-4  # coordinates are written with 4 decimals
    assert radius * sweep * math.sin(half) / half - rounding <= travelled <= radius * sweep + rounding


@pytest.mark.parametrize(("words", "clockwise", "centre"), [
    pytest.param({b"X": 10.0, b"Y": 10.0, b"R": 10.0}, True, (10.0, 0.0), id="R-short-way-cw"),
    pytest.param({b"X": 10.0, b"Y": 10.0, b"R": -10.0}, True, (0.0, 10.0), id="R-long-way-cw"),
    pytest.param({b"X": 10.0, b"Y": 10.0, b"R": 10.0}, False, (0.0, 10.0), id="R-short-way-ccw"),
    pytest.param({b"X": 0.0, b"Y": 0.0, b"I": 5.0}, False, (5.0, 0.0), id="full-circle"),
])
def test_marlins_arc_rules(words: dict[bytes, float], clockwise: bool, centre: tuple[float, float]) -> None:
    lines = segments((0.0, 0.0, 0.0, 0.0), words, clockwise)
    assert lines is not None
    radius = math.hypot(centre[0], centre[1])
    sagitta_ok((0.0, 0.0), points(lines), centre, radius)


def test_no_centre_is_a_straight_move_and_a_radius_too_small_a_half_circle_on_the_chord() -> None:
    assert segments((0, 0, 0, 0), {b"X": 10.0, b"Y": 0.0}, True) is None
    expander = ArcExpander()
    assert b"".join(expander.expand(b"G1 X5 Y5\nG2 X20 Y5 E3\n")) == b"G1 X5 Y5\nG1 X20 Y5 E3\n"
    for clockwise, side in ((True, 1.0), (False, -1.0)):  # Marlin's G2_G3.cpp: h = 0, the centre mid-chord
        lines = segments((0, 0, 0, 0), {b"X": 20.0, b"Y": 0.0, b"R": 5.0}, clockwise)
        assert lines is not None
        pts = points(lines)
        sagitta_ok((0.0, 0.0), pts, (10.0, 0.0), 10.0)
        assert pts[-1][:2] == pytest.approx((20.0, 0.0))
        assert max(side * p[1] for p in pts) == pytest.approx(10.0, abs=1e-3)  # G2 over the top, G3 below


@pytest.mark.parametrize("turns", [0, 1, 3, 100])
def test_full_turns_come_before_the_arc_with_z_and_e_spread_over_the_whole_path(turns: int) -> None:
    lines = segments((0.0, 0.0, 0.2, 0.0), {b"X": 10.0, b"Y": 0.0, b"I": 5.0, b"Z": 1.2, b"E": 10.0,
                                            b"P": float(turns)}, False)
    assert lines is not None
    pts = points(lines)
    sagitta_ok((0.0, 0.0), pts, (5.0, 0.0), 5.0)
    assert len(pts) <= (turns + 1) * MOST_SEGMENTS
    travelled = sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip([(0.0, 0.0), *pts], pts, strict=False))
    assert travelled == pytest.approx((turns + 0.5) * 2 * math.pi * 5, rel=1e-3)
    assert pts[-1] == pytest.approx((10.0, 0.0, 1.2, 10.0))
    for k, p in enumerate(pts):  # E grows with the path: evenly spread, as Marlin's plan_arc spreads it
        assert p[3] == pytest.approx(10.0 * (k + 1) / len(pts), abs=1e-4)


def test_the_analysis_counts_the_full_turns() -> None:
    from fabwire.xyz.gcodeinfo import MoveAnalyzer

    analyzer = MoveAnalyzer(timing=False)
    analyzer.feed_chunk(b"G1 X0 Y0 F600\nG2 X0 Y0 I5 P2 E1\n")
    assert analyzer.seconds == pytest.approx(3 * 2 * math.pi * 5 / 10)  # 3 circles at 10 mm/s


BASE = b"G28\nG1 Z0.2 F1200\nG1 X10 Y10 E1 F1500\n"


@pytest.mark.parametrize("layout", ["arrays", "indented"])
@pytest.mark.parametrize(("line", "why"), [
    (b"G2 X20 Y10 R0 E5", "centre offset is zero"), (b"G3 X20 Y10 R-0.0 E5", "centre offset is zero"),
    (b"G2 X20 Y10 I0 J0 E5", "centre offset is zero"), (b"G2 X20 Y10 I0 E5", "centre offset is zero"),
    (b"G03 X20 Y10 J0.000 E5", "centre offset is zero"), (b"G3 X10 Y10 R5 E5", "centre offset is zero"),
    (b"G2 R7 E5", "centre offset is zero"), (b"G2 X10 Y10 I5 P101 E5", "full-turn count"),
    (b"G2 X10 Y10 I5 P-1 E5", "full-turn count"), (b"G2 X10 Y10 I5 P2.5 E5", "full-turn count"),
    (b"G2 X10 Y10 I5 J0 P1000000000 E5", "full-turn count"), (b"G3 X10 Y10 R5 P1 E5", "centre offset is zero"),
])
def test_arcs_marlin_refuses_are_refused_with_their_line(tmp_path: Path, line: bytes, why: str, layout: str) -> None:
    code = BASE + line + b"\nG1 X20 Y20 E6\n"
    if layout == "indented":
        code = b"".join(b"  " + each + b"\n" for each in code.splitlines())
    src = tmp_path / "in.gcode"
    src.write_bytes(code)
    done = run_cli("xyz", "convert", str(src), str(tmp_path / "o.3w"), env=cli_env(tmp_path))
    assert done.returncode == 4, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert ": line 4: " in done.stderr
    assert why in done.stderr
    assert not (tmp_path / "o.3w").exists()


def test_relative_modes_are_followed() -> None:
    expander = ArcExpander()
    out = b"".join(expander.expand(b"G91\nM83\nG1 X10 Y10 F600\nG3 X10 Y10 I0 J10 E2\nG1 X1\n")).decode().splitlines()
    arc = out[3:-1]
    assert expander.converted == 1
    xs = [float(MOVE.match(line).group(1)) for line in arc]  # type: ignore[union-attr]
    es = [float(MOVE.match(line).group(4)) for line in arc]  # type: ignore[union-attr]
    assert sum(xs) == pytest.approx(10.0, abs=1e-3)
    assert sum(es) == pytest.approx(2.0, abs=1e-4)
    assert out[-1] == "G1 X1"


def test_convert_writes_segments_and_keep_arcs_keeps_them(tmp_path: Path) -> None:
    src = tmp_path / "arcs.gcode"
    src.write_bytes(b"G90\nM82\nG28\nG92 E0\nG1 Z0.2 F600\nG1 X55 Y75 F1200\n"
                    + b"".join(b"G2 X55 Y75 I20 J0 E%d F1200\n" % (40 * (k + 1)) for k in range(3)))
    info = convert_gcode_file(src, tmp_path / "out.3w")
    body = read_3w(tmp_path / "out.3w").gcode
    assert b"G2 " not in body
    assert body.count(b"\nG1 X") > 3 * 50
    assert any("3 G2/G3 arcs converted to line segments within 0.01 mm" in note for note in info.notes)
    kept = convert_gcode_file(src, tmp_path / "kept.3w", keep_arcs=True)
    assert read_3w(tmp_path / "kept.3w").gcode.count(b"\nG2 X55 Y75 I20 J0") == 3
    assert not any("arc" in note for note in kept.notes)
    done = run_cli("xyz", "convert", str(src), str(tmp_path / "cli.3w"), env=cli_env())
    assert "converted to line segments" in done.stderr
    assert read_3w(tmp_path / "cli.3w").gcode == read_3w(tmp_path / "out.3w").gcode.replace(b"out.3w", b"cli.3w")


def test_gcode_beyond_the_build_volume_is_refused_unless_forced(tmp_path: Path) -> None:
    src = tmp_path / "big.gcode"
    src.write_bytes(b"G28\nG1 Z0.2 F600\nG1 X10 Y10 F3000\nG1 X198 Y10 E5 F1200\nG1 X198 Y100 E9\n")
    refused = run_cli("xyz", "convert", str(src), str(tmp_path / "b.3w"), "-m", "mini w", env=cli_env())
    assert refused.returncode == 4
    assert "X 0.0 to 198.0 mm" in refused.stderr  # the travel from home counts too
    assert "150 × 150 × 150 mm" in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "b.3w").exists()
    forced = run_cli("xyz", "convert", "--force", str(src), str(tmp_path / "b.3w"), "-m", "mini w", env=cli_env())
    assert forced.returncode == 0, forced.stderr
    assert "converted anyway (--force)" in forced.stderr
    fits = run_cli("xyz", "convert", str(src), str(tmp_path / "c.3w"), "-m", "da Vinci 1.0", env=cli_env())
    assert fits.returncode == 0, fits.stderr


@settings(max_examples=100, deadline=None)
@given(st.dictionaries(st.sampled_from([b"X", b"Y", b"Z", b"E", b"I", b"J", b"R", b"F"]),
                       st.floats(allow_nan=True, allow_infinity=True, width=64), max_size=8),
       st.booleans(), st.booleans(), st.booleans())
def test_any_arc_words_give_bounded_segments_or_none(words: dict[bytes, float], clockwise: bool, absolute: bool,
                                                     absolute_e: bool) -> None:
    lines = segments((1.0, 2.0, 0.2, 3.0), words, clockwise, absolute=absolute, absolute_e=absolute_e)
    if lines is not None:
        assert 1 <= len(lines) <= MOST_SEGMENTS + 1
        assert all("nan" not in line and "inf" not in line for line in lines)


def test_full_turns_that_would_blow_a_file_up_are_refused_while_converting(tmp_path: Path) -> None:
    """Each line may ask for 100 full turns of a large circle (Marlin's most): a few kilobytes of them would be
    hundreds of megabytes of segments, so the growth is bounded (`arcwork.GROWTH_ALLOWED`) and nothing is kept."""
    from fabwire.xyz.arcwork import GROWTH_ALLOWED

    lines = ["G28", "G1 Z0.2 F1200", "G1 X75 Y5 F1500"]
    lines += [f"G2 X75 Y5 I0 J70 P100 E{i + 1}" for i in range(600)]
    source = tmp_path / "turns.gcode"
    source.write_text("\n".join(lines) + "\n")
    out = tmp_path / "turns.3w"
    done = run_cli("xyz", "convert", str(source), str(out), "--model", "miniMaker", env=cli_env(tmp_path))
    assert done.returncode == 4, done.stderr
    assert f"would make it more than {GROWTH_ALLOWED} times its size" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".turns")]  # no temporary file left either
    kept = run_cli("xyz", "convert", str(source), str(out), "--model", "miniMaker", "--keep-arcs",
                   env=cli_env(tmp_path))
    assert kept.returncode == 0, kept.stderr
    assert out.stat().st_size < 1_000_000


def _arc_code(radius: float, start: float, sweep: float, turns: int, clockwise: bool, relative: bool,
              indented: bool) -> tuple[bytes, bytes]:
    """(the lines before, an arc line) around (120, 80): X, Y, I and J with six decimals, a Z and an E change."""
    cx, cy = 120.0, 80.0
    x0, y0 = cx + radius * math.cos(start), cy + radius * math.sin(start)
    end = start - sweep if clockwise else start + sweep
    x1, y1 = cx + radius * math.cos(end), cy + radius * math.sin(end)
    before = f"G90\nM82\nG1 X{x0:.6f} Y{y0:.6f} Z0.2 E1 F1200\n" + ("G91\nM83\n" if relative else "")
    x, y = (x1 - x0, y1 - y0) if relative else (x1, y1)
    arc = (f"G{2 if clockwise else 3} X{x:.6f} Y{y:.6f} I{cx - x0:.6f} J{cy - y0:.6f} Z{0.1 if relative else 0.3}"
           f" E{2.5 if relative else 3.5}" + (f" P{turns}" if turns else "") + " F1800\n")
    if indented:  # the line reader's path through the analysis
        return "".join(f"  {line}\n" for line in before.splitlines()).encode(), f"  {arc}".encode()
    return before.encode(), arc.encode()


@settings(max_examples=120, deadline=None)
@given(radius=st.one_of(st.floats(1e-4, 0.05), st.floats(0.05, 300), st.floats(300, 60000)),
       start=st.floats(0, 2 * math.pi), sweep=st.floats(0, 2 * math.pi), turns=st.integers(0, 3),
       clockwise=st.booleans(), relative=st.booleans(), indented=st.booleans())
def test_the_analysis_counts_the_segments_the_conversion_writes(radius: float, start: float, sweep: float,
                                                                turns: int, clockwise: bool, relative: bool,
                                                                indented: bool) -> None:
    """The analysis counts as many segments as the conversion writes for each arc (one formula,
    `motion.arc_segment_counts`), and bounds their bytes from above (`arcwork.lines_size`)."""
    from fabwire.xyz.gcodeinfo import MoveAnalyzer

    before, arc = _arc_code(radius, start, sweep, turns, clockwise, relative, indented)
    analyzer = MoveAnalyzer(timing=False)
    analyzer.feed_chunk(before + arc)
    expander = ArcExpander()
    written = b"".join(expander.expand(before + arc))
    assert written.startswith(before)
    segment_lines = written[len(before):]
    assert expander.converted == 1
    assert analyzer.arc_segments == segment_lines.count(b"\n")
    assert len(segment_lines) <= analyzer.arc_bytes


@pytest.mark.parametrize("turns", [1, 100])
@pytest.mark.parametrize("radius", [0.001, 0.5, 37.0, 4000.0])
def test_full_turns_are_counted_as_the_conversion_writes_them(radius: float, turns: int) -> None:
    from fabwire.xyz.gcodeinfo import MoveAnalyzer

    before, arc = _arc_code(radius, 0.3, 1.0, turns, True, False, False)
    analyzer = MoveAnalyzer(timing=False)
    analyzer.feed_chunk(before + arc)
    segment_lines = b"".join(ArcExpander().expand(before + arc))[len(before):]
    assert analyzer.arc_segments == segment_lines.count(b"\n") <= (turns + 1) * MOST_SEGMENTS
    assert len(segment_lines) <= analyzer.arc_bytes <= 1.3 * len(segment_lines)  # a bound, and a close one


def _hostile(shape: str) -> str:
    """G-code whose arcs would make far more than GROWTH_ALLOWED times its size in segments."""
    head = "G28\nG1 Z0.2 F1200\nG1 X75 Y75 F1500\n"
    if shape == "tiny full circles":
        return head + "G2 I0.001 J0 P100\n" * 3000
    if shape == "huge radius":  # full circles 60 m across, at most MOST_SEGMENTS segments each
        return head + "".join(f"G2 X75 Y75 I30000 J0 E{k + 1}\n" for k in range(3000))
    if shape == "many full turns":
        return head + "".join(f"G3 X75 Y75 I0 J70 P100 E{k + 1}\n" for k in range(3000))
    assert shape == "mixed with lines"
    return head + "".join(f"G1 X{75 + k % 7} Y75 E{k / 10}\nG1 X75 Y{75 + k % 5}\n" + ("  G2 I0.5 J0 P40\n" if k % 3
                                                                                      else "G3 I0 J0.2 P7\n")
                          for k in range(3000))


@pytest.mark.parametrize("shape", ["tiny full circles", "huge radius", "many full turns", "mixed with lines"])
def test_arcs_that_would_grow_a_file_too_much_are_refused_before_anything_is_written(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], shape: str) -> None:
    """The analysis bounds each arc's segments and refuses the file at the arc that takes it past the limit,
    before the conversion writes anything (here without the free allowance, so a small file shows it)."""
    from fabwire.cli import main
    from fabwire.xyz import arcwork

    monkeypatch.setattr(arcwork, "GROWTH_FREE", 0)
    source = tmp_path / "hostile.gcode"
    source.write_text(_hostile(shape))
    out = tmp_path / "hostile.3w"
    written: list[int] = []
    expand = arcwork.ArcExpander.expand
    monkeypatch.setattr(arcwork.ArcExpander, "expand", lambda self, chunk: written.append(1) or expand(self, chunk))
    code = main(["xyz", "convert", "--force", str(source), str(out), "--model", "miniMaker"])
    error = capsys.readouterr().err
    assert code == 4, error
    assert len(error.strip().splitlines()) == 1
    found = re.search(r": its G2/G3 arcs as straight moves would make it more than 8 times its size \(past arc "
                      r"([0-9]+)\): slice it with arcs off, or convert it with --keep-arcs$", error.strip())
    assert found, error
    assert 1 <= int(found.group(1)) < 3000  # the arc that went past the limit, long before the file's end
    assert not written  # refused before any conversion began
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir()] == ["hostile.gcode"]  # no temporary file left either


def test_slicer_arcs_growing_a_file_a_few_times_are_converted(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Arcs as slicers fit them over polylines (a few millimetres to a few centimetres, a fraction of a turn,
    between straight moves) grow a file two to three times: well within the limit, even without its free
    allowance."""
    from fabwire.xyz import arcwork

    monkeypatch.setattr(arcwork, "GROWTH_FREE", 0)
    lines = ["G90", "M82", "G28", "G92 E0", "G1 Z0.2 F1200", "G1 X100 Y100 F3000"]
    x, y, e = 100.0, 100.0, 0.0
    for k in range(600):
        radius, sweep = 3 + k % 17, 0.2 + (k % 5) / 10
        cx, cy = x - radius, y  # from the circle's rightmost point, counter-clockwise
        x, y, e = cx + radius * math.cos(sweep), cy + radius * math.sin(sweep), e + radius * sweep * 0.04
        lines.append(f"G3 X{x:.3f} Y{y:.3f} I{-radius:.3f} J0 E{e:.5f}")
        x, e = x + 1.5, e + 0.06
        lines.append(f"G1 X{x:.3f} Y{y:.3f} E{e:.5f}")
        if k % 8 == 7:
            x, y = 100.0, 100.0
            lines.append("G1 X100 Y100 F3000")
    source = tmp_path / "fitted.gcode"
    source.write_text("\n".join(lines) + "\n")
    info = convert_gcode_file(source, tmp_path / "fitted.3w", model="miniMaker")
    assert any("600 G2/G3 arcs converted" in note for note in info.notes)
    assert source.stat().st_size < info.gcode_size < 4 * source.stat().st_size


def test_full_turns_read_as_arrays_or_line_by_line_give_the_same_figures() -> None:
    """Arcs with P are read with the other moves' arrays; the line reader (indented lines) gives the same."""
    from fabwire.xyz.gcodeinfo import MoveAnalyzer

    code = (b"G90\nM82\nG1 X50 Y50 Z0.2 F1200\nG2 X60 Y50 I5 J0 P2 E3\nG1 X70 Y70 E4\nG3 X70 Y70 I0 J-8 P1 E6 F900\n"
            b"G2 X75 Y75 R5 P3 E7\nG91\nG3 X5 Y0 I2.5 J0 P1 E1\nG2 I1 J1 P0\n")
    figures = []
    for text in (code, b"".join(b" " + line + b"\n" for line in code.splitlines())):
        analyzer = MoveAnalyzer()
        analyzer.feed_chunk(text)
        figures.append((analyzer.result(), analyzer.arc_segments, analyzer.arc_bytes))
    (arrays, segments_a, bytes_a), (lines, segments_l, bytes_l) = figures
    assert arrays.extent == lines.extent
    assert arrays.print_time_s == lines.print_time_s
    assert arrays.filament_mm == pytest.approx(lines.filament_mm)
    assert (segments_a, bytes_a) == (segments_l, bytes_l)
    assert segments_a == sum(line.startswith(b"G1") for line in b"".join(ArcExpander().expand(code)).splitlines()) - 2
