"""SVG path data and basic shapes to flattened subpaths, built point by point into compact arrays.

The path grammar is svgelements' streaming lexer; this module is the builder it calls. Each segment is
flattened in the element's user space with a tolerance chosen so that, once the element's transform is applied,
no chord strays more than `tolerance` output units from the true curve (an affine map stretches a distance by
at most its largest singular value). Points are kept in `array('d')` buffers, 16 bytes a point, so memory stays
in proportion to the geometry (SVG 1.1 §8.3 path data, §9 basic shapes, F.6 arc implementation notes).
"""

from __future__ import annotations

import math
import re
import warnings
from array import array
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import svgelements as se

from fabwire.lineus.plot.geometry import FloatArray
from fabwire.lineus.plot.svgunits import FLOAT32_MAX, IDENTITY

MAX_CURVE_POINTS = 10_000
"""Chords for one curve segment at most: beyond any drawing that fits the Line-us area at 0.05 mm."""
READ_TOGETHER_LARGEST = 1e6
"""Paths read together hold no number beyond this: relative steps summed across them then stay exact to far
below the pen's resolution (larger ones are read path by path)."""
_MAYBE_LARGE = re.compile(r"\d{39}|[eE]\+?0*(?:3[89]|[4-9]\d|\d{3,})")
_FLOAT = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


@dataclass(slots=True)
class Subpath:
    """One subpath in output units: its points, whether it was closed, and how many segments made it."""

    points: FloatArray
    closed: bool
    segments: int
    vertices: tuple[int, ...] | None = None
    """Indices of the points where segments start and end (markers sit there); None when every point is one."""


class _Point:
    __slots__ = ("x", "y")

    def __init__(self, x: float, y: float) -> None:
        self.x = x
        self.y = y


