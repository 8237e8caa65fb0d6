"""The Line-us G-code interpreter: what each command does to the arm and what the pen leaves on the paper.

One interpreter for every reader of Line-us G-code (the simulator, the drawing reader that previews a G-code file,
`files save` validation), so a file previews exactly as the machine draws it. The semantics, from the GCodeSpec
(1.0.4a and 3.2.0) and the Line-us README:

- `G01`/`G00` X Y Z: a parameter given alone changes only that axis; X and Y go through this connection's G54
  (`machine = value × S + offset`); `G00` moves every servo at full speed, so the pen sweeps a joint-space curve.
- `G28`: home, (1000, 1000) with the pen up, whatever G54 says.
- `G40` X Y Z: a move that ignores G54 (and calibration).
- `G54` X Y S: scale and origin, per connection, `X0 Y0 S1` when a connection starts (missing values too).
- `G94`: speeds only (no geometry), and every other code the grammar knows carries no geometry.
- Z below 500 is pen-down; Z outside 0…1000 puts the pen fully up. A target outside the drawing area moves the
  arm to the nearest point it can reach and lifts the pen (README: "Line-us will move to something approximating
  the closest it can get … and lift the pen").
- A pen lift happens before the XY motion and a drop after it: `G01 X Y Z0` from pen-up lands at (X, Y).
- Files may hold comments (`; …` to the end of the line, `( … )`); the wire carries none.
"""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass, field

from fabwire.errors import InputError, RemoteProtocolError, excerpt
from fabwire.lineus import kinematics as kin
from fabwire.lineus import protocol as p

Point2 = tuple[float, float]
Point3 = tuple[float, float, float]
MotionCommand = p.Move | p.Home | p.RawMove

HOME3: Point3 = (kin.HOME[0], kin.HOME[1], kin.Z_UP)

_COMMENT = re.compile(r"\([^)]*\)|;.*$")
OTHER_DIALECTS = {"G91": "relative positioning", "G02": "arcs", "G03": "arcs", "G20": "inch units"}
"""Codes that change the geometry on other machines; the Line-us refuses them, so a file holding them was written
for another machine and would be drawn wrongly."""
HARMLESS = frozenset({"G90", "G21", "G04", "G17"})
"""Codes of other dialects that say what the Line-us does anyway (absolute millimetres, no dwell effect on the
paper); the machine refuses them with `error` and draws on, so a reader skips them."""


@dataclass(frozen=True, slots=True)
class Motion:
    """Where one move command sends the arm, in machine units."""

    command: str
    """The line as received (empty when the caller did not give it)."""
    target: Point3
    clamped: bool
    """The target was outside the drawing area: moved to the nearest reachable point, pen lifted."""
    rapid: bool


class Interpreter:
    """One connection's G-code state (its G54) and the motion each move command asks for.

    `clamp`: apply the firmware's out-of-area rule (the simulator does; the drawing reader keeps the raw geometry so
    the planner can refuse, clip or fit what lies outside). `x_min_lower`: the firmware's body clearance below
    y = 0 (700 units; 500 on firmware 1.0.1, see `kinematics.X_MIN_LOWER_FW1`).
    """

    def __init__(self, *, clamp: bool = True, x_min_lower: float = kin.X_MIN_LOWER) -> None:
        self.clamp = clamp
        self.x_min_lower = x_min_lower
        self.origin: tuple[float, float, float] = (0.0, 0.0, 1.0)
        """G54 (x offset, y offset, scale)."""

    def set_origin(self, command: p.SetOrigin) -> None:
        self.origin = (command.x, command.y, command.scale)

    def motion(self, command: MotionCommand, here: Point3, text: str = "") -> Motion:
        """The target of a G00/G01/G28/G40 given the arm's (planned) position `here`."""
        x0, y0, z0 = here
        if isinstance(command, p.Home):
            x, y, z = HOME3
        else:
            ox, oy, scale = self.origin if isinstance(command, p.Move) else (0.0, 0.0, 1.0)
            x = x0 if command.x is None else command.x * scale + ox
            y = y0 if command.y is None else command.y * scale + oy
            z = z0 if command.z is None else command.z
        if not 0.0 <= z <= kin.Z_UP:
            z = kin.Z_UP
        clamped = False
        if self.clamp:
            where = kin.clamp_target(x, y, x_min_lower=self.x_min_lower)
            if where.clamped:
                x, y, z, clamped = where.x, where.y, kin.Z_UP, True
        rapid = isinstance(command, p.Move) and command.rapid
        return Motion(text, (x, y, z), clamped, rapid)


# -- the paper ------------------------------------------------------------------------------------------------------


