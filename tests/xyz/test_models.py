from __future__ import annotations

import pytest

from fabwire.errors import InputError
from fabwire.xyz.models import MODELS, FileFormat, PrinterModel, default_model, find_model, model_for_file_id


def test_table_has_every_known_model_once() -> None:
    numbers = [m.model_number for m in MODELS]
    assert len(MODELS) == 23
    assert len(set(numbers)) == len(numbers)
    assert len({m.name.lower() for m in MODELS}) == len(MODELS)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.model_number)
def test_every_model_is_found_by_number_and_name_in_any_case(model: PrinterModel) -> None:
    assert find_model(model.model_number) is model
    assert find_model(model.model_number.upper()) is model
    assert find_model(model.name) is model
    assert find_model(model.name.upper()) is model
    assert find_model(f"  {model.name.lower()}  ") is model


@pytest.mark.parametrize(
    ("text", "number"),
    [
        ("miniMaker", "dv1MX0A000"),
        ("mini maker", "dv1MX0A000"),
        ("mini w", "dv1MW0A000"),
        ("Mini W+", "dv1MW0C000"),
        ("nano", "dv1NX0A000"),
        ("nano w", "dv1NW0A000"),
        ("Jr 1.0 Pro", "dv1JP0A000"),
        ("jr. 2.0 mix", "dv2JW0A000"),
        ("super", "dv1SW0A000"),
        ("1.0 Pro", "dvF1W0A000"),
        ("da Vinci 1.0", "dvF100B000"),
        ("daVinci Jr. 1.0w", "dv1JW0A000"),
    ],
)
def test_common_names_and_aliases(text: str, number: str) -> None:
    assert find_model(text).model_number == number


@pytest.mark.parametrize(("text", "said"), [
    ("", "such as dv1MX0A000, miniMaker"), ("   ", "such as dv1MX0A000, miniMaker"),
    ("da Vinci Color", "such as dv1MX0A000, miniMaker"), ("prusa mk3", "(23 models are known)"),
    ("a" * 5000, "such as dv1MX0A000, miniMaker"),
    ("dv1CP0A000", "(did you mean 'dv1JP0A000'?)"), ("miniMakr", "(did you mean 'miniMaker'?)"),
    ("da vinci mini w plsu", "(did you mean 'mini w+'?)"), ("SUPR", "(did you mean 'Super'?)"),
])
def test_an_unknown_model_is_one_short_line_naming_the_closest(text: str, said: str) -> None:
    with pytest.raises(InputError) as caught:
        find_model(text)
    message = str(caught.value)
    assert message.startswith("unknown printer model ")
    assert said in message
    assert len(message) < 200
    assert "\n" not in message


def test_file_formats_follow_the_reference_table() -> None:
    zipped = {m.model_number for m in MODELS if m.file_format is FileFormat.V2_ZIP}
    v5 = {m.model_number for m in MODELS if m.file_format is FileFormat.V5}
    assert zipped == {"dvF100B000", "dvF100A000", "dvF10SA000", "dvF110B000", "dvF200B000", "dvF200A000"}
    assert v5 == {"dv1JSOA000", "dv1JP0A000", "dv1JPWA000", "dvF1W0A000", "dvF1WSA000", "dv1SW0A000"}
    for model in MODELS:
        assert model.container == (5 if model.model_number in v5 else 2)
        assert model.zipped == (model.model_number in zipped)


def test_model_details() -> None:
    mini_w = find_model("dv1MW0A000")
    assert (mini_w.wifi, mini_w.heated_bed, mini_w.file_id) == (True, False, "dv1MW0A000")
    assert find_model("dv1J00A000").file_id == "daVinciJR10"
    assert find_model("dv1NX0A000").serial_prefixes == ("3FN1XP", "3FNAXP")
    assert find_model("dv1SW0A000").build_volume_mm == (300, 300, 300)
    assert find_model("dvF1W0A000").heated_bed
    assert default_model().model_number == "dv1MX0A000"


def test_models_by_their_3w_machine_id() -> None:
    assert model_for_file_id("dv1MX0A000") is find_model("miniMaker")
    assert model_for_file_id("daVinciJR10") is find_model("dv1J00A000")
    assert model_for_file_id("daVinciF10") is find_model("dvF100B000")
    assert model_for_file_id("daVinciAW10") is find_model("dvF1W0A000")
    assert model_for_file_id("nothing") is None
