"""The live print view: a panel on a terminal, plain lines in order elsewhere, timestamped JSON lines; `--watch`
outlives a lost link."""

from __future__ import annotations

import datetime
import io
import json
import socket
import subprocess
import sys
import time

from rich.console import Console

from clitools import SimulatorStarter, cli_env
from fabwire.console import Output
from fabwire.units import ABSENT
from fabwire.xyz.live import JobView, job_panel
from fabwire.xyz.status import Status

PRINTING = Status.parse(["j:9505,2", "t:1,205,210", "b:55", 'O:{"nozzle":"210","bed":"60"}', "d:42,10,14"])
HEATING = Status.parse(["j:9505,1", "t:1,120,210"])


def _console(terminal: bool) -> tuple[Console, io.StringIO]:
    buffer = io.StringIO()
    return Console(file=buffer, force_terminal=terminal, width=100, color_system=None), buffer


def test_the_panel_shows_progress_temperatures_with_targets_and_times() -> None:
    console, buffer = _console(False)
    console.print(job_panel(PRINTING, "part.gcode"))
    text = buffer.getvalue()
    for expected in ("part.gcode", "printing", "42 %", "205 °C → 210 °C", "55 °C → 60 °C", "10 min", "14 min"):
        assert expected in text, expected
    console.print(job_panel(Status.parse(["j:9511"]), "idle"))
    assert f"Time left  {ABSENT}" in buffer.getvalue()


def test_plain_lines_in_order_when_not_a_terminal() -> None:
    console, buffer = _console(False)
    with JobView(Output(), console, "part.gcode") as view:
        assert not view.live_mode
        view.upload(4096, 8192)
        view.upload(8192, 8192)
        for status in (HEATING, HEATING, PRINTING):
            view.show(status)
    lines = buffer.getvalue().splitlines()
    assert lines == ["uploaded 8192 bytes", "printing, extruder 120 °C → 210 °C",
                     "printing, extruder 205 °C → 210 °C, bed 55 °C, 42 % (14 min left)"]


def test_a_terminal_gets_one_live_panel_not_a_scrolling_log() -> None:
    console, buffer = _console(True)
    with JobView(Output(), console, "part.gcode") as view:
        assert view.live_mode
        for _ in range(20):
            view.show(PRINTING)
    text = buffer.getvalue()
    assert text.count("\x1b[2K") >= 20 * 8  # each update erases the panel's lines and redraws it in place
    assert text.endswith("\x1b[?25h")


def test_json_lines_carry_an_iso_8601_time(capsys: object) -> None:
    console, _ = _console(False)
    output = Output(json_mode=True)
    with JobView(output, console, "x") as view:
        view.show(PRINTING, {"event": "status"})
    line = json.loads(capsys.readouterr().out)  # type: ignore[attr-defined]
    stamp = datetime.datetime.fromisoformat(line["time"])
    assert stamp.tzinfo is not None
    assert (line["event"], line["progress_percent"]) == ("status", 42)


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def test_watch_reconnects_after_the_printer_goes_away_and_comes_back(simulator: SimulatorStarter) -> None:
    port = _free_port()
    first = simulator("xyz", "--listen", f"127.0.0.1:{port}", "--speed", "100")
    watch = subprocess.Popen([sys.executable, "-m", "fabwire", "--json", "xyz", "-d", f"127.0.0.1:{port}", "status",
                              "--watch", "--count", "6", "--interval", "0.3"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=cli_env())
    try:
        assert watch.stdout is not None
        assert json.loads(watch.stdout.readline())["state"] == 9511
        first.stop()
        time.sleep(1.0)
        simulator("xyz", "--listen", f"127.0.0.1:{port}", "--speed", "100")
        out, err = watch.communicate(timeout=60)
    finally:
        if watch.poll() is None:
            watch.kill()
            watch.wait()
    assert watch.returncode == 0, err
    lines = [json.loads(line) for line in out.splitlines()]
    assert len(lines) == 5
    assert all(datetime.datetime.fromisoformat(line["time"]) for line in lines)
    assert "reconnecting in" in err


def test_save_to_sd_reaches_the_printer_and_ctrl_c_while_following_says_it_keeps_printing(
        simulator: SimulatorStarter, tmp_path: object) -> None:
    import signal
    from pathlib import Path

    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1", "--store", str(Path(str(tmp_path)) / "sd"))
    address = sim.url.removeprefix("tcp://")
    gcode = Path(str(tmp_path)) / "part.gcode"
    gcode.write_bytes(b";TIME:3600\nG28\n" + b"G1 X10 Y10 E1 F1200\n" * 200)
    follow = subprocess.Popen([sys.executable, "-m", "fabwire", "xyz", "-d", address, "print", "--save-to-sd",
                               "--name", "cube.3w", str(gcode)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=cli_env())
    try:
        assert follow.stderr is not None
        seen = ""
        while "uploaded" not in seen:  # plain lines: the upload is reported once the printer has the file
            line = follow.stderr.readline()
            assert line, "print ended before the upload finished"
            seen += line
        time.sleep(0.5)
        follow.send_signal(signal.SIGINT)
        _out, err = follow.communicate(timeout=30)
    finally:
        if follow.poll() is None:
            follow.kill()
            follow.wait()
    assert follow.returncode == 130
    assert "the printer keeps printing part.gcode" in err
    assert f"fabwire xyz -d {address} cancel" in err
    assert "Traceback" not in err
    assert (Path(str(tmp_path)) / "sd" / "cube.3w").exists()  # uploaded under --name
    status = subprocess.run([sys.executable, "-m", "fabwire", "--json", "xyz", "-d", address, "status"],
                            capture_output=True, text=True, env=cli_env(), timeout=30)
    assert json.loads(status.stdout)["state"] != 9511  # still printing (or heating) after the client left
