"""A simulator on a fake clock, spoken to in wire text: what the tests in this directory share."""

from __future__ import annotations

from fabwire.mmu.protocol import ResponseDecoder, encode, make_request
from fabwire.mmu.sim import MMUSimulator


class Wire:
    def __init__(self, version: str = "3.0.4", faults: tuple[str, ...] = (), booted: bool = True,
                 arithmetic: str = "pc") -> None:
        self.t = 0.0
        self.sim = MMUSimulator(version, faults=faults, clock=lambda: self.t, arithmetic=arithmetic)
        if booted:
            self.t = 5.0

    def raw(self, data: bytes, dt: float = 0.0) -> bytes:
        self.t += dt
        return self.sim.exchange(data, self.t)

    def send(self, text: str, dt: float = 0.0) -> str:
        """Send one request given as text without CRC (e.g. 'T1', 'W22 190'); return the reply text."""
        code, rest = text[0], text[1:]
        if code == "W":
            address, value = rest.split(" ")
            request = make_request("W", int(address, 16), int(value, 16))
        else:
            request = make_request(code, int(rest or "0", 16))
        reply = self.raw(encode(request), dt)
        if not reply:
            return ""
        events = ResponseDecoder().feed(reply)
        assert len(events) == 1, reply
        return str(events[0])

    def run_until(self, finished: str, *, step: float = 0.25, limit: float = 400.0,
                  fsensor_follow: bool = True) -> list[str]:
        """Poll Q0 like a printer (reporting f1 on P1c, f0 on P3) until the reply equals `finished`."""
        replies: list[str] = []
        end = self.t + limit
        while self.t < end:
            reply = self.send("Q0", step)
            if not replies or replies[-1] != reply:
                replies.append(reply)
            if fsensor_follow and reply.endswith(" P1c"):
                assert self.send("f1") == "f1 A"
            if fsensor_follow and reply.endswith(" P3"):
                assert self.send("f0") == "f0 A"
            if reply == finished:
                return replies
        raise AssertionError(f"never reached {finished!r}: {replies}")
