"""A job's figures (`fabwire.agent.model.job_figures`) over any record: durations that move on with the clock and
stay within what the printer's own whole-minute elapsed time allows, progress, filament and layer that follow
progress, and a finished job's figures that no longer move."""

from __future__ import annotations

from datetime import UTC, datetime

from hypothesis import given
from hypothesis import strategies as st

from fabwire.agent.model import PRINTER_ELAPSED_STEP_S, job_figures

START = 1_800_000_000.0


def iso(epoch: float) -> str:
    return datetime.fromtimestamp(epoch, UTC).isoformat().replace("+00:00", "Z")


@st.composite
def running_jobs(draw: st.DrawFn) -> tuple[dict[str, object], float]:
    """A running job record as the agent keeps it, and a moment after its last news."""
    run_for = draw(st.floats(0, 20_000))
    said_at = START + draw(st.floats(0, run_for))
    said = draw(st.sampled_from([None, *(60.0 * m for m in range(400))]))
    paused = draw(st.floats(0, run_for))
    job = {"state": "running", "started": iso(START), "finished": None,
           "progress_percent": draw(st.floats(0, 100)), "size_bytes": draw(st.integers(0, 10**9)),
           "file_meta": draw(st.one_of(st.none(), st.fixed_dictionaries({
               "filament_mm": st.floats(0.1, 1e5), "layers": st.one_of(st.none(), st.integers(1, 5000)),
               "print_time_s": st.one_of(st.none(), st.integers(1, 10**6))}))),
           "paused_s": paused, "paused_since": None, "resumed_at": None,
           "printer_elapsed": None if said is None else [said, said_at]}
    return job, START + run_for


@given(running_jobs(), st.floats(0, 5_000))
def test_durations_go_on_with_the_clock_within_the_printers_minute(case: tuple[dict[str, object], float],
                                                                    later: float) -> None:
    job, now = case
    first, second = job_figures(job, now), job_figures(job, now + later)
    assert 0 <= first.print_s <= first.total_s
    assert first.total_s <= second.total_s <= first.total_s + later + 0.002  # never a jump of a minute
    said = job["printer_elapsed"]
    if said is not None:
        value, since = said  # type: ignore[misc]
        assert value - 0.001 <= first.total_s <= value + PRINTER_ELAPSED_STEP_S + (now - since) + 0.001


@given(running_jobs())
def test_progress_filament_and_layer_follow_each_other(case: tuple[dict[str, object], float]) -> None:
    job, now = case
    figures = job_figures(job, now)
    meta = job["file_meta"] or {}
    assert 0.0 <= figures.fraction <= 1.0
    assert figures.position == int(figures.size * figures.fraction)
    filament = meta.get("filament_mm")  # type: ignore[union-attr]
    assert figures.filament_used_mm == (round(filament * figures.fraction, 2) if filament else 0.0)
    layers = meta.get("layers")  # type: ignore[union-attr]
    if layers is None:
        assert figures.current_layer is None
    else:
        assert 0 <= figures.current_layer <= layers  # type: ignore[operator]
        assert (figures.current_layer == 0) == (figures.fraction == 0)


@given(running_jobs(), st.sampled_from(["done", "cancelled", "failed"]), st.floats(1, 10**6))
def test_an_ended_job_keeps_its_figures(case: tuple[dict[str, object], float], end: str, later: float) -> None:
    job, now = case
    ended = {**job, "state": end, "finished": iso(now)}
    at_end, afterwards = job_figures(ended, now), job_figures(ended, now + later)
    assert at_end == afterwards
    if end == "done":
        assert at_end.fraction == 1.0
        assert at_end.current_layer == (job["file_meta"] or {}).get("layers")  # type: ignore[union-attr]
    assert at_end.printing_s == 0.0
