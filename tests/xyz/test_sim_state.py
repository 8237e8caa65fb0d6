"""The simulator's state file and speed: whatever they hold, the simulator refuses them in one line or runs a
printer whose every status reply can be written on the wire."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clitools import run_cli
from fabwire.errors import InputError
from fabwire.mmu.sim import MMUSimulator
from fabwire.xyz import protocol as p
from fabwire.xyz.sim import XYZSimulator
from fabwire.xyz.simstate import MAX_STATE_BYTES, Settings

KEYS = [f.name for f in Settings.__dataclass_fields__.values()]
JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70) | st.floats() | st.text(max_size=40),
    lambda inner: st.lists(inner, max_size=10) | st.dictionaries(st.text(max_size=5), inner, max_size=5),
    max_leaves=20,
)


def _reply_of(sim: XYZSimulator) -> bytes:
    return p.reply_lines(sim.printer.status().lines(), dollar=True)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.dictionaries(st.sampled_from(KEYS) | st.text(max_size=8), JSON_VALUES | st.sampled_from(
    ["\u0100", "a\nb", "\x00", "ABC", "[x]", "a,b", 9, 10, -1, [1] * 9, [70000] * 9, "10.0.0.1"]), max_size=6))
def test_any_state_file_is_refused_or_gives_statuses_the_wire_can_carry(tmp_path: Path, data: dict[str, object]
                                                                        ) -> None:
    state = tmp_path / "state.json"
    state.write_text(json.dumps(data))
    try:
        sim = XYZSimulator(state_file=state)
    except InputError as exc:
        refused = str(exc)
    else:
        refused = ""
    if refused:
        assert str(state) in refused
        return
    reply = _reply_of(sim)
    lines = reply.decode("latin-1").split("\n")
    assert lines[-2:] == ["$", ""]
    assert all(len(line) >= 2 and line[1] == ":" for line in lines[:-2])  # no value broke a line


@pytest.mark.parametrize("content", [b"[1, 2]", b"[" * 100_000 + b"]" * 100_000, b"{\"zoffset\": 1e400}",
                                     b"{\"name\": \"\\u0100\"}", b"{\"ip\": \"1.2.3.4\\n\"}", b"\xff\xfe",
                                     b" " * (MAX_STATE_BYTES + 1)])
def test_a_hostile_state_file_is_one_line_of_error_at_start(tmp_path: Path, content: bytes) -> None:
    state = tmp_path / "state.json"
    state.write_bytes(content)
    done = run_cli("sim", "xyz", "--listen", "127.0.0.1:0", "--state", str(state), timeout=60)
    assert done.returncode == 4
    assert done.stderr.count("\n") == 1
    assert done.stderr.startswith("fabwire: error: simulator state ")
    assert "Traceback" not in done.stderr


def test_a_good_state_file_is_kept_and_written_back(tmp_path: Path) -> None:
    state = tmp_path / "state.json"
    state.write_text(json.dumps({"name": "Lab", "zoffset": -12, "language": "fr", "unknown": [1]}))
    sim = XYZSimulator(state_file=state)
    assert (sim.printer.settings.name, sim.printer.settings.zoffset, sim.printer.settings.language) == (
        "Lab", -12, "fr")
    sim.printer.execute(p.SetZOffset(30))
    assert json.loads(state.read_text())["zoffset"] == 30


@pytest.mark.parametrize("speed", [math.nan, math.inf, -math.inf, 0.0, -1.0, 1e-300, 1e300, 0.001, 10_001.0])
@pytest.mark.parametrize("simulator", [XYZSimulator, MMUSimulator])
def test_a_speed_the_clock_cannot_run_at_is_refused(simulator: type[object], speed: float) -> None:
    with pytest.raises(InputError, match=r"speed must be a number from 0\.01 to 10000"):
        simulator(speed=speed)


@pytest.mark.parametrize("url", ["sim://xyz?speed=nan", "sim://xyz?speed=inf", "sim://xyz?speed=1e-300"])
def test_a_sim_url_with_an_impossible_speed_is_bad_input(url: str) -> None:
    done = run_cli("xyz", "-d", url, "status", timeout=60)
    assert done.returncode == 4
    assert done.stderr.strip().splitlines() == [
        f"fabwire: error: sim://xyz option 'speed': expected a number from 0.01 to 10000, not {url.split('=')[1]!r}"]


@pytest.mark.parametrize("store", ["/dev/null", "/proc/no-such-dir/x"])
def test_a_store_that_cannot_be_a_folder_is_bad_input(store: str) -> None:
    done = run_cli("xyz", "-d", f"sim://xyz?store={store}", "status", timeout=60)
    assert (done.returncode, done.stdout) == (4, "")
    assert done.stderr.startswith(f"fabwire: error: cannot keep received files in '{store}': ")
    assert done.stderr.count("\n") == 1