class Ink:
    """What the pen puts on paper as the arm moves: pen-down polylines (a lone point is a dot: the pen went down
    and up again in one place) and pen-up travel, in machine units.

    `lift_over_notch`: firmware 3 keeps the pen out of the body notch (x < 700 below y = 0), so a pen-down line
    between two reachable ends that cuts the notch leaves ink only where it is reachable. `collisions`: firmware
    1.0.1 goes into the notch, where the pen screw hits the body; each move that enters it is noted.
    """

    def __init__(self, *, lift_over_notch: bool = False, detect_collisions: bool = False,
                 keep: int | None = None) -> None:
        self.strokes: list[list[Point2]] = []
        self.travel: list[list[Point2]] = []
        self.collisions: list[Point2] = []
        self.lift_over_notch = lift_over_notch
        self.detect_collisions = detect_collisions
        self.keep = keep
        """Points kept in `strokes` (and as many in `travel`), the oldest dropped first; None keeps every point."""
        self.dropped = 0
        """Points dropped to stay within `keep`."""
        self._moves_since_trim = 0
        self._open = False
        """The last stroke is still under the pen."""

    def move(self, start: Point3, end: Point3, *, rapid: bool = False) -> None:
        self._mark(start, end, rapid=rapid)
        if self.keep is not None:
            self._moves_since_trim += 1
            if self._moves_since_trim >= TRIM_EVERY:
                self._moves_since_trim = 0
                self.dropped += _drop_oldest(self.strokes, self.keep) + _drop_oldest(self.travel, self.keep)

    def _mark(self, start: Point3, end: Point3, *, rapid: bool) -> None:
        a, b = (start[0], start[1]), (end[0], end[1])
        down0, down1 = start[2] < kin.PEN_DOWN_BELOW, end[2] < kin.PEN_DOWN_BELOW
        path = joint_path(a, b) if rapid and a != b else [a, b]
        if self.detect_collisions:
            self._check_body(path)
        if not (down0 and down1):
            self._open = False  # a lift happens before the XY motion
            if a != b:
                self.travel.append(path)
            if down1:
                self.strokes.append([b])  # and a drop after it: the pen lands at the end
                self._open = True
            return
        if a == b:
            if not self._open:
                self.strokes.append([a])
                self._open = True
            return
        if self.lift_over_notch and not rapid and kin.crosses_body_zone(a, b):
            pieces = reachable_pieces(a, b)
            if pieces != [[a, b]]:
                for piece in pieces:
                    self._draw(piece, join=piece[0] == a)
                self._open = bool(pieces) and pieces[-1][-1] == b
                return
        self._draw(path, join=True)

    def _draw(self, path: list[Point2], *, join: bool) -> None:
        if join and self._open and self.strokes and self.strokes[-1][-1] == path[0]:
            self.strokes[-1].extend(path[1:])
        else:
            self.strokes.append(list(path))
        self._open = True

    def _check_body(self, path: list[Point2]) -> None:
        for a, b in itertools.pairwise(path):
            if kin.crosses_body_zone(a, b):
                self.collisions.append(_first_in_zone(a, b))
                return


TRIM_EVERY = 1000
"""Moves between two checks of a bounded record: it may exceed `keep` by what these moves add."""


def _drop_oldest(lines: list[list[Point2]], keep: int) -> int:
    """Drop the oldest polylines, or the start of the oldest, until `lines` holds at most `keep` points; returns
    how many were dropped. The newest polyline keeps its end, so a stroke under the pen still joins on."""
    excess = sum(map(len, lines)) - keep
    dropped = 0
    while excess > 0 and lines:
        first = lines[0]
        if len(first) <= excess and len(lines) > 1:
            del lines[0]
            taken = len(first)
        else:
            taken = min(excess, len(first) - 1)
            del first[:taken]
            if taken == 0:
                break
        excess -= taken
        dropped += taken
    return dropped


def _first_in_zone(a: Point2, b: Point2, step: float = 1.0) -> Point2:
    n = max(1, math.ceil(math.hypot(b[0] - a[0], b[1] - a[1]) / step))
    for k in range(n + 1):
        point = (a[0] + (b[0] - a[0]) * k / n, a[1] + (b[1] - a[1]) * k / n)
        if kin.in_body_zone(*point):
            return point
    return b


