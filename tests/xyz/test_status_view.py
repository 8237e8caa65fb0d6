"""What people and scripts see of a status: a dash for what the printer did not report, typed JSON with units."""

from __future__ import annotations

import io
import json
import re
from pathlib import Path

import pytest
from rich.console import Console

from fabwire.units import ABSENT
from fabwire.xyz.cli import render_status
from fabwire.xyz.live import job_line
from fabwire.xyz.status import Status

DATA = Path(__file__).parent / "data"
CAPTURES = ["pro_10.txt", "plus_11.txt", "mini_w_wifi.txt", "nano_fw320_usb.txt"]


def _status(name: str) -> Status:
    lines = [line for line in (DATA / name).read_text().splitlines() if line and line != "$"]
    return Status.parse(lines)


def _text(status: Status) -> str:
    console = Console(file=io.StringIO(), width=120, color_system=None)
    console.print(render_status(status))
    return console.file.getvalue()  # type: ignore[attr-defined, no-any-return]


@pytest.mark.parametrize("capture", CAPTURES)
def test_no_python_none_in_what_people_read(capture: str) -> None:
    status = _status(capture)
    assert "None" not in _text(status)
    assert "None" not in job_line(status)


def test_a_state_without_substate_and_an_absent_extruder() -> None:
    assert "idle (9511)" in _text(_status("pro_10.txt"))
    plus = _status("plus_11.txt")
    assert job_line(plus) == f"idle, extruder {ABSENT}"
    assert re.search(f"Extruder +{ABSENT} ", _text(plus))
    assert job_line(Status.parse(["j:9511,0", "t:1,215,220", "b:60"])) == "idle, extruder 215 °C → 220 °C, bed 60 °C"


@pytest.mark.parametrize("capture", CAPTURES)
def test_json_is_typed_with_units_and_the_wire_under_raw(capture: str) -> None:
    status = _status(capture)
    data = json.loads(json.dumps(status.to_dict()))
    assert set(data["raw"]) == set(status.order)
    for letter, value in data["raw"].items():
        assert f"{letter}:{value.rstrip()}" in (DATA / capture).read_text()  # `n:` is space-padded on the wire
    for key, value in data.items():
        if key.endswith(("_c", "_s", "_mm", "_percent", "_bytes")):
            assert value is None or isinstance(value, int | float), key
    assert isinstance(data["state"], int)


def test_json_values_and_units() -> None:
    status = Status.parse(["j:9505,2", "t:1,210,215", "b:55", "d:40,12,30", "z:-12", "L:1,2.5,3", "o:p8,t1,c1,a+"])
    data = status.to_dict()
    assert (data["state"], data["substate"], data["extruder_c"], data["extruder_target_c"], data["bed_c"]) == \
        (9505, 2, 210, 215, 55)
    assert (data["progress_percent"], data["elapsed_s"], data["time_left_s"]) == (40, 720, 1800)
    assert data["zoffset_mm"] == -0.12
    assert data["block_size_bytes"] == 8192
    assert data["raw"]["z"] == "-12"
    assert data["model"] is None


@pytest.mark.parametrize("hostile", ["[/]", "[bold]x[/bold]", ":smile:", "[link=file:///etc]n[/link]"])
def test_what_the_printer_reports_is_printed_as_it_is_never_as_markup(hostile: str,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    from fabwire.console import Output

    status = Status.parse(["j:9511,0", f"n:{hostile}", f"i:{hostile}"])
    Output().out.print(render_status(status))
    printed = capsys.readouterr().out
    assert printed.count(hostile) == 2, printed
