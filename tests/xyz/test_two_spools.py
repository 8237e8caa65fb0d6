"""Two-spool printers (Jr. 2.0 Mix; the 2.0 Duo has two extruders too): `w:2,SN1,SN2`, `f:2,len1,len2` and
`t:2,a,b` read into both spools and both extruders, in the panel, --json, the simulator and the agent's summary."""

from __future__ import annotations

import json

import pytest

from clitools import SimulatorStarter, run_cli
from fabwire.agent.drivers.xyz import printer_summary
from fabwire.xyz.cli import render_status
from fabwire.xyz.status import Status

MIX = ["w:2,PMP6PTH6840596,PMP6QTH64R1093", "f:2,120000,80000", "t:1,22,0", "p:dv2JW0A000", "j:9511,0"]


@pytest.mark.parametrize(("lines", "spools", "extruder2"), [
    pytest.param(MIX, [("PMP6PTH6840596", 120000), ("PMP6QTH64R1093", 80000)], None, id="jr-mix"),
    pytest.param(["w:2,PMP6PTH6840596,PMP6QTH64R1093", "f:2,120000,80000", "t:2,180,175", "p:dvF200B000"],
                 [("PMP6PTH6840596", 120000), ("PMP6QTH64R1093", 80000)], 175, id="duo-two-extruders"),
    pytest.param(["w:2,PMP6PTH6840596,--------------", "f:2,120000,-1", "t:1,22,0"],
                 [("PMP6PTH6840596", 120000), (None, None)], None, id="second-spool-missing"),
    pytest.param(["w:1,PMP6QTH64R1093,210", "f:1,200000", "t:1,22,0"], [("PMP6QTH64R1093", 200000)], None,
                 id="one-spool"),
])
def test_both_spools_and_extruders(lines: list[str], spools: list[tuple[str | None, int | None]],
                                   extruder2: int | None) -> None:
    status = Status.parse(lines)
    data = status.to_dict()
    assert [(s["serial"], s["filament_left_mm"]) for s in data["spools"]] == spools
    assert data["filament2_left_mm"] == (spools[1][1] if len(spools) > 1 else None)
    assert data["extruder2_c"] == extruder2
    summary = printer_summary(status)
    assert summary["filament2_left_mm"] == data["filament2_left_mm"]
    assert summary["extruder2_temp_c"] == extruder2


def test_panel_shows_both(capsys: pytest.CaptureFixture[str]) -> None:
    from rich.console import Console

    console = Console(width=100)
    console.print(render_status(Status.parse([*MIX[:2], "t:2,180,175"])))
    shown = capsys.readouterr().out
    assert "Filament 1  PMP6PTH6840596" in shown
    assert "Filament 2  PMP6QTH64R1093 Clear Tangerine, 80.00 m left" in shown
    assert "Extruder 2  175 °C" in shown


def test_the_mix_persona_reports_two_spools(simulator: SimulatorStarter) -> None:
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000", "--model", "dv2JW0A000")
    dev = sim.url.removeprefix("tcp://")
    data = json.loads(run_cli("--json", "xyz", "-d", dev, "status").stdout)
    assert data["raw"]["w"] == "2,PMP6QTH64R1093,PMP6PTH6840596"
    assert data["raw"]["f"] == "2,200000,120000"
    assert [s["filament_left_mm"] for s in data["spools"]] == [200000, 120000]
    text = run_cli("xyz", "-d", dev, "status").stdout
    assert "Filament 2" in text
    assert "120.00 m left" in text


@pytest.mark.parametrize(("model", "shown"), [("da Vinci Jr. 2.0 Mix", True), ("da Vinci 2.0 Duo", True),
                                              ("da Vinci mini w", False), (None, False)])
def test_home_assistant_gets_the_second_spool_of_two_spool_models(model: str | None, shown: bool) -> None:
    from fabwire.mqtt.discovery import discovery_payload

    payload = discovery_payload({"id": "mix", "kind": "xyz", "name": "Mix", "model": model}, "bench")
    names = {c["name"] for c in payload["components"].values()}
    assert ({"Filament 2 left", "Extruder 2 temperature"} <= names) is shown
    assert "Filament left" in names