def reachable_pieces(a: Point2, b: Point2, step: float = 2.0) -> list[list[Point2]]:
    """The parts of the segment a-b inside the drawing area, sampled every `step` units."""
    n = max(1, math.ceil(math.hypot(b[0] - a[0], b[1] - a[1]) / step))
    points = [(a[0] + (b[0] - a[0]) * k / n, a[1] + (b[1] - a[1]) * k / n) for k in range(n + 1)]
    inside = kin.reachable_mask([x for x, _ in points], [y for _, y in points])
    pieces: list[list[Point2]] = []
    run: list[Point2] = []
    for point, ok in zip(points, inside, strict=True):
        if ok:
            run.append(point)
        elif run:
            pieces.append([run[0], run[-1]])
            run = []
    if run:
        pieces.append([run[0], run[-1]])
    pieces = [piece for piece in pieces if piece[0] != piece[1]]
    if len(pieces) == 1 and pieces[0][0] == a and pieces[0][1] == b:
        return [[a, b]]
    return pieces


def joint_path(a: Point2, b: Point2, samples: int = 16) -> list[Point2]:
    """G00 runs each servo at full speed, so the pen sweeps a curve between the joint angles, not a line."""
    try:
        ja, jb = kin.inverse(*a), kin.inverse(*b)
    except ValueError:
        return [a, b]
    out = []
    for k in range(samples + 1):
        t = k / samples
        out.append(kin.forward(kin.Joints(ja.shoulder + (jb.shoulder - ja.shoulder) * t,
                                          ja.elbow + (jb.elbow - ja.elbow) * t)))
    out[0], out[-1] = a, b
    return out


# -- files ------------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ProgramLine:
    number: int
    """1-based line number in the file."""
    text: str
    """The command as the machine receives it: comments and surrounding blanks removed."""
    command: p.Command


@dataclass
class Program:
    """A G-code file read line by line: the commands, and the lines skipped (number, text, why)."""

    lines: list[ProgramLine] = field(default_factory=list)
    skipped: list[tuple[int, str, str]] = field(default_factory=list)

    def skipped_note(self) -> str | None:
        if not self.skipped:
            return None
        number, text, why = self.skipped[0]
        return (f"skipped {len(self.skipped)} line(s) the Line-us refuses and draws on without "
                f"(first: line {number} {text!r}: {why})")


def strip_comment(raw: str) -> str:
    return _COMMENT.sub("", raw).replace("\x00", "").strip()


def read_program(text: str, *, name: str = "G-code", strict: bool = True) -> Program:
    """Every line of a G-code file through the device's own grammar.

    strict: a line the Line-us would refuse raises InputError (`file, line N: why`), except the harmless codes of
    other dialects (`G90`, `G21`, unknown M-codes), which are skipped and listed. Not strict: every refused line
    is skipped, as the firmware's memory drawing answers it with `error` and plays on.
    """
    program = Program()
    for number, raw in enumerate(text.splitlines(), start=1):
        line = strip_comment(raw)
        if not line:
            continue
        try:
            command = p.parse_command(line)
        except RemoteProtocolError as exc:
            why = str(exc)
            if strict:
                _refuse(name, number, line, why)
            program.skipped.append((number, line, why))
            continue
        program.lines.append(ProgramLine(number, line, command))
    return program


def _refuse(name: str, number: int, line: str, why: str) -> None:
    """Raise for a line the grammar refused, unless it is a harmless code of another dialect."""
    code = p.command_code(line)
    where = f"{name}, line {number}"
    if code is None:
        raise InputError(f"{where}: cannot read {excerpt(line, 60)}: not a Line-us G-code line")
    if code in OTHER_DIALECTS:
        raise InputError(f"{where}: {code} ({OTHER_DIALECTS[code]}) is not supported by the Line-us")
    if code in HARMLESS or (code.startswith("M") and why.startswith("unknown command")):
        return
    if why.startswith("unknown command"):
        raise InputError(f"{where}: unknown command {code} in {excerpt(line, 60)}")
    raise InputError(f"{where}: cannot read parameters of {excerpt(line, 60)}: {why}")


@dataclass
class Traced:
    """A program run on paper: the ink, and how many moves the firmware's area rule changed."""

    ink: Ink
    program: Program
    clamped: int = 0
    end: Point3 = HOME3


def run_program(program: Program, interpreter: Interpreter, ink: Ink, start: Point3 = HOME3) -> Traced:
    """Run the program's moves from `start`, inking as the arm would; settings without geometry are passed over."""
    here = start
    clamped = 0
    for line in program.lines:
        command = line.command
        if isinstance(command, p.SetOrigin):
            interpreter.set_origin(command)
        elif isinstance(command, p.Move | p.Home | p.RawMove):
            motion = interpreter.motion(command, here, line.text)
            clamped += motion.clamped
            ink.move(here, motion.target, rapid=motion.rapid)
            here = motion.target
    return Traced(ink, program, clamped, here)


def trace_text(text: str, *, name: str = "G-code") -> Traced:
    """What a G-code file draws, in raw geometry (no area rule), from home with the pen up."""
    return run_program(read_program(text, name=name), Interpreter(clamp=False), Ink())

