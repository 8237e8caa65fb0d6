"""The words a refusal uses are the machine's own: a Line-us draws (never "prints"), an MMU is named as one, for every
phase the doors know and every kind."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest

from fabwire.agent.model import PHASE_OF_SUMMARY, STATE_CODE_PHASE, MachineView, TakesNoJobs
from fabwire.devices import KINDS


def view(kind: str, phase: str, job: dict[str, Any] | None = None, takes_jobs: bool = True) -> MachineView:
    return MachineView(id="m", name="bench", kind=kind, model=None, online=True, phase=phase, message=phase,
                       error=None, extruder_c=None, extruder_target_c=None, bed_c=None, bed_target_c=None, job=job,
                       progress_percent=None, elapsed_s=None, time_left_s=None, takes_jobs=takes_jobs)


PHASES = sorted({"printing", "pausing", "paused", "resuming", "cancelling", *STATE_CODE_PHASE.values(),
                 *PHASE_OF_SUMMARY.values()})


@pytest.mark.parametrize("phase", PHASES)
def test_a_line_us_is_said_to_draw_in_every_phase(phase: str) -> None:
    for refusal in (view("lineus", phase).refusal(),
                    view("lineus", phase, job={"id": "j1", "filename": "logo.svg"}).refusal()):
        if refusal is not None:
            assert "print" not in refusal, refusal


def test_a_busy_line_us_and_a_busy_printer_in_their_words() -> None:
    job = {"id": "j1", "filename": "logo.svg"}
    assert view("lineus", "printing", job).refusal() == ("bench is busy with job j1 (logo.svg, drawing): wait for it "
                                                          "to finish or cancel it")
    assert view("lineus", "paused").refusal() == "bench is paused: wait for the drawing to finish or cancel it"
    assert view("xyz", "paused").refusal() == "bench is paused: wait for the print to finish or cancel it"


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_a_machine_that_takes_no_files_is_named_by_its_kind(kind: str) -> None:
    none = view(kind, "standby", takes_jobs=False)
    with pytest.raises(TakesNoJobs, match=f"^bench is {KINDS[kind].a_title}: it takes no files$"):
        none.require_files()
    assert none.refusal() == f"bench is {KINDS[kind].a_title} and takes no jobs"
    replace(none, takes_jobs=True).require_files()  # one that does: nothing raised
