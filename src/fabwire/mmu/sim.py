"""An MMU3 on the wire: the firmware's request automaton and dispatch rules in front of the machine model.

One request is processed per tick, nothing is ever sent unprompted, X/F/garbage/bad CRC get no reply, and the
UART is deaf while booting. Model time = real time × speed, from an injectable clock.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from typing import Any, Protocol

from fabwire.errors import InputError, LinkClosed, excerpt
from fabwire.mmu import codes, units
from fabwire.mmu.faults import HANDS, PHYSICAL_BUTTONS, Fault, parse_fault
from fabwire.mmu.machine import HistoryItem
from fabwire.mmu.model import MMUModel
from fabwire.mmu.protocol import Request, RequestDecoder, encode_response
from fabwire.simspeed import checked_speed
from fabwire.transport import Transport, register_simulator, spawn_in_process

HANDS_LINE_LIMIT = 200
PHANTOM_LINE = b"a\n"
"""One garbage byte and a newline: what the `phantom-reply` fault sends after a reply."""
PENDING_LIMIT = 8
"""Decoded requests waiting for the main loop; the real RX ring holds 32 bytes, so a flood loses messages."""


class Port:
    """One line into the MMU: its own request decoder and queue of decoded requests.

    A real MMU has one UART. Over TCP every connection gets its own Port, so one client's stray or half-sent
    bytes never mix with another's requests; all ports drive the same machine, one request per tick."""

    def __init__(self, phantoms: bool = False) -> None:
        self.decoder = RequestDecoder(phantoms=phantoms)
        self.pending: deque[Request] = deque()
        self.dropped = 0

    def reset(self) -> None:
        self.decoder.reset()
        self.pending.clear()


def firmware(version: str) -> codes.FirmwareVersion:
    try:
        return codes.FIRMWARES[version]
    except KeyError:
        raise InputError(f"unknown MMU firmware {excerpt(version, 20)}; choose one of "
                         f"{', '.join(codes.FIRMWARES)}") from None


