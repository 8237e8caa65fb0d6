"""Documents to passes and back: page ↔ machine units, one transform for all layers, the progress file's
pen-change marks."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import vpype
from fabwire.errors import InputError
from fabwire.lineus.kinematics import reachable_mask
from fabwire.lineus.plot import PlanOptions
from fabwire.vpype.drawing import PEN_CHANGE, flatten, unflatten
from fabwire.vpype.passes import document_passes, fit_document, plan_gcode, plan_passes, to_machine, to_page

coords = st.floats(-5000, 5000, allow_nan=False)


@given(st.lists(st.tuples(coords, coords), min_size=1, max_size=20))
def test_page_and_machine_units_round_trip(points: list[tuple[float, float]]) -> None:
    line = np.array([complex(x, y) for x, y in points])
    np.testing.assert_allclose(to_page(to_machine(line)), line, atol=1e-6)


def test_page_origin_is_the_app_area_corner_with_y_up() -> None:
    # 96 px is one inch = 25.4 mm = 508 units; y grows down the page and up on the machine.
    np.testing.assert_allclose(to_machine(np.array([0j, 96 + 96j])), [[650, 1000], [650 + 508, 1000 - 508]])


def two_layer_document() -> vpype.Document:
    doc = vpype.Document()
    doc.add(vpype.LineCollection([np.array([0, 400 + 0j]), np.array([0j, 400 + 300j])]), 1)
    doc.add(vpype.LineCollection([np.array([100 + 100j, 300 + 100j, 300 + 200j])]), 4)
    doc.layers[4].set_property("vp_name", "red")
    return doc


def test_fit_moves_all_layers_together_and_keeps_their_ids_and_names() -> None:
    doc = two_layer_document()
    before = {lid: [line.copy() for line in layer] for lid, layer in doc.layers.items()}
    fit_document(doc, PlanOptions(fit=True, margin_mm=2.0))
    assert sorted(doc.layers) == [1, 4]
    assert doc.layers[4].property("vp_name") == "red"
    # One similarity transform for everything: the same affine map takes every old point to its new place.
    old = np.concatenate([np.concatenate(before[1]), np.concatenate(before[4])])
    new = np.concatenate([np.concatenate(list(doc.layers[1])), np.concatenate(list(doc.layers[4]))])
    scale = (new[1] - new[0]) / (old[1] - old[0])
    np.testing.assert_allclose(new, new[0] + (old - old[0]) * scale, atol=1e-6)
    machine = np.concatenate([to_machine(line) for layer in doc.layers.values() for line in layer])
    assert bool(reachable_mask(machine[:, 0], machine[:, 1]).all())


def test_passes_follow_layer_numbers_and_name_themselves() -> None:
    doc = fit_document(two_layer_document(), PlanOptions(fit=True))
    passes = document_passes(doc)
    assert [(p.layer_id, p.label) for p in passes] == [(1, "layer 1"), (4, "layer 4 (red)")]
    assert [p.layer_id for p in document_passes(doc, [4])] == [4]


def test_unplaced_layer_is_refused_naming_it() -> None:
    doc = two_layer_document()
    doc.add(vpype.LineCollection([np.array([0j, 5000 + 0j])]), 2)
    fit_document(doc, PlanOptions(fit=True))
    doc.add(vpype.LineCollection([np.array([0j, -5000 + 0j])]), 7)
    with pytest.raises(InputError, match=r"^layer 7: .*lineus-fit"):
        plan_passes(document_passes(doc), PlanOptions(fit=False))


def test_progress_marks_round_trip_between_passes() -> None:
    doc = fit_document(two_layer_document(), PlanOptions(fit=True))
    plans = plan_passes(document_passes(doc), PlanOptions(fit=False, optimize=False))
    flat = flatten(plans)
    assert flat.count(PEN_CHANGE) == 1
    assert flat[2] == PEN_CHANGE
    back = unflatten(flat)
    assert [len(p.strokes) for p in back] == [2, 1]
    for got, want in zip(back, plans, strict=True):
        for a, b in zip(got.strokes, want.plan.strokes, strict=True):
            np.testing.assert_allclose(a, b, atol=1e-3)


def test_gcode_starts_with_the_pen_up_and_lifts_after_every_stroke() -> None:
    doc = fit_document(two_layer_document(), PlanOptions(fit=True))
    lines = plan_gcode(plan_passes(document_passes(doc), PlanOptions(fit=False, optimize=False)), pen_z=300)
    assert lines[0] == "G01 Z1000"
    assert lines.count("G01 Z300") == 3
    assert lines.count("G01 Z1000") == 4
    assert all(line.startswith("G01 ") for line in lines)


def test_fit_uses_the_app_area_as_the_page_unless_the_full_area_is_asked_for() -> None:
    app = fit_document(two_layer_document(), PlanOptions(fit=True, margin_mm=0.0))
    full = fit_document(two_layer_document(), PlanOptions(fit=True, margin_mm=0.0, full_area=True))
    width, height = app.page_size
    assert (round(width * 25.4 / 96, 1), round(height * 25.4 / 96, 1)) == (56.2, 100.0)  # the app's 56 x 100 mm
    x0, y0, x1, y1 = app.bounds()
    assert min(x0, y0) >= -1e-6
    assert x1 <= width + 1e-6
    assert y1 <= height + 1e-6
    assert full.layers[1].width() > app.layers[1].width()
