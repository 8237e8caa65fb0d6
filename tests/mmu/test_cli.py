"""`fabwire mmu …` and `fabwire sim mmu` as real subprocesses over TCP and a pty."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import pytest

from clitools import SimulatorStarter, cli_env, run_cli
from fabwire.mmu import codes

SPEED = "50"


def mmu(url: str, *args: str, json_mode: bool = False) -> tuple[int, str, str]:
    prefix = ["--json"] if json_mode else []
    done = run_cli(*prefix, "mmu", "-d", url, *args, "--speed", SPEED, timeout=60)
    return done.returncode, done.stdout, done.stderr


def test_version_status_and_registers(simulator: SimulatorStarter) -> None:
    sim = simulator("mmu", "--listen", "127.0.0.1:0", "--speed", SPEED, "--version", "3.0.3")
    assert sim.url.startswith("tcp://127.0.0.1:")
    code, out, err = mmu(sim.url, "version")
    assert (code, out.strip()) == (0, "MMU firmware 3.0.3+896"), err
    code, out, _ = mmu(sim.url, "version", json_mode=True)
    assert json.loads(out) == {"major": 3, "minor": 0, "revision": 3, "build": 896, "version": "3.0.3+896"}
    code, out, _ = mmu(sim.url, "status")
    assert code == 0
    assert "FINDA         off" in out
    assert "selector      parked" in out
    assert "command       X0 finished" in out
    code, out, _ = mmu(sim.url, "write", "bowden_length", "420")
    assert (code, out.strip()) == (0, "0x22 bowden_length := 420")
    code, out, _ = mmu(sim.url, "read", "0x22", json_mode=True)
    assert json.loads(out) == {"address": 0x22, "name": "bowden_length", "value": 420, "meant": 420}
    code, _, err = mmu(sim.url, "write", "pulley_acceleration", "900")
    assert code == 4  # read-only on 3.0.3, known once the version is
    assert "read-only on this firmware" in err


def test_tool_change_prints_progress_in_words(simulator: SimulatorStarter) -> None:
    sim = simulator("mmu", "--listen", "127.0.0.1:0", "--speed", SPEED)
    code, out, err = mmu(sim.url, "tool-change", "2")
    assert code == 0, err
    assert out.strip() == "T2 finished"
    assert "T2: Feeding to FSensor" in err  # the MMU waits there for the host's f1, so it is always seen
    known = set(codes.PROGRESS_WORDS.values())
    assert all(line.removeprefix("T2: ") in known for line in err.splitlines() if not line.startswith("link lost"))
    code, out, _ = mmu(sim.url, "status", json_mode=True)
    status = json.loads(out)
    assert status["command"] == "T2"
    assert status["finda"] is True
    assert status["filament_text"] == "in nozzle"
    assert status["slot"] == 2
    assert (status["error_code"], status["error_text"]) == (1, "OK")  # register 0x06 after a command that ended well
    code, out, _ = mmu(sim.url, "unload", json_mode=True)
    result = json.loads(out)
    assert result["command"] == "U0"
    assert result["result"] == 0
    assert any(e["name"] == "UNLOADING_TO_FINDA" for e in result["events"])


def test_stuck_fault_fails_clearly_then_button_retry(simulator: SimulatorStarter) -> None:
    sim = simulator("mmu", "--listen", "127.0.0.1:0", "--speed", SPEED, "--fault", "finda-didnt-trigger:4")
    code, _, err = mmu(sim.url, "tool-change", "1")
    assert code == 7
    line = "04101 FINDA DIDN'T TRIGGER (0x8001) during T1 — FINDA didn't trigger; check the filament path, then Retry"
    run_as = f"fabwire mmu -d {sim.url} --speed {SPEED}"  # what a message advises works as typed, link included
    answers = f"`{run_as} button retry`, or `{run_as} reset --yes`"
    assert err.endswith(f"error: {line}; answer it with {answers}\n")
    assert err.count(line) == 4  # three automatic retries, then the error once, with what answers it
    assert err.count(f"{line} (retrying automatically)\n") == 3
    assert err.count("(retrying automatically)") == 3
    code, out, _ = mmu(sim.url, "status", json_mode=True)
    assert json.loads(out)["kind"] == "E"
    assert json.loads(out)["text"] == "04101 FINDA DIDN'T TRIGGER (0x8001)"
    code, out, _ = mmu(sim.url, "status")
    assert "command       T1 04101 FINDA DIDN'T TRIGGER (0x8001)\n" in out
    assert f"error         {line}\n" in out
    code, _, err = mmu(sim.url, "tool-change", "2")  # the MMU still waits in T1's error
    assert code == 7
    assert err.strip() == ("fabwire: error: the MMU stopped in 04101 FINDA DIDN'T TRIGGER "
                           f"(0x8001) during T1 — answer it with {answers}")
    code, out, err = mmu(sim.url, "button", "retry")  # the fourth failure was the last: this Retry heals
    assert (code, out.strip()) == (0, "retry: T1 finished"), err
    code, out, err = mmu(sim.url, "button", "retry")
    assert code == 4
    assert "no error is pending: the MMU reports T1 finished" in err


def test_retry_with_the_cause_still_there_says_so(simulator: SimulatorStarter) -> None:
    sim = simulator("mmu", "--listen", "127.0.0.1:0", "--speed", SPEED, "--fault", "homing-failed:always")
    for _ in range(100):  # the boot homing stalls first (a loaded machine may take a while to get there)
        code, out, _ = mmu(sim.url, "status", json_mode=True)
        if code == 0 and json.loads(out)["value"] == 0x8087:
            break
    code, _, err = mmu(sim.url, "button", "retry")  # the re-home stalls again
    assert code == 7
    assert "04115 SELECTOR CANNOT HOME (0x8087) during X0" in err
    code, _, err = mmu(sim.url, "button", "continue")  # the printer's dialog offers Retry only
    assert code == 4
    assert "04115 SELECTOR CANNOT HOME (0x8087) offers Retry, not continue" in err


def test_eject_waits_for_the_person(simulator: SimulatorStarter) -> None:
    sim = simulator("mmu", "--listen", "127.0.0.1:0", "--speed", SPEED)
    code, out, err = mmu(sim.url, "eject", "3")
    assert (code, out.strip()) == (0, f"E3: filament ejected — take it out, then `fabwire mmu -d {sim.url} --speed "
                                      f"{SPEED} button continue`"), err
    code, out, err = mmu(sim.url, "status", json_mode=True)
    assert (json.loads(out)["command"], json.loads(out)["kind"], json.loads(out)["value"]) == ("E3", "E", 0x800C)
    code, out, err = mmu(sim.url, "button", "continue")
    assert (code, out.strip()) == (0, "continue: E3 finished"), err
    code, out, err = mmu(sim.url, "eject", "1", "--continue-after", "0.2")
    assert (code, out.strip()) == (0, "E1 finished"), err
    assert "continuing in 0.2 s" in err


def test_reset_erase_needs_yes_and_registers_lists_all(simulator: SimulatorStarter) -> None:
    sim = simulator("mmu", "--listen", "127.0.0.1:0", "--speed", SPEED)
    code, _, err = mmu(sim.url, "reset", "--erase")
    assert code == 4
    assert "add --yes" in err
    code, out, err = mmu(sim.url, "reset", "--erase", "--yes")
    assert (code, out.strip()) == (0, "EEPROM erased and MMU reset; firmware 3.0.4+936 answering"), err
    code, out, err = mmu(sim.url, "registers", json_mode=True)
    rows = json.loads(out)
    assert [r["address"] for r in rows] == list(range(0x24))
    assert rows[0x22] == {"address": 0x22, "name": "bowden_length", "value": 360, "meant": 360, "bits": 16,
                          "access": "read/write", "meaning": "bowden tube length, mm (341-1000)"}
    assert rows[0x04]["access"] == "read-only"
    code, out, err = mmu(sim.url, "registers")
    assert "0x22 bowden_length" in out


def test_the_time_scale_comes_from_a_simulator_address() -> None:
    done = run_cli("mmu", "-d", "sim://mmu?speed=50", "tool-change", "2", timeout=60)
    assert (done.returncode, done.stdout.strip()) == (0, "T2 finished"), done.stderr
    assert "faster than this host assumes" not in done.stderr


def test_a_sped_up_mmu_without_speed_is_named_as_such(simulator: SimulatorStarter) -> None:
    sim = simulator("mmu", "--listen", "127.0.0.1:0", "--speed", "40")
    done = run_cli("mmu", "-d", sim.url, "tool-change", "2", timeout=90)
    assert "faster than this host assumes: its timing does not fit (give --speed" in done.stderr


def test_a_device_that_never_answers_fails_in_five_seconds() -> None:
    import socket
    import threading

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    accepted: list[socket.socket] = []
    threading.Thread(target=lambda: accepted.append(server.accept()[0]), daemon=True).start()
    try:
        done = run_cli("mmu", "-d", f"127.0.0.1:{server.getsockname()[1]}", "version", timeout=60)
    finally:
        server.close()
        for conn in accepted:
            conn.close()
    assert done.returncode == 9
    assert "did not complete the handshake within 5 s (no reply within 2 s, 2 times)" in done.stderr


@pytest.mark.parametrize(("args", "message"), [
    (("tool-change", "5"), "filament slot must be 0 to 4"),
    (("load", "9"), "filament slot must be 0 to 4"),
    (("read", "nosuch"), "unknown MMU register 'nosuch'"),
    (("read", "Bowden_Lenght"), "unknown MMU register 'Bowden_Lenght' (did you mean 'bowden_length'?)"),
    (("write", "vcc", "1"), "is read-only"),
    (("write", "cut_length", "zz"), "must be a number"),
])
def test_bad_arguments_fail_before_connecting(args: tuple[str, ...], message: str) -> None:
    done = run_cli("mmu", "-d", "127.0.0.1:9", *args)  # nothing listens there: bad input must win
    assert done.returncode == 4
    assert message in done.stderr
    assert "Traceback" not in done.stderr


def test_unreachable_mmu_is_a_link_error() -> None:
    done = run_cli("mmu", "-d", "127.0.0.1:9", "version")
    assert done.returncode == 8
    assert "connection refused" in done.stderr


def test_monitor_is_bounded_and_json(simulator: SimulatorStarter) -> None:
    sim = simulator("mmu", "--listen", "127.0.0.1:0", "--speed", SPEED)
    code, out, err = mmu(sim.url, "monitor", "--count", "3", "--all", json_mode=True)
    assert code == 0, err
    lines = [json.loads(line) for line in out.splitlines()]
    assert len(lines) == 3
    assert all(line["event"] == "status" and datetime.fromisoformat(line["time"]).tzinfo is not None for line in lines)
    code, out, err = mmu(sim.url, "monitor", "--count", "3", json_mode=True)  # nothing changes: one line, ends
    assert code == 0, err
    assert len(out.splitlines()) == 1
    code, out, _ = mmu(sim.url, "monitor", "--duration", "1")
    assert code == 0
    stamp, _, text = out.splitlines()[0].partition(" ")
    assert len(stamp) == len("12:34:56.789")
    assert text.startswith("status: X0 finished, FINDA off")


def test_over_a_pty_with_trace(simulator: SimulatorStarter, tmp_path: Path) -> None:
    link = tmp_path / "ttyMMU"
    sim = simulator("mmu", "--pty", "--link", str(link), "--speed", SPEED)
    trace = tmp_path / "trace.jsonl"
    done = run_cli("mmu", "-d", str(link), "--trace", str(trace), "load", "3", "--speed", SPEED, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "L3 finished"
    shown = run_cli("trace", "show", str(trace), "--no-time")
    assert "S0*c6" in shown.stdout
    assert "L3*" in shown.stdout
    assert sim.where[0].startswith("/dev/")


def test_home_eject_cut_reset(simulator: SimulatorStarter) -> None:
    sim = simulator("mmu", "--listen", "127.0.0.1:0", "--speed", SPEED)
    for args, expected in ((("eject", "4", "--continue-after", "0"), "E4 finished"), (("cut", "0"), "K0 finished"),
                           (("home",), "H0 finished")):
        code, out, err = mmu(sim.url, *args)
        assert (code, out.strip()) == (0, expected), err
    code, out, err = mmu(sim.url, "reset")
    assert (code, out) == (4, "")
    assert err.strip() == "fabwire: error: this would reboot the MMU: add --yes to confirm"
    code, out, err = mmu(sim.url, "reset", "--yes")
    assert (code, out.strip()) == (0, "MMU reset; firmware 3.0.4+936 answering"), err


def test_sim_refuses_unknown_fault_and_missing_address() -> None:
    done = run_cli("sim", "mmu", "--fault", "gremlins")
    assert done.returncode == 4
    assert "unknown MMU fault 'gremlins'" in done.stderr
    done = run_cli("sim", "mmu")
    assert done.returncode == 4
    assert "--listen HOST:PORT" in done.stderr


@pytest.mark.parametrize("value", ["0x" + "f" * 5000, "9" * 5000, "\u0661\u0662", "1_000"])
def test_a_register_value_that_is_no_plain_number_is_one_line_of_bad_input(value: str) -> None:
    done = run_cli("mmu", "-d", "sim://mmu?speed=50", "--speed", SPEED, "write", "cut_length", value, timeout=60)
    assert (done.returncode, done.stdout) == (4, "")
    assert done.stderr.count("\n") == 1
    assert "register value must be a number" in done.stderr


def poll_until(url: str, reply: str, polls: int = 600) -> bool:
    """Send Q0 over a plain socket (no sensor reports, no retries) until the MMU answers `reply`."""
    host, port = url.removeprefix("tcp://").rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=10) as link, link.makefile("rwb") as line:
        for _ in range(polls):
            line.write(b"Q0*ea\n")
            line.flush()
            if line.readline().decode().startswith(reply + "*"):
                return True
            time.sleep(0.05)
    return False


def test_ctrl_c_in_a_tool_change_says_the_mmu_goes_on_and_where_it_will_stop(simulator: SimulatorStarter) -> None:
    sim = simulator("mmu", "--listen", "127.0.0.1:0", "--speed", "10")  # slow enough to be mid-change
    proc = subprocess.Popen([sys.executable, "-m", "fabwire", "mmu", "-d", sim.url, "--speed", "10", "tool-change",
                             "3"], env=cli_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    seen = ""
    while "T3:" not in seen:  # the first progress line: the MMU has taken the command
        chunk = proc.stderr.read(1)
        assert chunk, "the CLI ended before the tool change began"
        seen += chunk
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130
    lines = err.splitlines()
    assert "error:" not in err  # a stop the person asked for is no error
    assert lines[-2].startswith("stopped following T3 (")
    run_as = f"fabwire mmu -d {sim.url} --speed 10"  # as this command was run
    assert lines[-2].endswith(f"); the MMU goes on with it. Follow it with `{run_as} monitor`")
    assert lines[-1] == (
        f"warning: nothing reports the printer's filament sensor to the MMU now; unless a host does (`{run_as} "
        f"monitor` does), T3 will stop at 04103 FSENSOR DIDN'T TRIGG. (0x8003) (Feeding to FSensor): then "
        f"push the filament into the extruder and answer with `{run_as} button retry`, or `{run_as} reset --yes`")
    assert "Traceback" not in err
    assert poll_until(sim.url, "T3 E8003")  # a bare status poll, as a printer that reports no sensor sends it
    code, out, err = mmu(sim.url, "tool-change", "1")
    assert (code, out) == (7, "")
    assert err.strip() == ("fabwire: error: the MMU stopped in 04103 FSENSOR DIDN'T TRIGG. "
                           f"(0x8003) during T3 — answer it with `fabwire mmu -d {sim.url} --speed {SPEED} button "
                           f"retry`, or `fabwire mmu -d {sim.url} --speed {SPEED} reset --yes`")
    code, out, err = mmu(sim.url, "button", "retry")  # this host reports the sensor: the change completes
    assert (code, out.strip()) == (0, "retry: T3 finished"), err


def test_a_failed_change_says_its_error_once_with_what_answers_it() -> None:
    url = "sim://mmu?speed=50&fault=fsensor-didnt-trigger"
    done = run_cli("mmu", "-d", url, "--speed", SPEED, "tool-change", "2", timeout=60)
    assert done.returncode == 7
    final = ("04103 FSENSOR DIDN'T TRIGG. (0x8003) during T2 — printer filament sensor didn't trigger; check the "
             "filament reached the extruder and the sensor works, then Retry")
    assert done.stderr.count(final + "\n") == 0  # the automatic retries are marked, the end is said once
    assert done.stderr.count(final + " (retrying automatically)") == 3
    run_as = f"fabwire mmu -d '{url}' --speed {SPEED}"  # quoted for a shell: the URL has & and ?
    assert done.stderr.splitlines()[-1] == (f"fabwire: error: {final}; answer it with `{run_as} button retry`, or "
                                            f"`{run_as} reset --yes`")


def test_the_advised_commands_repeat_every_link_option_the_command_was_run_with() -> None:
    """--timeout and each of the MMU's link options (--speed, --accept repeated), wherever they were typed."""
    url = "sim://mmu?speed=50&fault=fsensor-didnt-trigger"
    done = run_cli("mmu", "--accept", "3.0.4", "-d", url, "--accept", "3.0.3", "--timeout", "7", "tool-change", "2",
                   "--speed", SPEED, timeout=60)
    assert done.returncode == 7, done.stderr
    run_as = f"fabwire mmu -d '{url}' --timeout 7 --accept 3.0.4 --accept 3.0.3 --speed {SPEED}"
    assert done.stderr.splitlines()[-1].endswith(f"; answer it with `{run_as} button retry`, or `{run_as} reset --yes`")
    again = subprocess.run(["sh", "-c", f"{sys.executable} -m {run_as} status"],
                           env=cli_env(), capture_output=True, text=True, timeout=60)
    assert again.returncode == 0, again.stderr  # the advice works as typed in a shell
    advised_reset = done.stderr.splitlines()[-1].rsplit("`", 2)[-2]
    reset = subprocess.run(["sh", "-c", advised_reset.replace("fabwire", f"{sys.executable} -m fabwire", 1)],
                           env=cli_env(), stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=60)
    assert reset.returncode == 0, reset.stderr  # the advised reset runs where nobody can answer a question


