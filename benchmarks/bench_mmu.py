"""MMU3 codec throughput (one core, streaming) and host CPU per tool change against the in-process simulator."""

from __future__ import annotations

import random
import time

try:
    from common import Figure
except ImportError:  # imported as benchmarks.bench_mmu
    from benchmarks.common import Figure
from fabwire.mmu import host as h
from fabwire.mmu import protocol as p
from fabwire.mmu.sim import Lockstep, MMUSimulator

CHUNK = 4096
REPEAT = 5
"""Best of several runs for the distinct-frame figure and its baseline: the machine is shared, and the
least-disturbed run is the codec's own speed."""


def _reply_mix() -> list[p.Response]:
    """What a printer receives in one heartbeat cycle during a tool change."""
    return [p.Processing("T", 1, 5), p.Accepted("f", 0), p.Accepted("R", 8, 1), p.Accepted("R", 0x1B, 1),
            p.Accepted("R", 0x1C, 1), p.Accepted("R", 4, 75), p.Accepted("R", 0x1A, 388)]


def _request_mix() -> list[p.Request]:
    return [p.Query(0), p.FSensorState(0), p.Read(8), p.Read(0x1B), p.Read(0x1C), p.Read(4), p.Read(0x1A)]


def _rate(work: int, seconds: float) -> float:
    return work / seconds if seconds > 0 else float("inf")


def _time(func: object, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        func()  # type: ignore[operator]
        best = min(best, time.perf_counter() - start)
    return best


def bench_encode() -> Figure:
    messages = _request_mix() * 20000
    seconds = _time(lambda: [p.encode_request(m) for m in messages], 3)
    rate = _rate(len(messages), seconds)
    return Figure("mmu: encode requests (streaming)", rate, "frames/s", ">= 1,000,000", rate >= 1e6)


def _stream(messages: list[p.Response]) -> list[bytes]:
    wire = b"".join(p.encode(m) for m in messages)
    return [wire[i:i + CHUNK] for i in range(0, len(wire), CHUNK)]


def bench_decode() -> list[Figure]:
    frames = _reply_mix() * 30000
    chunks = _stream(frames)

    def fast() -> None:
        decoder = p.ResponseDecoder()
        for chunk in chunks:
            decoder.feed(chunk)

    rate = _rate(len(frames), _time(fast, 3))

    few = frames[:7000]
    few_chunks = _stream(few)

    def exact() -> None:
        decoder = p.ResponseDecoder()
        events: list[object] = []
        for chunk in few_chunks:
            for byte in chunk:
                decoder._step(byte, events)

    baseline = _rate(len(few), _time(exact, 2))
    out = [Figure("mmu: decode replies (streaming, repetitive traffic, memo hits)", rate, "frames/s",
                  ">= 1,000,000", rate >= 1e6,
                  baseline, "exact byte automaton")]

    rng = random.Random(7)
    distinct = [p.RESPONSE_TYPES[rng.choice("APEFB")](rng.choice(p.REQUEST_CODES), rng.randrange(256),
                                                       rng.randrange(65536)) for _ in range(100000)]
    distinct_chunks = _stream(distinct)

    def unseen() -> None:
        decoder = p.ResponseDecoder()
        for chunk in distinct_chunks:
            decoder.feed(chunk)

    some = distinct[:20000]
    some_chunks = _stream(some)

    def exact_distinct() -> None:
        decoder = p.ResponseDecoder()
        events: list[object] = []
        for chunk in some_chunks:
            for byte in chunk:
                decoder._step(byte, events)

    distinct_rate = _rate(len(distinct), _time(unseen, REPEAT))
    out.append(Figure("mmu: decode replies, every frame distinct (no memo hits)", distinct_rate, "frames/s",
                      ">= 1,000,000", distinct_rate >= 1e6,
                      _rate(len(some), _time(exact_distinct, REPEAT)), "exact byte automaton"))
    return out


class _Metered:
    """Counts the CPU time spent inside the host logic only."""

    def __init__(self, inner: h.HostLogic) -> None:
        self.inner = inner
        self.cpu = 0.0

    def _timed(self, func, *args):  # type: ignore[no-untyped-def]
        start = time.process_time()
        try:
            return func(*args)
        finally:
            self.cpu += time.process_time() - start

    def data_to_send(self) -> bytes:
        return self._timed(self.inner.data_to_send)  # type: ignore[no-any-return]

    def receive(self, data: bytes, now: float) -> None:
        self._timed(self.inner.receive, data, now)

    def handle_timer(self, now: float) -> None:
        self._timed(self.inner.handle_timer, now)

    def next_deadline(self) -> float | None:
        return self._timed(self.inner.next_deadline)  # type: ignore[no-any-return]

    def events(self) -> list[h.HostEvent]:
        return self._timed(self.inner.events)  # type: ignore[no-any-return]


def bench_tool_change() -> Figure:
    clock = [0.0]
    sim = MMUSimulator("3.0.4", clock=lambda: clock[0])
    logic = h.HostLogic()
    metered = _Metered(logic)
    pair = Lockstep(metered, sim)
    logic.start(0.0)
    pair.run(lambda new: any(isinstance(e, h.LinkUp) for e in new))
    changes = 200
    metered.cpu = 0.0
    for i in range(changes):
        start = time.process_time()
        logic.plan_command(p.ToolChange(i % 5), pair.now)
        metered.cpu += time.process_time() - start
        events = pair.run(lambda new: any(isinstance(e, h.CommandFinished) for e in new))
        assert isinstance(events[-1], h.CommandFinished), events[-1]
    per_change_ms = metered.cpu / changes * 1000
    return Figure("mmu: host CPU per tool change (in-process simulator, fake clock)", per_change_ms, "ms CPU",
                  "< 5", per_change_ms < 5)


def bench_noisy_line() -> list[Figure]:
    """The full client (asyncio, memory link with 1 % of bytes flipped both ways) on a fake clock."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from robustness.fakeclock import run_on_fake_clock
    from robustness.noisy_mmu import noisy_tool_changes

    changes = 200
    start = time.perf_counter()
    report = run_on_fake_clock(noisy_tool_changes(changes, corrupt=0.01, seed=99))
    wall = time.perf_counter() - start
    share = report.completed / changes * 100
    return [Figure("mmu: tool changes completed through 1 % byte corruption (both ways)", share, "%", ">= 99",
                   share >= 99),
            Figure("mmu: wall time per noisy tool change (fake clock, 1× MMU timing)", wall / changes * 1000,
                   "ms", "< 300", wall / changes < 0.3)]


def run() -> list[Figure]:
    return [bench_encode(), *bench_decode(), bench_tool_change(), *bench_noisy_line()]


if __name__ == "__main__":
    for figure in run():
        extra = f"  (baseline {figure.baseline:,.0f} {figure.baseline_name})" if figure.baseline else ""
        print(f"{figure.name}: {figure.value:,.2f} {figure.unit} target {figure.target or '-'}{extra}")
