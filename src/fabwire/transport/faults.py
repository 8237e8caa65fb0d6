"""A seeded, deterministic fault injector that wraps any transport.

The same seed and the same traffic give the same faults, so a failing robustness case replays exactly.
"""

from __future__ import annotations

import asyncio
import re
from typing import TYPE_CHECKING, Annotated, Literal

import msgspec

from fabwire.errors import InputError, LinkClosed, excerpt
from fabwire.transport.base import DEFAULT_READ_SIZE, Transport

if TYPE_CHECKING:
    import random

Side = Literal["both", "write", "read"]
Count = Annotated[int, msgspec.Meta(ge=0)]
Probability = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]


class FaultPlan(msgspec.Struct, frozen=True):
    """What to do to the bytes; every field off by default."""

    chunk: Count = 0
    """Split each write (and each read handed up) into pieces of 1..chunk bytes."""
    delay: Annotated[float, msgspec.Meta(ge=0.0, le=60.0)] = 0.0
    """Sleep up to this many seconds before each piece."""
    drop: Probability = 0.0
    """Probability that a piece vanishes."""
    corrupt: Probability = 0.0
    """Probability that a byte gets one bit flipped."""
    silent_after: Count | None = None
    """After this many bytes have passed, pass nothing more (the peer seems to hang)."""
    disconnect_after: Count | None = None
    """After this many bytes have passed, close the link."""
    side: Side = "both"
    """Which direction the faults apply to, seen from the wrapped end."""
    seed: int = 0
    extra: dict[str, str] = msgspec.field(default_factory=dict)

    @classmethod
    def parse(cls, text: str) -> FaultPlan:
        """Parse `chunk=1,delay=0.01,drop=0.05,corrupt=0.001,silent_after=100,disconnect_after=5000,seed=3`.

        Raises InputError for an unknown setting or a value out of its range (counts ≥ 0, probabilities 0-1,
        delays 0-60 s)."""
        values: dict[str, object] = {}
        for item in filter(None, (part.strip() for part in text.split(","))):
            key, sep, raw = item.partition("=")
            key = key.strip().replace("-", "_")
            if not sep:
                raise InputError(f"fault setting {item!r} needs a value (key=value)")
            try:
                if key in ("chunk", "silent_after", "disconnect_after", "seed"):
                    if not re.fullmatch(r"-?[0-9]{1,18}", raw.strip()):  # ASCII, few: int() refuses 4,300
                        raise ValueError(raw)
                    values[key] = int(raw)
                elif key in ("delay", "drop", "corrupt"):
                    values[key] = float(raw)
                elif key == "side" and raw in ("both", "write", "read"):
                    values[key] = raw
                else:
                    raise InputError(f"unknown fault setting {excerpt(key, 40)}")
            except ValueError:
                raise InputError(f"fault setting {excerpt(key, 40)} has a bad value {excerpt(raw, 40)}") from None
        try:
            return msgspec.convert(values, cls)
        except msgspec.ValidationError as exc:  # nan fails every range check too
            raise InputError(f"fault plan {excerpt(text, 80)}: {exc}") from None


class FaultyTransport(Transport):
    def __init__(self, inner: Transport, plan: FaultPlan) -> None:
        self._inner = inner
        self._plan = plan
        import random  # only where faults are injected: a command without them does not load it

        self._rng: random.Random = random.Random(plan.seed)
        self._passed = 0
        self._silent = False
        self._disconnected = False
        self._pending = bytearray()
        self._closed_event = asyncio.Event()
        self.url = inner.url
        self.peer = inner.peer
        self.dropped = 0
        self.corrupted = 0

    @property
    def closed(self) -> bool:
        return self._disconnected or self._inner.closed

    def _applies(self, side: Literal["write", "read"]) -> bool:
        return self._plan.side in ("both", side)

    def _pieces(self, data: bytes) -> list[bytes]:
        if self._plan.chunk <= 0:
            return [data]
        pieces, i = [], 0
        while i < len(data):
            size = self._rng.randint(1, self._plan.chunk)
            pieces.append(data[i : i + size])
            i += size
        return pieces

    def _mangle(self, piece: bytes) -> bytes:
        if self._plan.drop and self._rng.random() < self._plan.drop:
            self.dropped += len(piece)
            return b""
        if not self._plan.corrupt:
            return piece
        out = bytearray(piece)
        for i in range(len(out)):
            if self._rng.random() < self._plan.corrupt:
                out[i] ^= 1 << self._rng.randrange(8)
                self.corrupted += 1
        return bytes(out)

    def _budget(self, piece: bytes) -> tuple[bytes, bool]:
        """Cut `piece` at the silence/disconnect limit; say whether the limit was reached."""
        limits = [n for n in (self._plan.silent_after, self._plan.disconnect_after) if n is not None]
        if not limits:
            self._passed += len(piece)
            return piece, False
        room = max(0, min(limits) - self._passed)
        head = piece[:room]
        self._passed += len(head)
        return head, len(head) < len(piece) or self._passed >= min(limits)

    async def _trip(self) -> None:
        if self._plan.disconnect_after is not None and self._passed >= self._plan.disconnect_after:
            self._disconnected = True
            await self._inner.close()
            self._closed_event.set()
        else:
            self._silent = True

    def _check(self) -> None:
        if self._disconnected:
            raise LinkClosed(f"link to {self.peer} dropped (injected fault)")

    async def write(self, data: bytes) -> None:
        self._check()
        if not self._applies("write"):
            await self._inner.write(data)
            return
        for piece in self._pieces(data):
            if self._silent:
                return
            if self._plan.delay:
                await asyncio.sleep(self._rng.uniform(0, self._plan.delay))
            piece, tripped = self._budget(self._mangle(piece))
            if piece:
                await self._inner.write(piece)
            if tripped:
                await self._trip()
                self._check()
                return

    async def read(self, max_bytes: int = DEFAULT_READ_SIZE) -> bytes:
        while True:
            self._check()
            if self._silent:
                await self._closed_event.wait()
                self._check()
                raise LinkClosed(f"link to {self.peer} is closed")
            if not self._applies("read"):
                return await self._inner.read(max_bytes)
            if not self._pending:
                data = await self._inner.read(max_bytes)
                for piece in self._pieces(data):
                    self._pending += self._mangle(piece)
                if not self._pending:
                    continue
            size = len(self._pending)
            if self._plan.chunk > 0:
                size = min(size, self._rng.randint(1, self._plan.chunk))
            size = min(size, max_bytes)
            if self._plan.delay:
                await asyncio.sleep(self._rng.uniform(0, self._plan.delay))
            piece, tripped = self._budget(bytes(self._pending[:size]))
            del self._pending[:size]
            if tripped:
                await self._trip()
                if not piece:
                    continue
            if piece:
                return piece

    async def close(self) -> None:
        self._closed_event.set()
        self._disconnected = True
        await self._inner.close()