@pytest.mark.parametrize(("slot", "code", "said"), [
    ("T1", 0, "T1 finished"), ("t2", 0, "T2 finished"),
    ("T9", 4, "filament slot must be 0 to 4, not 9"), ("x1", 2, "a tool is a slot number 0 to 4, or T0 to T4"),
    ("T", 2, "a tool is a slot number"), ("T١", 2, "a tool is a slot number"),
])
def test_tool_change_takes_the_tool_as_mmu_people_write_it(slot: str, code: int, said: str) -> None:
    done = run_cli("mmu", "-d", f"sim://mmu?speed={SPEED}", "--speed", SPEED, "tool-change", slot, timeout=60)
    assert done.returncode == code, done.stderr
    assert said in (done.stdout if code == 0 else done.stderr)
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize(("command", "seen", "sensor_on", "version", "stops"), [
    ("T3", {5}, False, (3, 0, 4), [0x8003]),  # feeding: only the sensor report can end the bowden push
    ("T3", set(), True, (3, 0, 4), [0x8004, 0x8003]),  # loaded: the unload waits for the sensor to go off first
    ("T3", {3, 25, 5, 6, 28, 7}, True, (3, 0, 4), []),  # past the nozzle feed: nothing left to wait for
    ("U0", set(), True, (3, 0, 4), [0x8004]),
    ("U0", set(), True, (3, 0, 3), []),  # 3.0.3 unloads without waiting for the sensor
    ("U0", set(), False, (3, 0, 4), []),
    ("L1", set(), True, (3, 0, 4), []),
])
def test_which_sensor_step_a_command_will_stop_at(command: str, seen: set[int], sensor_on: bool,
                                                  version: tuple[int, int, int], stops: list[int]) -> None:
    from fabwire.mmu.cli import SENSOR_STEPS

    assert [s.error for s in SENSOR_STEPS if s.ahead(command, seen, sensor_on, version)] == stops


def test_the_simulator_says_where_each_fault_shows(tmp_path: Path) -> None:
    """A cause present from power-on meets the firmware only where its check runs (finda-stuck at an unload), so
    the simulator says so for every fault given, before it listens."""
    from fabwire.mmu.errors import format_error
    from fabwire.mmu.faults import FAULT_NAMES, FAULTS

    process = subprocess.Popen([sys.executable, "-m", "fabwire", "sim", "mmu", "--listen", "127.0.0.1:0",
                                *(arg for name in FAULT_NAMES for arg in ("--fault", name))],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=cli_env(tmp_path))
    try:
        assert process.stdout is not None
        assert " listening on " in process.stdout.readline()
    finally:
        process.terminate()
        _, err = process.communicate(timeout=30)
    said = dict(line.removeprefix("fault ").split(": ", 1) for line in err.splitlines() if line.startswith("fault "))
    assert set(said) == set(FAULT_NAMES)
    for name, kind in FAULTS.items():
        assert said[name] == f"{kind.where} → {format_error(kind.word)}"
