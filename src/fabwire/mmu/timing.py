"""Does the MMU's clock fit the host's? A simulator sped up N× moves its filament N× faster than any real MMU.

The pulley can feed at most at its load/unload feedrate (95 mm/s by default, registers 0x11/0x0d; reference §5.5).
The host polls the pulley position (register 0x1a) after every heartbeat; when the filament moved much farther
between two polls than that allows in the host's idea of MMU time, the MMU runs faster than the host assumes and
its timeouts (the printer's sensor report, the 2 s link timeout) no longer mean what they should.
"""

from __future__ import annotations

MAX_FEEDRATE = 95.0
"""mm/s: the fastest the pulley moves (load and unload feedrate defaults)."""
MARGIN = 2.0
"""Observed speed above MARGIN × MAX_FEEDRATE counts as a mismatch (position reads are whole millimetres)."""
MIN_TRAVEL = 50.0
"""mm: shorter moves are too coarse to judge."""


class TimingCheck:
    def __init__(self, time_scale: float) -> None:
        self.time_scale = time_scale
        self.too_fast: float | None = None
        """Roughly how many times faster than assumed the MMU runs, once seen; None while it fits."""
        self._last: tuple[float, int] | None = None

    def observe(self, now: float, pulley_mm: int | None) -> None:
        """Feed one polled pulley position (signed mm) taken at host time `now` (seconds)."""
        if pulley_mm is None:
            return
        last, self._last = self._last, (now, pulley_mm)
        if last is None or now <= last[0]:
            return
        travel = abs(pulley_mm - last[1])
        mmu_seconds = (now - last[0]) * self.time_scale
        if travel >= MIN_TRAVEL and travel / mmu_seconds > MARGIN * MAX_FEEDRATE:
            factor = travel / mmu_seconds / MAX_FEEDRATE
            self.too_fast = max(self.too_fast or 0.0, factor)