class MMUSimulator:
    """A whole MMU: control plane (faults, buttons) plus `serve(transport)`, one decoder per connection."""

    def __init__(self, version: str = "3.0.4", *, speed: float = 1.0, faults: Iterable[str | Fault] = (),
                 clock: Callable[[], float] | None = None, arithmetic: str = units.DEFAULT_FLOAT,
                 phantom_requests: bool = False) -> None:
        """`arithmetic`: whose floating point the firmware's unit conversions use, "pc" (the firmware built for a
        PC, as its own test runs do) or "avr" (the MMU board's 32-bit floats); see `fabwire.mmu.units`.
        `phantom_requests`: a one-byte garbage line right after a request repeats that request, as the firmware's
        response decoder repeats a response (`fabwire.mmu.protocol` `phantoms`): a host that sends such bytes can
        be tested against it. The fault `phantom-reply` makes the simulator send such lines itself."""
        self.phantom_requests = phantom_requests
        self.speed = checked_speed(speed)
        if arithmetic not in units.FLOAT_FORMATS:
            raise InputError(f"unknown MMU arithmetic {excerpt(arithmetic, 20)}; choose one of "
                             f"{', '.join(units.FLOAT_FORMATS)}")
        self._clock = clock or time.monotonic
        self._t0 = self._clock()
        parsed = tuple(parse_fault(f) if isinstance(f, str) else f for f in faults)
        self.model = MMUModel(firmware(version), faults=parsed, now=0.0,
                              float_format=units.FLOAT_FORMATS[arithmetic])
        self._port = Port(phantom_requests)
        """The line `receive`/`tick`/`exchange` use when no port is given (in-process and lockstep use)."""
        self._ports: list[Port] = [self._port]

    # ------------------------------------------------------------------------------------------ sans-IO

    def now(self) -> float:
        """Model seconds since power-on."""
        return (self._clock() - self._t0) * self.speed

    def receive(self, data: bytes, now: float | None = None, port: Port | None = None) -> None:
        """Bytes from the printer. While booting they are lost, as on the real UART."""
        port = port or self._port
        now = self.now() if now is None else now
        self.model.advance(now)
        if self.model.booting:
            return
        for event in port.decoder.feed(data):
            if isinstance(event, Request):
                if len(port.pending) >= PENDING_LIMIT:
                    port.dropped += 1
                    continue
                port.pending.append(event)

    @property
    def pending(self) -> int:
        return len(self._port.pending)

    @property
    def dropped_requests(self) -> int:
        return sum(p.dropped for p in self._ports)

    def tick(self, now: float | None = None, port: Port | None = None) -> bytes:
        """One main-loop pass: process at most one request; return the reply bytes (often none)."""
        port = port or self._port
        now = self.now() if now is None else now
        self.model.advance(now)
        if self.model.booting:
            port.pending.clear()
            return b""
        if not port.pending:
            return b""
        reply = self.model.handle(port.pending.popleft(), now)
        if self.model.booting:  # X: the board resets, whatever was still queued on any line is lost
            for each in self._ports:
                each.reset()
        if reply is None:
            return b""
        data = encode_response(reply)
        if self.model.faults.hit("phantom-reply"):
            data += PHANTOM_LINE
        return data

    def exchange(self, data: bytes, now: float | None = None) -> bytes:
        """Receive `data` and run ticks until every complete request has been handled."""
        self.receive(data, now)
        out = bytearray()
        while self._port.pending:
            out += self.tick(now)
        return bytes(out)

    # ------------------------------------------------------------------------------------------ control

    def inject(self, fault: str | Fault) -> None:
        """A cause appears: `NAME` stays until removed, `NAME:N` fails N checks (`fabwire.mmu.faults`)."""
        self.model.advance(self.now())
        self.model.inject(fault)

    def remove_cause(self, name: str | None = None) -> list[str]:
        """The owner removes a cause (all when None); its error waits for Retry or a reset. Returns what was
        there."""
        self.model.advance(self.now())
        return self.model.remove_cause(name)

    def clear_faults(self, name: str | None = None) -> None:
        self.remove_cause(name)

    def causes(self) -> dict[str, int]:
        """The causes present: name → checks they will still fail (-1: until removed)."""
        return self.model.causes()

    def press(self, button: int) -> None:
        """A press on the MMU's own buttons: 0 Right, 1 Middle, 2 Left."""
        self.model.advance(self.now())
        self.model.press(button)

    def power_cycle(self) -> None:
        """Off and on again: the UART is deaf while it boots, the EEPROM and every cause stay."""
        self.model.power_cycle(self.now())
        for port in self._ports:
            port.reset()

    def hands(self, action: str, argument: str = "") -> dict[str, Any]:
        """One act of the owner's hands on the machine (`HANDS`), as a JSON-able answer; InputError for an unknown
        action, button or cause, or for removing a cause that is not there."""
        action = action.strip().lower()
        argument = argument.strip()
        if action == "remove":
            name = parse_fault(argument).name if argument else None
            removed = self.remove_cause(name)
            if not removed:
                present = ", ".join(self.causes()) or "none"
                raise InputError(f"nothing to remove: {name or 'no cause'} is not present (present: {present})")
            return {"removed": removed, "causes": self.causes()}
        if action == "press":
            button = PHYSICAL_BUTTONS.get(argument.lower())
            if button is None:
                raise InputError(f"press which button? left, middle or right, not {excerpt(argument, 20)}")
            self.press(button)
            return {"pressed": argument.lower()}
        if action == "power-cycle":
            self.power_cycle()
            return {"power_cycled": True, "causes": self.causes()}
        if action == "inject":
            if not argument:
                raise InputError("inject which cause? NAME (until removed) or NAME:N (fails N checks)")
            self.inject(argument)
            return {"injected": parse_fault(argument).name, "causes": self.causes()}
        if action == "causes":
            return {"causes": self.causes()}
        raise InputError(f"unknown action {excerpt(action, 20)}; choose one of {', '.join(HANDS)}")

    async def serve_hands(self, transport: Transport) -> None:
        """The control plane on a connection: one action a line (`remove finda-stuck`, `press middle`,
        `power-cycle`, `inject NAME[:N]`, `causes`), one JSON object a line back (`{"ok": true, …}` or
        `{"ok": false, "error": …}`)."""
        buffer = b""
        try:
            while True:
                buffer += await transport.read(256)
                while b"\n" in buffer:
                    line, buffer = buffer.split(b"\n", 1)
                    action, _, argument = line.decode("utf-8", "replace").strip().partition(" ")
                    try:
                        answer: dict[str, Any] = {"ok": True, **self.hands(action, argument)}
                    except InputError as exc:
                        answer = {"ok": False, "error": str(exc)}
                    await transport.write(json.dumps(answer).encode() + b"\n")
                if len(buffer) > HANDS_LINE_LIMIT:
                    await transport.write(b'{"ok": false, "error": "line too long"}\n')
                    return
        except LinkClosed:
            return

    @property
    def history(self) -> list[HistoryItem]:
        return list(self.model.history)

    def progress_sequence(self, command: str | None = None) -> list[str]:
        """`P5`, `E8001`, `F0`… in order, for one command's echo (e.g. 'T1') or all."""
        return [f"{h.kind}{h.value:x}" for h in self.model.history if command is None or h.command == command]

    # ------------------------------------------------------------------------------------------ serving

    async def serve(self, transport: Transport) -> None:
        """Answer one connection until it closes. Every connection sees the same machine through its own
        decoder, so clients never corrupt each other's requests (replies go to whoever asked)."""
        port = Port(self.phantom_requests)
        self._ports.append(port)
        try:
            while True:
                data = await transport.read(256)
                self.receive(data, port=port)
                while port.pending:
                    out = self.tick(port=port)
                    if out:
                        await transport.write(out)
                    await asyncio.sleep(0)
        except LinkClosed:
            return
        finally:
            self._ports.remove(port)


