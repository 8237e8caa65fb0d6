"""`fabwire lineus shell`: one connection for a whole session of moves, pen changes and G-code lines.

Every other CLI call opens a new connection, and the firmware homes the arm on connect, so a series of `move`s
bounces home between moves; here the arm stays where it was sent. Lines come from standard input (a terminal gets
a prompt and line editing; a pipe works the same, line by line). With --json every line's outcome is one JSON
object on stdout: `{"line", "position": {...}}` (as `lineus position --json` prints it),
`{"line", "reply": {"ok", "text", "fields"}}`, `{"line", "text"}`, `{"line", "error"}` or `{"notice"}`.
"""

from __future__ import annotations

import asyncio
import re
import sys
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

import click

from fabwire.cli_support import DeviceContext, pass_device
from fabwire.errors import DeviceError, InputError, LocalProtocolError, RemoteProtocolError
from fabwire.lineus import kinematics as kin
from fabwire.lineus import protocol as p
from fabwire.lineus.client import LineUs, Position

HELP = """\
move X Y [up|down]   G01 to machine point X Y (pen as it is, or lifted/lowered on the way)
up | down            lift or lower the pen where it is
home                 back to (1000, 1000), pen up
position | pos       where the arm is (M114)
speed S [P]          largest step while drawing (S) and travelling (P), 1-30
G.. / M..            any Line-us G-code line, sent as it is (checked first); the reply is printed
history              the lines entered so far
help                 this text
quit | exit          end the session (so does end of input)"""

_GCODE = re.compile(r"[GgMm]\d")


@dataclass
class Session:
    arm: LineUs
    emit: Callable[[dict[str, Any], str], None]
    """Shows one outcome: as a JSON object (--json) or as its line of text."""
    history: list[str] = field(default_factory=list)
    shown_notices: int = 0
    line: str = ""
    """The input line being run."""

    async def run_line(self, line: str) -> bool:
        """Run one input line; False when the session should end."""
        line = line.strip()
        words = line.split()
        if not words:
            return True
        self.history.append(line)
        self.line = line
        head = words[0].lower()
        if head in ("quit", "exit"):
            return False
        if head == "help":
            self._say(HELP)
        elif head == "history":
            self._say("\n".join(f"{n:>4}  {text}" for n, text in enumerate(self.history, 1)))
        elif _GCODE.match(words[0]):
            await self._gcode(line)
        else:
            action = self._commands().get(head)
            if action is None:
                raise InputError(f"unknown command {words[0]!r} (type help)")
            await action(words[1:])
        self._notices()
        return True

    def _commands(self) -> dict[str, Callable[[list[str]], Awaitable[None]]]:
        return {"move": self._move, "m": self._move, "up": self._pen(kin.Z_UP), "down": self._pen(kin.Z_DOWN),
                "home": self._home, "position": self._position, "pos": self._position, "speed": self._speed}

    async def _move(self, args: list[str]) -> None:
        if len(args) not in (2, 3) or (len(args) == 3 and args[2].lower() not in ("up", "down")):
            raise InputError("move X Y [up|down]")
        x, y = _number(args[0]), _number(args[1])
        z = None if len(args) == 2 else kin.Z_UP if args[2].lower() == "up" else kin.Z_DOWN
        where = await self.arm.move(x, y, z)
        if note := kin.clamp_note(x, y, notch_guarded=self.arm.guard_body):
            self.emit({"notice": note.split(":", 1)[0]}, note)
        self._show(where)

    def _pen(self, z: float) -> Callable[[list[str]], Awaitable[None]]:
        async def pen(args: list[str]) -> None:
            if args:
                raise InputError("up and down take no arguments")
            self._show(await self.arm.move(z=z))

        return pen

    async def _home(self, args: list[str]) -> None:
        self._show(await self.arm.home())

    async def _position(self, args: list[str]) -> None:
        self._show(await self.arm.position())

    async def _speed(self, args: list[str]) -> None:
        if len(args) not in (1, 2):
            raise InputError("speed S [P]")
        await self.arm.set_speed(_number(args[0]), _number(args[1]) if len(args) == 2 else None)
        self._say("ok")

    async def _gcode(self, line: str) -> None:
        try:
            command = p.parse_command(line.strip())
        except RemoteProtocolError as exc:
            raise InputError(f"not a Line-us command: {exc}") from None
        reply = await self.arm.send(command)
        self.emit({"line": self.line, "reply": {"ok": reply.ok, "text": reply.text(), "fields": reply.as_dict()}},
                  reply.text())

    def _say(self, text: str) -> None:
        self.emit({"line": self.line, "text": text}, text)

    def _show(self, where: Position) -> None:
        self.emit({"line": self.line, "position": where.as_dict()}, where.text())

    def _notices(self) -> None:
        for notice in self.arm.notices[self.shown_notices :]:
            self.emit({"notice": notice}, notice)
        self.shown_notices = len(self.arm.notices)


def _number(text: str) -> float:
    try:
        return p.parse_number(text, "coordinate")
    except LocalProtocolError as exc:
        raise InputError(str(exc)) from None


async def _read_line(prompt: str | None) -> str | None:
    """One line of standard input (None at its end), read off the event loop so replies keep flowing."""
    loop = asyncio.get_running_loop()
    if prompt is not None:
        try:
            return await loop.run_in_executor(None, input, prompt)
        except EOFError:
            return None
    line = await loop.run_in_executor(None, sys.stdin.readline)
    return line if line else None


@click.command("shell")
@pass_device
def shell(dctx: DeviceContext) -> None:
    """An interactive session on one connection: moves, pen, position, G-code lines and their replies.

    Reads commands line by line from standard input (type help); a wrong line gets a one-line error and the
    session goes on. Ends at `quit` or the end of input."""
    interactive = sys.stdin.isatty()
    if interactive:
        import readline  # noqa: F401  (line editing and arrow-key history at the prompt)

    async def main() -> int:
        failures = 0
        async with dctx.open(LineUs) as arm:
            hello = arm.hello
            dctx.output.note(f"connected to {hello.name} (firmware {hello.firmware_label}); type help")
            session = Session(arm, dctx.output.event)
            while (line := await _read_line("lineus> " if interactive else None)) is not None:
                try:
                    if not await session.run_line(line):
                        break
                except (InputError, DeviceError) as exc:
                    failures += 1
                    if dctx.output.json_mode:
                        dctx.output.event({"line": line.strip(), "error": str(exc)}, "")
                    click.echo(f"error: {exc}", err=True)
        return failures

    failures = asyncio.run(main())
    if failures:
        raise InputError(f"{failures} line(s) of the session failed (see above)")