class PathBuilder:
    """Receives svgelements' lexer callbacks and produces transformed, flattened subpaths.

    `matrix` is the 2x3 user-to-output transform; `tolerance` is the chord error allowed in output units.
    """

    def __init__(self, matrix: FloatArray, tolerance: float, room: int | None = None) -> None:
        self.matrix = matrix
        self.room = room
        """How many more points the curves may add (None: no bound): a curve's points grow with its size, so
        twenty bytes of path data could otherwise become thousands of points (TooManyPoints past it)."""
        stretch = _largest_stretch(matrix) or 1.0
        self.user_tolerance = tolerance / stretch
        self.subpaths: list[Subpath] = []
        self.curved = False
        self.current_point: _Point | None = None
        self._start = (0.0, 0.0)
        self._buf = array("d")
        self._segments = 0
        self._ends: list[int] = []
        self._last_cubic: tuple[float, float] | None = None
        self._last_quad: tuple[float, float] | None = None

    # -- lexer protocol ---------------------------------------------------------------------------------------

    def start(self) -> None:
        """Beginning of the path data."""

    def end(self) -> None:
        self._flush(closed=False)

    def move(self, *points: tuple[float, float], relative: bool = False) -> None:
        self._flush(closed=False)
        x, y = points[-1]
        self._buf.extend((x, y))
        self._start = (x, y)
        self._at(x, y)

    def line(self, *points: tuple[float, float], relative: bool = False) -> None:
        for x, y in points:
            self._begin()
            self._buf.extend((x, y))
            self._segment()
            self._at(x, y)

    def horizontal(self, *xs: float | None, relative: bool = False) -> None:
        for value in xs:
            if value is None:
                raise ValueError("a horizontal line needs a number")
            here = self._here()
            self.line((here[0] + value if relative else value, here[1]))

    def vertical(self, *ys: float | None, relative: bool = False) -> None:
        for value in ys:
            if value is None:
                raise ValueError("a vertical line needs a number")
            here = self._here()
            self.line((here[0], here[1] + value if relative else value))

    def cubic(self, c1: tuple[float, float], c2: tuple[float, float], end: tuple[float, float],
              relative: bool = False) -> None:
        p0 = self._here()
        self._bezier(np.array([p0, c1, c2, end], dtype=float))
        self._at(*end)
        self._last_cubic = c2

    def smooth_cubic(self, c2: tuple[float, float], end: tuple[float, float], relative: bool = False) -> None:
        here = self._here()
        prev = self._last_cubic
        c1 = (2 * here[0] - prev[0], 2 * here[1] - prev[1]) if prev is not None else here
        self.cubic(c1, c2, end)

    def quad(self, c: tuple[float, float], end: tuple[float, float], relative: bool = False) -> None:
        p0 = self._here()
        self._bezier(np.array([p0, c, end], dtype=float))
        self._at(*end)
        self._last_quad = c

    def smooth_quad(self, end: tuple[float, float], relative: bool = False) -> None:
        here = self._here()
        prev = self._last_quad
        c = (2 * here[0] - prev[0], 2 * here[1] - prev[1]) if prev is not None else here
        self.quad(c, end)

    def arc(self, rx: float, ry: float, rotation: float, large: bool, sweep: bool, end: tuple[float, float],
            relative: bool = False) -> None:
        p0 = self._here()
        self._begin()
        pts = _arc_points(p0, abs(rx), abs(ry), rotation, bool(large), bool(sweep), end, self.user_tolerance)
        self._spend(len(pts))
        if len(pts) > 1:
            self.curved = True
        self._buf.extend(pts.ravel().tolist())
        self._segment()
        self._at(*end)

    def closed(self, relative: bool = False) -> None:
        self._begin()
        here = self._here()
        if here != self._start:
            self._buf.extend(self._start)
        self._segment()
        self._flush(closed=True)
        self._at(*self._start)  # a command after Z starts a new subpath at this start point

    # -- internals --------------------------------------------------------------------------------------------

    def _here(self) -> tuple[float, float]:
        p = self.current_point
        return (p.x, p.y) if p is not None else (0.0, 0.0)

    def _at(self, x: float, y: float) -> None:
        self.current_point = _Point(x, y)
        self._last_cubic = None
        self._last_quad = None

    def _begin(self) -> None:
        """A drawing command without a moveto before it starts at the current point."""
        if not self._buf:
            here = self._here()
            self._buf.extend(here)
            self._start = here

    def _bezier(self, ctrl: FloatArray) -> None:
        self._begin()
        n = _bezier_steps(ctrl, self.user_tolerance)
        t = np.linspace(0.0, 1.0, n + 1)[1:, None]
        if len(ctrl) == 4:
            s = 1 - t
            pts = s**3 * ctrl[0] + 3 * s * s * t * ctrl[1] + 3 * s * t * t * ctrl[2] + t**3 * ctrl[3]
        else:
            s = 1 - t
            pts = s * s * ctrl[0] + 2 * s * t * ctrl[1] + t * t * ctrl[2]
        self._spend(n)
        if n > 1:
            self.curved = True
        self._buf.extend(pts.ravel().tolist())
        self._segment()

    def _segment(self) -> None:
        self._segments += 1
        self._ends.append(len(self._buf) // 2 - 1)

    def _spend(self, points: int) -> None:
        if self.room is not None:
            self.room -= points
            if self.room < 0:
                raise TooManyPoints

    def _flush(self, *, closed: bool) -> None:
        if self._buf:
            user = np.frombuffer(self._buf, dtype=float).reshape(-1, 2)
            with np.errstate(invalid="ignore", over="ignore"):  # non-finite points are dropped by the reader
                out = user @ self.matrix[:, :2].T + self.matrix[:, 2]
            self.subpaths.append(Subpath(out, closed, self._segments, (0, *self._ends)))
        self._buf = array("d")
        self._segments = 0
        self._ends = []


def _largest_stretch(matrix: FloatArray) -> float:
    """The largest singular value of the matrix's 2x2 part: how much it can lengthen any distance."""
    (a, b, _), (c, d, _) = matrix.tolist()
    half = (a * a + b * b + c * c + d * d) / 2
    det = a * d - b * c
    return math.sqrt(half + math.sqrt(max(0.0, half * half - det * det)))


def _bezier_steps(ctrl: FloatArray, tolerance: float) -> int:
    """Chords keeping a Bézier within `tolerance` of its polygon (Wang's bound on the second differences)."""
    second = ctrl[2:] - 2 * ctrl[1:-1] + ctrl[:-2]
    m = float(np.hypot(second[:, 0], second[:, 1]).max())
    degree = len(ctrl) - 1
    n = math.sqrt(degree * (degree - 1) / 8 * m / tolerance)
    return max(1, min(MAX_CURVE_POINTS, math.ceil(n))) if math.isfinite(n) else 1


def _arc_points(p0: tuple[float, float], rx: float, ry: float, rotation: float, large: bool, sweep: bool,
                end: tuple[float, float], tolerance: float) -> FloatArray:
    """Points after `p0` along an elliptical arc, endpoint to centre form (SVG 1.1 F.6.5, radii per F.6.6)."""
    x1, y1 = p0
    x2, y2 = end
    if (x1, y1) == (x2, y2):
        return np.empty((0, 2))
    if not (rx * rx * ry * ry > 0 and math.isfinite(rx * ry)):
        return np.array([end], dtype=float)  # a zero (or unusable) radius is a straight line (SVG 1.1 F.6.2)
    phi = math.radians(rotation % 360)
    cos_p, sin_p = math.cos(phi), math.sin(phi)
    dx, dy = (x1 - x2) / 2, (y1 - y2) / 2
    xp, yp = cos_p * dx + sin_p * dy, -sin_p * dx + cos_p * dy
    grow = xp * xp / (rx * rx) + yp * yp / (ry * ry)
    if grow > 1:
        rx, ry = rx * math.sqrt(grow), ry * math.sqrt(grow)
    num = rx * rx * ry * ry - rx * rx * yp * yp - ry * ry * xp * xp
    den = rx * rx * yp * yp + ry * ry * xp * xp
    k = math.sqrt(max(0.0, num / den)) if den else 0.0
    if large == sweep:
        k = -k
    cxp, cyp = k * rx * yp / ry, -k * ry * xp / rx
    cx = cos_p * cxp - sin_p * cyp + (x1 + x2) / 2
    cy = sin_p * cxp + cos_p * cyp + (y1 + y2) / 2
    theta1 = math.atan2((yp - cyp) / ry, (xp - cxp) / rx)
    theta2 = math.atan2((-yp - cyp) / ry, (-xp - cxp) / rx)
    delta = theta2 - theta1
    if sweep and delta < 0:
        delta += 2 * math.pi
    elif not sweep and delta > 0:
        delta -= 2 * math.pi
    radius = max(rx, ry)
    step = 2 * math.acos(1 - tolerance / radius) if tolerance < radius else math.pi / 2
    n = max(1, min(MAX_CURVE_POINTS, math.ceil(abs(delta) / step))) if step > 0 else 1
    t = theta1 + delta * np.linspace(0.0, 1.0, n + 1)[1:]
    ex, ey = rx * np.cos(t), ry * np.sin(t)
    pts = np.column_stack([cos_p * ex - sin_p * ey + cx, sin_p * ex + cos_p * ey + cy])
    pts[-1] = end  # land exactly on the endpoint the next segment starts from
    return pts


class TooManyPoints(Exception):
    """A path's curves need more points than the drawing has room for (`PathBuilder.room`)."""


class PathDataError(ValueError):
    """Path data in error for a reason the grammar alone does not show."""


def path_data(builder: PathBuilder, d: str) -> None:
    """Feed path data `d` to `builder`; ValueError where the data breaks the grammar or holds a number beyond
    single precision, which browsers cannot read (what precedes is kept, as SVG 1.1 §F.2 error processing renders
    the path up to the error)."""
    if len(d) > 256 and straight_path_data(builder, d):
        return
    cut = _first_number_beyond_single(d)
    if cut is not None:
        d = d[:cut]
    try:
        se.SVGLexicalParser().parse(builder, d)
    except ValueError:
        if cut is None:
            raise
    finally:
        builder.end()
    if cut is not None:
        raise PathDataError("a number beyond what a browser can hold")


def _first_number_beyond_single(d: str) -> int | None:
    """Where the first number too large for single precision starts, or None (a cheap test rules most data out)."""
    if not _MAYBE_LARGE.search(d):
        return None
    for match in _FLOAT.finditer(d):
        if abs(float(match.group())) > FLOAT32_MAX:
            return match.start()
    return None


def numbers(text: str) -> list[float]:
    """The numbers in an attribute such as `points`."""
    return [float(v) for v in _FLOAT.findall(text)]


def polyline(builder: PathBuilder, values: list[float], *, close: bool) -> None:
    """`<polyline>`/`<polygon>` points; an odd trailing number is ignored (SVG 1.1 §9.7.1)."""
    pts = list(zip(values[0::2], values[1::2], strict=False))
    if not pts:
        return
    builder.move(pts[0])
    if len(pts) > 1:
        builder.line(*pts[1:])
    if close:
        builder.closed()
    builder.end()


def rect(builder: PathBuilder, x: float, y: float, w: float, h: float, rx: float | None, ry: float | None) -> None:
    """A rectangle, with rounded corners when rx/ry are given (auto and clamping as SVG 1.1 §9.2)."""
    if not (w > 0 and h > 0):
        return
    if rx is None and ry is None:
        rx = ry = 0.0
    rx = ry if rx is None else rx
    ry = rx if ry is None else ry
    rx, ry = min(abs(rx or 0.0), w / 2), min(abs(ry or 0.0), h / 2)
    if rx == 0 or ry == 0:
        builder.move((x, y))
        builder.line((x + w, y), (x + w, y + h), (x, y + h))
    else:
        builder.move((x + rx, y))
        builder.line((x + w - rx, y))
        builder.arc(rx, ry, 0, False, True, (x + w, y + ry))
        builder.line((x + w, y + h - ry))
        builder.arc(rx, ry, 0, False, True, (x + w - rx, y + h))
        builder.line((x + rx, y + h))
        builder.arc(rx, ry, 0, False, True, (x, y + h - ry))
        builder.line((x, y + ry))
        builder.arc(rx, ry, 0, False, True, (x + rx, y))
    builder.closed()
    builder.end()


def ellipse(builder: PathBuilder, cx: float, cy: float, rx: float, ry: float) -> None:
    """An ellipse (or circle) from its rightmost point, in the positive-angle direction."""
    if not (rx > 0 and ry > 0):
        return
    builder.move((cx + rx, cy))
    builder.arc(rx, ry, 0, False, True, (cx - rx, cy))
    builder.arc(rx, ry, 0, False, True, (cx + rx, cy))
    builder.closed()
    builder.end()


def line(builder: PathBuilder, x1: float, y1: float, x2: float, y2: float) -> None:
    builder.move((x1, y1))
    builder.line((x2, y2))
    builder.end()


_STRAIGHT_ONLY = re.compile(r"[MmLlHhVvZz0-9eE.,+\-\s]*")
_M, _L, _H, _V, _Z = (ord(c) for c in "MLHVZ")
_COMMANDS = np.zeros(256, dtype=bool)
_COMMANDS[np.frombuffer(b"MmLlHhVvZz", dtype=np.uint8)] = True
_SPACE = np.zeros(256, dtype=bool)
_SPACE[np.frombuffer(b" \t\r\n\f,", dtype=np.uint8)] = True


def straight_path_data(builder: PathBuilder, d: str) -> bool:
    """Path data made only of straight segments (M L H V Z, either case), the bulk of generated drawings, read
    with array operations instead of one lexer call per number: same subpaths as the general reader, several
    times faster. Returns False, having built nothing, for anything it does not take on (curves, arcs, compact
    number forms, relative commands right after a closepath, numbers beyond single precision, malformed data);
    the general reader does those."""
    read = _straight_subpaths(d, builder.matrix)
    if read is None:
        return False
    builder.subpaths.extend(read[0])
    return True


def is_straight(d: str) -> bool:
    """Whether path data holds only the characters of straight segments (the straight reader may take it)."""
    return _STRAIGHT_ONLY.fullmatch(d) is not None


def straight_paths(ds: list[str]) -> list[list[Subpath]] | None:
    """Many path data strings, each starting with an absolute moveto, read in one pass of array operations (the
    cost of a call is paid once, not per path): each one's subpaths in user units, as `straight_path_data` would
    give them. None when any of them is not for the straight reader (then read each on its own)."""
    if not ds or not all(d.lstrip()[:1] == "M" for d in ds):
        return None
    read = _straight_subpaths(" ".join(ds), IDENTITY, largest=READ_TOGETHER_LARGEST)
    if read is None:
        return None
    subpaths, first_command = read
    commands_before = np.cumsum([sum(d.count(c) for c in "MmLlHhVvZz") for d in ds])
    owner = np.searchsorted(commands_before, first_command, side="right")
    out: list[list[Subpath]] = [[] for _ in ds]
    for sub, k in zip(subpaths, owner.tolist(), strict=True):
        out[k].append(sub)
    return out


def _straight_subpaths(d: str, matrix: FloatArray, *, largest: float = FLOAT32_MAX,
                       ) -> tuple[list[Subpath], npt.NDArray[np.int32]] | None:
    """The subpaths of straight-only path data under `matrix`, with the index of the command each starts at;
    None when the data is not for this reader or holds a number beyond `largest`."""
    if not _STRAIGHT_ONLY.fullmatch(d):
        return None
    text = np.frombuffer(re.sub(r"(?<=[0-9.])(?=[-+])", " ", d).encode("ascii"), dtype=np.uint8)
    is_cmd = _COMMANDS[text]
    blank = _SPACE[text] | is_cmd
    token_at = np.flatnonzero(~blank & np.concatenate([[True], blank[:-1]]))
    cmd_at = np.flatnonzero(is_cmd)
    if not len(cmd_at) or (len(token_at) and token_at[0] < cmd_at[0]):
        return None
    cleaned = np.where(blank, np.uint8(32), text).tobytes().decode("ascii")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a token it cannot read ends the array early: caught by the count below
            values = np.fromstring(cleaned, dtype=float, sep=" ")
    except ValueError:  # a compact number form such as 1.5.5 or 1e
        return None
    if len(values) != len(token_at) or (len(values) and float(np.abs(values).max()) > largest):
        return None
    cmds = text[cmd_at]
    first = np.searchsorted(token_at, cmd_at)
    count = np.diff(np.append(first, len(values)))
    upper = cmds & 0xDF  # ASCII upper case
    relative = cmds != upper
    pairs = (upper == _M) | (upper == _L)
    if upper[0] != _M or (count[pairs] % 2).any() or (count[pairs] == 0).any() or (count[upper == _Z] != 0).any():
        return None
    if ((count == 0) & ((upper == _H) | (upper == _V))).any():
        return None
    closes = np.flatnonzero(upper == _Z)
    after = closes + 1
    after = after[after < len(cmds)]
    if len(after) and (cmds[after] != _M).any():
        return None
    # One event per point: pairs for M/L, singles for H/V, none for Z (added below). Temporaries are dropped as
    # soon as they are used: a generated path can hold millions of points.
    per = np.where(pairs, count // 2, np.where(upper == _Z, 0, count))
    group = np.repeat(np.arange(len(cmds), dtype=np.int32), per)
    offset = np.arange(len(group), dtype=np.int64) - np.repeat(np.cumsum(per) - per, per)
    kind = upper[group]
    is_pair = pairs[group]
    starts = np.flatnonzero((kind == _M) & (offset == 0))
    if not len(starts) or starts[0] != 0:
        return None
    pos = first[group]
    pos += np.where(is_pair, 2 * offset, offset)
    del offset
    np.minimum(pos, len(values) - 1, out=pos)
    rel = relative[group]
    sets_x = is_pair | (kind == _H)
    sets_y = is_pair | (kind == _V)
    points = np.zeros((len(group), 2))
    points[sets_x, 0] = values[pos[sets_x]]
    points[is_pair, 1] = values[np.minimum(pos[is_pair] + 1, len(values) - 1)]
    points[kind == _V, 1] = values[pos[kind == _V]]
    del pos, values, kind, is_pair
    # x_i is the value when set absolutely, x_(i-1) plus the value when relative or untouched (V sets y only).
    points[:, 0] = _carry(points[:, 0], ~rel & sets_x)
    points[:, 1] = _carry(points[:, 1], ~rel & sets_y)
    del rel, sets_x, sets_y
    if matrix is not IDENTITY:
        with np.errstate(invalid="ignore", over="ignore"):
            points @= matrix[:, :2].T
            points += matrix[:, 2]
    bounds = [*starts.tolist(), len(points)]
    closed_groups = set(closes.tolist())
    # A Z right after a subpath's last point closes it.
    last_group = group[np.array(bounds[1:]) - 1]
    subpaths = []
    for k in range(len(starts)):
        a, b = bounds[k], bounds[k + 1]
        closed = int(last_group[k]) + 1 in closed_groups
        piece = points[a:b]
        if closed and not np.array_equal(points[a], points[b - 1]):
            piece = np.vstack([piece, points[a : a + 1]])
        subpaths.append(Subpath(piece, closed, (b - a - 1) + (1 if closed else 0)))
    return subpaths, group[starts]


def _carry(values: FloatArray, absolute: npt.NDArray[np.bool_]) -> FloatArray:
    """Running coordinate: restart at each absolute value, add relative ones (an untouched axis adds 0). Only
    relative steps are summed, so a large absolute value never costs a later one its precision."""
    total = np.cumsum(np.where(absolute, 0.0, values))
    anchor = np.where(absolute, np.arange(len(values)), -1)
    np.maximum.accumulate(anchor, out=anchor)
    anchored = anchor >= 0
    total[anchored] += values[anchor[anchored]] - total[anchor[anchored]]
    return total
