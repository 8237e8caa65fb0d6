"""MMUs that lie: they accept a command and report it finished (`F0`) without doing it, or do it to another slot.

Run as a program it serves one on a loopback TCP port and prints `tcp://127.0.0.1:PORT` (for CLI tests):
`python lying_mmu.py idle|other-slot|no-reset SPEED`.
"""

from __future__ import annotations

import asyncio
import sys

from fabwire.mmu.codes import Progress
from fabwire.mmu.model import MMUModel
from fabwire.mmu.protocol import Accepted, Request, Response
from fabwire.mmu.sim import MMUSimulator, firmware
from fabwire.transport import serve_tcp


class IdleLiar(MMUModel):
    """Answers every command `A`, then `F0` at once: nothing moves, every register shows the state from before."""

    def _plan(self, code: str, value: int) -> Response:
        if self.state != Progress.OK:
            return super()._plan(code, value)
        self._script = None
        self.command = (code, value)
        self._finish()
        return Accepted(code, value)


class OtherSlotLiar(MMUModel):
    """Runs each slot command on the slot two further on, reporting it under the slot asked for."""

    def _plan(self, code: str, value: int) -> Response:
        if code not in "TLKE":
            return super()._plan(code, value)
        reply = super()._plan(code, (value + 2) % 5)
        self.command = (code, value)
        return type(reply)(code, value, reply.value)


class ResetDeafLiar(MMUModel):
    """Ignores X (reset) requests: never reboots, yet answers the handshake that follows."""

    def handle(self, request: Request, now: float) -> Response | None:
        if request.code == "X":
            self.advance(now)
            return None
        return super().handle(request, now)


LIARS: dict[str, type[MMUModel]] = {"idle": IdleLiar, "other-slot": OtherSlotLiar, "no-reset": ResetDeafLiar}


def lying_simulator(kind: str, speed: float) -> MMUSimulator:
    sim = MMUSimulator(speed=speed)
    sim.model = LIARS[kind](firmware("3.0.4"), now=sim.now())
    return sim


async def _main(kind: str, speed: float) -> None:
    server = await serve_tcp(lying_simulator(kind, speed).serve, "127.0.0.1", 0)
    print(f"tcp://127.0.0.1:{server.sockets[0].getsockname()[1]}", flush=True)
    await asyncio.sleep(120)  # bounded: the test that started it stops it long before


if __name__ == "__main__":
    asyncio.run(_main(sys.argv[1], float(sys.argv[2])))
