"""Every number a command takes is checked for being a number: nan passes every range comparison and inf makes
a wait or a size endless, so a float option or argument anywhere in the tree must refuse both at parse time."""

from __future__ import annotations

from pathlib import Path

import click
import pytest

from clitools import leaf_commands, run_cli
from fabwire.cli_options import FiniteRange


def _float_params() -> list[tuple[str, str, click.Parameter]]:
    found = []
    for path, command in leaf_commands().items():
        for param in command.params:
            if isinstance(param.type, click.types.FloatParamType):
                found.append((" ".join(path), param.name or "?", param))
    return found


def test_every_float_parameter_refuses_nan_and_infinity() -> None:
    loose = [f"{path} {name}" for path, name, param in _float_params() if not isinstance(param.type, FiniteRange)]
    assert not loose, f"float parameters that take nan or inf: {loose}"
    open_ended = [f"{path} {name}" for path, name, param in _float_params()
                  if isinstance(param.type, FiniteRange) and param.type.open_ended]
    assert open_ended == ["sim lineus speed"]  # inf = no motion delay, as its help says


def test_a_pen_height_outside_the_arm_is_refused_not_clamped() -> None:
    result = run_cli("lineus", "-d", "sim://lineus?speed=inf", "move", "1500", "0", "--z", "5000", timeout=60)
    assert result.returncode == 2
    assert "5000" in result.stderr
    assert "0<=x<=1000" in result.stderr


@pytest.mark.parametrize("line", [
    ["serve", "--max-upload", "nan"], ["serve", "--retention", "inf"], ["demo", "--speed", "nan"],
    ["sim", "--idle-timeout", "nan", "xyz"], ["lineus", "-d", "sim://lineus", "move", "nan", "0"],
    ["lineus", "preview", "DRAWING", "--margin", "nan"], ["lineus", "text", "hi", "--size", "inf"],
    ["sim", "lineus", "--speed", "nan"],
])
def test_a_non_finite_number_is_a_usage_error_before_anything_runs(line: list[str], tmp_path: Path) -> None:
    drawing = tmp_path / "d.svg"
    drawing.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"><path d="M0 0 L5 5" '
                       'stroke="black"/></svg>')
    result = run_cli(*(str(drawing) if word == "DRAWING" else word for word in line), timeout=60)
    assert result.returncode == 2, result.stderr
    assert "is not a finite number" in result.stderr
    assert "Traceback" not in result.stderr


NOT_TYPED_NUMBERS = ["1_000", "١٠٠٠", "１０", "0x10", "1e", "--1", "1,5", ""]
"""Strings Python's float() may take (underscores, other scripts' digits) or that are no number at all."""


@pytest.mark.parametrize("text", NOT_TYPED_NUMBERS)
def test_every_float_parameter_takes_only_plain_digits(text: str) -> None:
    for _path, _name, param in _float_params():
        with pytest.raises(click.BadParameter, match="is not a number"):
            param.type.convert(text, param, None)


def test_a_number_in_another_script_is_a_usage_error() -> None:
    result = run_cli("lineus", "-d", "sim://lineus?speed=inf", "move", "1_000", "1000", timeout=60)
    assert result.returncode == 2
    assert "'1_000' is not a number" in result.stderr
