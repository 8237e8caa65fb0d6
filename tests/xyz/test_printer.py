"""The simulated machine stepped with a fake clock: flows, heating, jobs, faults and personalities."""

from __future__ import annotations

from pathlib import Path

import pytest

from fabwire.errors import InputError
from fabwire.xyz import protocol as p
from fabwire.xyz.models import find_model
from fabwire.xyz.personas import personality
from fabwire.xyz.printer import Printer
from fabwire.xyz.threew import write_3w

GCODE = b";TIME:600\n;LAYER_COUNT:3\n;Filament used: 0.25m\nG28\nG0 X10 Y10\nG1 X20 Y20 E1\nM84\n"


def test_personalities_match_the_captures() -> None:
    nano = Printer(personality("nano")).status()
    assert nano.zoffset == -469
    assert nano.calibration is not None
    assert len(nano.calibration) == 12
    assert nano.network is None
    assert nano.print_file is not None
    pro = Printer(personality("1.0 Pro")).status()
    assert pro.state == (9511, None)
    assert pro.temperatures is not None
    assert pro.temperatures.values == (22,)
    assert pro.targets == {"nozzle": "0", "bed": "0"}
    assert "dr" in (pro.settings or {})
    mini = Printer(personality("miniMaker")).status()
    assert "V" not in mini.order
    assert "4" not in mini.order
    assert len(mini.serial or "") == 18
    with pytest.raises(InputError, match="does not speak XYZv3"):
        personality("da Vinci 1.0")


def test_load_flow_heats_then_feeds_then_cancels() -> None:
    pr = Printer(personality())
    assert pr.execute(p.Flow("load", "new")) == [p.stat_line("load", "start")]
    assert pr.outbox == [p.stat_line("load", "heat", extemp="22")]
    assert pr.state == (9530, 11)
    pr.advance(10)
    assert pr.status().temperatures == pr.status().temperatures
    assert 70 < pr.extruder < 90
    assert pr.state == (9530, 11)
    pr.advance(40)
    assert pr.state == (9530, 12)
    assert pr.outbox[-1] == p.stat_line("load", "load")
    assert pr.execute(p.Flow("load", "cancel")) == [p.stat_line("load", "complete")]
    assert pr.state == (9511, 0)
    assert pr.target == 0
    pr.advance(100)
    assert pr.extruder < 200


def test_unload_completes_by_itself() -> None:
    pr = Printer(personality())
    pr.execute(p.Flow("unload", "new"))
    pr.advance(35)
    assert pr.state == (9531, 22)
    assert pr.target == 100
    pr.advance(60)
    assert pr.state == (9511, 0)
    assert pr.outbox[-1] == p.stat_line("unload", "complete")


def test_job_lifecycle_and_filament_use(tmp_path: Path) -> None:
    pr = Printer(personality(), state_file=tmp_path / "state.json")
    data = write_3w(GCODE, find_model("dv1MW0A000"))
    verdict = pr.check_file(data)
    assert verdict.ok
    assert verdict.print_time == 600
    before = pr.settings.filament_mm
    pr.start_job("a.3w", data, verdict)
    assert pr.status().state == (9520, 0)
    pr.advance(3)
    assert pr.state[0] == 9505
    pr.advance(60)
    progress = pr.status().progress
    assert progress is not None
    assert 0 < progress.percent < 100
    assert progress.remaining_min is not None
    pr.execute(p.PrintControl("pause"))
    frozen = pr.status().progress
    pr.advance(200)
    assert pr.status().progress == frozen
    pr.execute(p.PrintControl("resume"))
    pr.advance(800)
    assert pr.state == (9509, 0)
    assert pr.status().lines("d") == ["d:0,0,0"]
    assert pr.settings.filament_mm == before - 250
    pr.execute(p.PrintControl("complete"))
    assert pr.state == (9511, 0)
    assert '"filament_mm": ' + str(before - 250) in (tmp_path / "state.json").read_text()


def test_file_checks_per_model() -> None:
    mini = Printer(personality("dv1MW0A000"))
    assert not mini.check_file(GCODE).ok
    assert not mini.check_file(write_3w(GCODE, find_model("dv1JP0A000"))).ok
    assert not mini.check_file(write_3w(GCODE, find_model("dv1MW0A000"), container=5)).ok
    nano = Printer(personality("nano"))
    assert nano.check_file(write_3w(GCODE, find_model("dv1NX0A000"), container=5)).ok
    assert nano.check_file(write_3w(GCODE, find_model("dv1NX0A000"))).ok
    corrupt = bytearray(write_3w(GCODE, find_model("dv1NX0A000")))
    corrupt[-1] ^= 0xFF
    assert not nano.check_file(bytes(corrupt)).ok


def test_faults() -> None:
    pr = Printer(personality(), faults=("door-open",))
    assert [w.name for w in pr.status().error_words] == ["M_TOP_DOOR_OPEN"]
    pr.inject("door-open", False)
    pr.inject("no-cartridge")
    st = pr.status()
    assert st.errors == (0x40000206,)
    assert st.cartridge is not None
    assert st.cartridge.fields == ("-" * 14,)
    assert st.filament == (1, -1)
    assert pr.execute(p.Flow("load", "new")) == [p.stat_line("load", "fail")]
    stuck = Printer(personality(), faults=("stuck",))
    stuck.execute(p.Home())
    stuck.advance(1000)
    assert stuck.state == (9534, 5)
    assert stuck.refusal(p.Jog("x", 5)) == 3
    with pytest.raises(InputError, match="unknown fault"):
        Printer(personality(), faults=("gremlins",))


def test_zoffset_get_lags_one_nudge_like_the_firmware() -> None:
    pr = Printer(personality())
    pr.execute(p.NudgeZOffset(True))
    assert pr.execute(p.GetZOffset()) == ["245"]
    assert pr.execute(p.GetZOffset()) == ["246"]


def test_fw3_answers_busy_while_a_print_winds_down() -> None:
    pr = Printer(personality("nano"))
    data = write_3w(b";TIME:60\n" + GCODE, find_model("dv1NX0A000"), container=5)
    pr.start_job("n.3w", data, pr.check_file(data))
    replies = []
    for t in range(200):
        pr.advance(t * 0.5)
        replies.append(pr.busy_reply())
    assert pr.state == (9509, 0)
    seen = [r for r in replies if r is not None]
    assert seen[0] == 7
    assert seen[-1] == 4
    assert replies[-1] is None


def test_plus_status_is_its_own_capture() -> None:
    capture = (Path(__file__).parent / "data" / "plus_11.txt").read_text()
    pr = Printer(personality("1.1 Plus"))
    assert "".join(f"{line}\n" for line in pr.status().lines()) + "$\n" == capture
    assert pr.refusal(p.Home()) == 1
    assert pr.refusal(p.SetBuzzer(False)) == 1
    assert pr.refusal(p.Query("a")) is None
    assert Printer(personality("mini w")).refusal(p.Signature()) == 1
    nano = Printer(personality("nano"))
    (line,) = nano.execute(p.Signature())
    assert p.raw_reply_value(p.Signature(), line) is not None
