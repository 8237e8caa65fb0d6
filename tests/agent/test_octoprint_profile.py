"""The OctoPrint printer profile's `heatedBed` comes from the model's row (every da Vinci of
`fabwire.xyz.models.MODELS`), not from whether the printer reports a bed temperature: a mini w reports one and
has no heater, and Home Assistant's OctoPrint integration makes bed entities from this flag."""

from __future__ import annotations

import pytest

from fabwire.agent.doors.octoprint import _heated_bed
from fabwire.agent.model import MachineView
from fabwire.xyz.models import MODELS, PrinterModel


def view(kind: str, model: str | None, bed_c: float | None = 24.0, bed_target_c: float | None = None
         ) -> MachineView:
    return MachineView(id="m", name="m", kind=kind, model=model, online=True, phase="standby", message="ready",
                       error=None, extruder_c=24.0, extruder_target_c=None, bed_c=bed_c,
                       bed_target_c=bed_target_c, job=None, progress_percent=None, elapsed_s=None,
                       time_left_s=None, takes_jobs=True)


@pytest.mark.parametrize("model", MODELS, ids=[m.name for m in MODELS])
def test_heated_bed_is_the_models_whatever_the_printer_reports(model: PrinterModel) -> None:
    assert _heated_bed(view("xyz", model.name)) is model.heated_bed
    assert _heated_bed(view("xyz", model.name, bed_target_c=60.0)) is model.heated_bed


def test_other_kinds_and_unknown_models() -> None:
    assert _heated_bed(view("lineus", "Line-us")) is False
    assert _heated_bed(view("xyz", None)) is False
    assert _heated_bed(view("xyz", "da Vinci 9000", bed_target_c=60.0)) is True
    assert _heated_bed(view("xyz", "da Vinci 9000")) is False