def options_to_simulator(options: dict[str, str]) -> MMUSimulator:
    """Build a simulator from `sim://mmu?speed=…&version=…&fault=…&arithmetic=…&phantom_requests=1`, read by the
    one table of simulator options (`fabwire.transport.simaddress.MMU_OPTIONS`)."""
    from fabwire.transport.simaddress import read_options

    given = read_options("mmu", options)
    return MMUSimulator(given.get("version", "3.0.4"), speed=given.get("speed", 1.0), faults=given.get("fault", ()),
                        arithmetic=given.get("arithmetic", units.DEFAULT_FLOAT),
                        phantom_requests=given.get("phantom_requests", False))


async def _factory(options: dict[str, str]) -> Transport:
    return await spawn_in_process("mmu", options_to_simulator(options).serve)


register_simulator("mmu", _factory)


class Lockstep:
    """A host core and a simulator wired together on one fake clock: deterministic, instant, no I/O.

    `host` needs `data_to_send`, `receive(data, now)`, `handle_timer(now)`, `next_deadline()` and `events()`.
    """

    def __init__(self, host: LockstepHost, simulator: MMUSimulator, now: float = 0.0) -> None:
        self.host = host
        self.sim = simulator
        self.now = now
        self.wire: list[tuple[float, str, bytes]] = []
        self.record = False

    def run(self, until: Callable[[list[object]], bool], limit: float = 600.0,
            mangle: Callable[[bytes], bytes] | None = None) -> list[object]:
        """Advance until `until(new_events)` is true or `limit` seconds of fake time pass; return all events."""
        seen: list[object] = []
        end = self.now + limit
        while True:
            data = self.host.data_to_send()
            if data:
                if self.record:
                    self.wire.append((self.now, ">", data))
                reply = self.sim.exchange(data, self.now)
                if reply and mangle is not None:
                    reply = mangle(reply)
                if reply:
                    if self.record:
                        self.wire.append((self.now, "<", reply))
                    self.host.receive(reply, self.now)
            new = list(self.host.events())
            seen += new
            if new and until(new):
                return seen
            if data:
                continue
            deadline = self.host.next_deadline()
            if deadline is None or deadline > end:
                return seen
            self.now = max(self.now, deadline)
            self.host.handle_timer(self.now)


class LockstepHost(Protocol):
    def data_to_send(self) -> bytes: ...
    def receive(self, data: bytes, now: float) -> None: ...
    def handle_timer(self, now: float) -> None: ...
    def next_deadline(self) -> float | None: ...
    def events(self) -> Sequence[object]: ...
