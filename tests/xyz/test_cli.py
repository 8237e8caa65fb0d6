"""`fabwire xyz …` as a subprocess against `fabwire sim xyz` on loopback TCP and on a pty."""

from __future__ import annotations

import ipaddress
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path

import pytest

from clitools import SimulatorStarter, cli_env, run_cli
from fabwire.xyz.models import find_model
from fabwire.xyz.threew import read_3w, write_3w

GCODE = b";TIME:600\n;LAYER_COUNT:3\n;Filament used: 0.25m\nG28\nG0 X10 Y10\nG1 X20 Y20 E1\nM84\n"


def device(url: str) -> str:
    return url.removeprefix("tcp://")


def status_json(dev: str) -> dict[str, object]:
    result = run_cli("--json", "xyz", "-d", dev, "status")
    assert result.returncode == 0, result.stderr
    data: dict[str, object] = json.loads(result.stdout)
    return data


def free_port_on(*hosts: str) -> int:
    for _ in range(50):
        with socket.socket() as probe:
            probe.bind((hosts[0], 0))
            port = int(probe.getsockname()[1])
        ok = True
        for host in hosts[1:]:
            with socket.socket() as other:
                try:
                    other.bind((host, port))
                except OSError:
                    ok = False
        if ok:
            return port
    raise RuntimeError("no common free port")


def test_status_print_and_store(simulator: SimulatorStarter, tmp_path: Path) -> None:
    store = tmp_path / "store"
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000", "--store", str(store))
    dev = device(sim.url)
    human = run_cli("xyz", "-d", dev, "status")
    assert human.returncode == 0, human.stderr
    assert "da Vinci mini w" in human.stdout
    assert "idle" in human.stdout
    src = tmp_path / "cube.gcode"
    src.write_bytes(GCODE * 50)
    result = run_cli("xyz", "-d", dev, "print", str(src))
    assert result.returncode == 0, result.stderr
    assert "print finished" in result.stdout
    stored = (store / "cube.3w").read_bytes()
    assert stored == write_3w(GCODE * 50, find_model("dv1MW0A000"), filename="cube.3w")
    assert read_3w(stored).gcode.count(b"G28") == 50
    again = run_cli("xyz", "-d", dev, "print", str(src))
    assert again.returncode == 4  # a state that passes, as for every machine (the API's 409)
    assert "finished but not yet acknowledged" in again.stderr
    assert "fabwire xyz acknowledge" in again.stderr
    garbage = tmp_path / "notes.txt"
    garbage.write_bytes(bytes(range(256)))
    refused = run_cli("xyz", "-d", dev, "print", str(garbage))  # the file is judged before the printer's state
    assert refused.returncode == 4
    assert "notes.txt is binary data, not G-code or a .3w print file" in refused.stderr
    assert run_cli("xyz", "-d", dev, "acknowledge").returncode == 0
    data = status_json(dev)
    assert (data["state"], data["substate"]) == (9511, 0)
    piped = run_cli("xyz", "-d", dev, "print", "-", input_text=(GCODE * 50).decode())
    assert piped.returncode == 0, piped.stderr
    assert piped.stdout == "standard input: print finished\n"
    assert (store / "stdin.3w").read_bytes() == write_3w(GCODE * 50, find_model("dv1MW0A000"), filename="stdin.3w")
    assert run_cli("xyz", "-d", dev, "acknowledge").returncode == 0


def test_settings_commands(simulator: SimulatorStarter) -> None:
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000")
    dev = device(sim.url)
    for args in (("set", "buzzer", "off"), ("set", "autolevel", "off"), ("zoffset", "-12"), ("name", "Lab"),
                 ("language", "fr"), ("energy", "6")):
        result = run_cli("xyz", "-d", dev, *args)
        assert result.returncode == 0, result.stderr
    data = status_json(dev)
    assert data["buzzer"] is False
    assert data["autolevel"] is False
    assert (data["zoffset_mm"], data["name"], data["language"]) == (-0.12, "Lab", "fr")
    assert data["raw"]["z"] == "-12"
    energy = run_cli("--json", "xyz", "-d", dev, "energy", "6")
    assert json.loads(energy.stdout) == {"energy_saving_s": 360, "confirmed": False}  # Wi-Fi: no reply, no field
    assert run_cli("xyz", "-d", dev, "energy", "6").stdout == ("energy saving after 6 min idle (sent; a printer on "
                                                               "Wi-Fi does not confirm this setting)\n")
    up = run_cli("--json", "xyz", "-d", dev, "zoffset", "up")
    assert json.loads(up.stdout) == {"zoffset_mm": -0.11}
    refused = run_cli("xyz", "-d", dev, "restore-defaults")
    assert refused.returncode == 4
    assert "--yes" in refused.stderr
    assert run_cli("xyz", "-d", dev, "restore-defaults", "--yes").returncode == 0
    assert status_json(dev)["name"] == "mini w"
    watch = run_cli("--json", "xyz", "-d", dev, "status", "--watch", "--count", "3", "--interval", "0.05")
    assert watch.returncode == 0
    assert len(watch.stdout.strip().splitlines()) == 3


def test_flows_with_prompts(simulator: SimulatorStarter) -> None:
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "100")
    dev = device(sim.url)
    assert run_cli("xyz", "-d", dev, "home").returncode == 0
    assert run_cli("xyz", "-d", dev, "jog", "x", "10").returncode == 0
    assert run_cli("xyz", "-d", dev, "jog", "z", "-5").returncode == 0
    assert run_cli("xyz", "-d", dev, "load", input_text="\n").returncode == 0
    assert run_cli("xyz", "-d", dev, "unload").returncode == 0
    assert run_cli("xyz", "-d", dev, "clean-nozzle", input_text="\n").returncode == 0
    calib = run_cli("--json", "xyz", "-d", dev, "calibrate", input_text="\n\n")
    assert calib.returncode == 0, calib.stderr
    values = json.loads(calib.stdout)["calibration"]
    assert len(values) == 9
    assert status_json(dev)["calibration"] == [int(v) for v in values]
    no_answer = run_cli("xyz", "-d", dev, "load", input_text="")
    assert no_answer.returncode == 4
    assert "no confirmation" in no_answer.stderr
    errors = [line for line in no_answer.stderr.splitlines() if "no confirmation" in line]
    assert [line for line in errors if "press Enter" not in line] == errors, no_answer.stderr  # prompt line ended
    assert (status_json(dev)["state"], status_json(dev)["substate"]) == (9511, 0)


def test_unfinished_calibration_releases_the_printer(simulator: SimulatorStarter) -> None:
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "100")
    dev = device(sim.url)
    for answers in ("", "\n"):  # no confirmation to lower, then none to raise the detector
        result = run_cli("--json", "xyz", "-d", dev, "calibrate", input_text=answers)
        assert result.returncode == 4, result.stderr
        assert "no confirmation" in result.stderr
        assert "printer is idle again" in result.stderr
        errors = [line for line in result.stderr.splitlines() if "no confirmation" in line]
        assert [line for line in errors if "press Enter" not in line] == errors, result.stderr  # prompt line ended
        assert (status_json(dev)["state"], status_json(dev)["substate"]) == (9511, 0)
    proc = subprocess.Popen([sys.executable, "-m", "fabwire", "xyz", "-d", dev, "calibrate"], env=cli_env(),
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    seen = ""
    while "press Enter" not in seen:
        chunk = proc.stderr.read(1)
        assert chunk, "the CLI ended before asking"
        seen += chunk
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)  # stdin stays open: Ctrl-C must not wait for a line
    assert proc.returncode == 130
    assert "printer is idle again" in seen + err
    assert (status_json(dev)["state"], status_json(dev)["substate"]) == (9511, 0)
    assert run_cli("xyz", "-d", dev, "home").returncode == 0


def test_bad_input_and_printer_errors(simulator: SimulatorStarter, tmp_path: Path) -> None:
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000")
    dev = device(sim.url)
    png = tmp_path / "photo.gcode"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(200))
    result = run_cli("xyz", "-d", dev, "print", str(png))
    assert result.returncode == 4
    assert "photo.gcode is an image (PNG), not G-code" in result.stderr
    other = tmp_path / "pro.3w"
    other.write_bytes(write_3w(GCODE, find_model("dvF1W0A000")))
    result = run_cli("xyz", "-d", dev, "print", str(other))
    assert result.returncode == 4
    assert "1.0 Pro" in result.stderr
    result = run_cli("xyz", "-d", dev, "print", "--model", "no-such-printer", str(other))
    assert result.returncode == 4
    assert "unknown printer model" in result.stderr
    long_job = tmp_path / "long.gcode"
    long_job.write_bytes(b";TIME:1000000\n" + GCODE)
    assert run_cli("xyz", "-d", dev, "print", "--no-wait", str(long_job)).returncode == 0
    busy = run_cli("xyz", "-d", dev, "home")
    assert busy.returncode == 4
    assert "busy" in busy.stderr
    assert "printing" in busy.stderr or "checking file" in busy.stderr
    unconfirmed = run_cli("xyz", "-d", dev, "cancel")
    assert unconfirmed.returncode == 4
    assert unconfirmed.stderr.strip() == "fabwire: error: this would cancel the running print: add --yes to confirm"
    assert status_json(dev)["state"] != 9511  # still printing
    assert run_cli("xyz", "-d", dev, "cancel", "--yes").returncode == 0
    assert "Traceback" not in busy.stderr


def test_faulty_printers(simulator: SimulatorStarter, tmp_path: Path) -> None:
    src = tmp_path / "part.gcode"
    src.write_bytes(GCODE * 2000)
    nocart = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000", "--fault", "no-cartridge")
    result = run_cli("xyz", "-d", device(nocart.url), "print", str(src))
    assert result.returncode == 7
    assert "no filament cartridge installed" in result.stderr
    drop = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000", "--fault", "link-drop")
    result = run_cli("xyz", "-d", device(drop.url), "print", str(src))
    assert result.returncode == 8
    assert "did not receive the whole file" in result.stderr
    unreachable = run_cli("xyz", "-d", "127.0.0.1:1", "status")
    assert unreachable.returncode == 8


@pytest.mark.parametrize("fault", ["heater-failure", "file-rejected"])
def test_a_failed_job_never_reads_finished(simulator: SimulatorStarter, tmp_path: Path, fault: str) -> None:
    src = tmp_path / "part.gcode"
    src.write_bytes(GCODE * 20)
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000", "--fault", fault)
    for json_flag in ((), ("--json",)):
        result = run_cli(*json_flag, "xyz", "-d", device(sim.url), "print", str(src))
        assert result.returncode == 7, result.stderr
        assert "device error" in result.stderr
        assert "print finished" not in result.stdout + result.stderr
        assert "9509" not in result.stdout
        run_cli("xyz", "-d", device(sim.url), "acknowledge")


def test_a_stuck_file_check_is_reported_while_waiting_and_in_printer_time(tmp_path: Path) -> None:
    src = tmp_path / "part.gcode"
    src.write_bytes(GCODE)
    # 120 printer seconds of checking take about 1.2 s at speed 100: the limit follows the simulator's clock
    result = run_cli("xyz", "-d", "sim://xyz?speed=100&fault=stuck", "print", str(src), timeout=50)
    assert result.returncode == 9, result.stderr
    assert "still checking the file" in result.stderr
    assert "checking the file for over 120 s" in result.stderr


@pytest.mark.parametrize(("distance", "code", "words"), [
    ("nan", 2, "not a finite number"), ("inf", 2, "not a finite number"), ("-inf", 2, "not a finite number"),
    ("0", 4, "jog distance"), ("301", 4, "jog distance"), ("-1e9", 4, "jog distance")])
def test_a_jog_the_printer_cannot_make_is_bad_input(distance: str, code: int, words: str) -> None:
    result = run_cli("xyz", "-d", "127.0.0.1:1", "jog", "x", distance)  # refused before any connection
    assert result.returncode == code, result.stderr
    assert words in result.stderr


def test_several_simulators_on_loopback_aliases(simulator: SimulatorStarter) -> None:
    port = free_port_on("127.0.0.2", "127.0.0.3")
    a = simulator("xyz", "--listen", f"127.0.0.2:{port}", "--model", "miniMaker")
    b = simulator("xyz", "--listen", f"127.0.0.3:{port}", "--model", "nano")
    assert status_json(device(a.url))["model_number"] == "dv1MX0A000"
    nano = status_json(device(b.url))
    assert nano["model_number"] == "dv1NX0A000"
    assert nano["zoffset_mm"] == -4.69
    found = run_cli("--json", "xyz", "discover", "--host", "127.0.0.2", "--host", "127.0.0.3", "--host", "127.0.0.4",
                    "--port", str(port), "--probe-timeout", "0.5")
    assert found.returncode == 0, found.stderr
    addresses = {entry["address"]: entry["model_number"] for entry in json.loads(found.stdout)}
    assert addresses == {f"127.0.0.2:{port}": "dv1MX0A000", f"127.0.0.3:{port}": "dv1NX0A000"}
    subnet = run_cli("--json", "xyz", "discover", "--subnet", "127.0.0.0/30", "--port", str(port),
                     "--probe-timeout", "0.5")
    # 127.0.0.1 is every parallel test's address: a simulator of another may hold the same port number there
    scanned = {entry["address"] for entry in json.loads(subnet.stdout)} - {f"127.0.0.1:{port}"}
    assert scanned == {f"127.0.0.2:{port}"}  # and not 127.0.0.3, outside the /30


def test_discover_with_nothing_found_says_how_to_search_the_network() -> None:
    """Without --host or --subnet only USB is looked at (no USB printer here): said, with the command that searches
    this computer's network."""
    result = run_cli("xyz", "discover")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "no printers found on USB"
    hint = re.search(r"to search the network too: fabwire xyz discover --subnet (\S+) \(or --host ADDRESS\)",
                     result.stderr)
    assert hint is not None, result.stderr
    assert ipaddress.ip_network(hint[1]).prefixlen == 24


def test_pty_simulator_and_state_file(simulator: SimulatorStarter, tmp_path: Path) -> None:
    state = tmp_path / "state.json"
    link = tmp_path / "ttyXYZ"
    sim = simulator("xyz", "--pty", "--link", str(link), "--state", str(state), "--speed", "1000")
    assert run_cli("xyz", "-d", str(link), "name", "Persist").returncode == 0
    assert run_cli("xyz", "-d", str(link), "zoffset", "261").returncode == 0
    data = status_json(str(link))
    assert (data["name"], data["zoffset_mm"]) == ("Persist", 2.61)
    sim.process.terminate()
    sim.process.wait(10)
    again = simulator("xyz", "--listen", "127.0.0.1:0", "--state", str(state))
    data = status_json(device(again.url))
    assert (data["name"], data["zoffset_mm"]) == ("Persist", 2.61)


@pytest.mark.parametrize("args", [("--model", "nosuch"), ("--fault", "gremlins")])
def test_simulator_refuses_bad_options(args: tuple[str, str]) -> None:
    result = run_cli("sim", "xyz", "--listen", "127.0.0.1:0", *args, timeout=20)
    assert result.returncode == 4
    assert "unknown" in result.stderr


def test_wifi_scan_plus_limits_and_a_wrong_device(simulator: SimulatorStarter) -> None:
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000")
    scan = run_cli("--json", "xyz", "-d", device(sim.url), "wifi", "scan")
    assert scan.returncode == 0, scan.stderr
    assert "TUCKER_HOME" in [n["ssid"] for n in json.loads(scan.stdout)]
    plus = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000", "--model", "1.1 Plus")
    refused = run_cli("xyz", "-d", device(plus.url), "set", "buzzer", "off")
    assert refused.returncode == 7
    assert "only status" in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        port = listener.getsockname()[1]

        def answer() -> None:
            conn, _ = listener.accept()
            with conn:
                conn.recv(100)
                conn.sendall(b"SSH-2.0-OpenSSH_9.2\r\n")

        threading.Thread(target=answer, daemon=True).start()
        wrong = run_cli("xyz", "-d", f"127.0.0.1:{port}", "--timeout", "2", "status")
    assert wrong.returncode == 6, wrong.stderr
    assert "not an XYZv3 printer" in wrong.stderr
    assert "SSH-2.0" in wrong.stderr
    assert "Traceback" not in wrong.stderr


def _join_on_a_terminal(dev: str, ssid: str, typed: bytes) -> tuple[int, str]:
    """`wifi join` with a pty as its stdin (the password prompt needs a terminal); returns exit code, stderr."""
    master, slave = os.openpty()
    try:
        # a new session has no /dev/tty, so the prompt goes to stderr and the answer is read from the pty
        proc = subprocess.Popen([sys.executable, "-m", "fabwire", "xyz", "-d", dev, "wifi", "join", ssid],
                                env=cli_env(), stdin=slave, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                start_new_session=True)
        assert proc.stderr is not None
        seen = b""
        while typed and b"Password" not in seen:
            chunk = proc.stderr.read(1)
            if not chunk:
                break
            seen += chunk
        if b"Password" in seen:
            os.write(master, typed)
        out, err = proc.communicate(timeout=30)
    finally:
        os.close(slave)
        os.close(master)
    return proc.returncode, (out + seen + err).decode()


def test_wifi_join_password_comes_from_the_option_or_a_terminal(simulator: SimulatorStarter) -> None:
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000")
    dev = device(sim.url)
    no_terminal = run_cli("xyz", "-d", dev, "wifi", "join", "MYNET", input_text="")
    assert no_terminal.returncode == 4
    assert "no password given (use --password)" in no_terminal.stderr
    assert "Warning" not in no_terminal.stderr
    code, text = _join_on_a_terminal(dev, "", b"\n")
    assert code == 4
    assert "Wi-Fi network name" in text
    assert "Password" not in text  # refused before asking
    code, text = _join_on_a_terminal(dev, "MYNET", b"secret-key\n")
    assert code == 0, text
    assert "joining MYNET" in text
    given = run_cli("xyz", "-d", dev, "wifi", "join", "MYNET", "--password", "")
    assert given.returncode == 0, given.stderr


def test_an_endless_firmware_file_is_refused_after_a_bounded_read() -> None:
    done = run_cli("xyz", "-d", "sim://xyz", "firmware", "--yes", "/dev/zero")
    assert (done.returncode, done.stdout) == (4, "")
    assert done.stderr.strip().splitlines() == [
        "fabwire: error: /dev/zero is over 64 MiB: not a da Vinci firmware image"]


def test_a_name_the_printer_does_not_report_is_shown_absent_not_empty() -> None:
    status = (b"j:9511,0\nb:20\np:dv1MW0A000\nt:1,22,0\no:p8,t1,c1,a+\n$\n")
    with socket.create_server(("127.0.0.1", 0)) as server:

        def printer() -> None:
            for _ in range(2):
                conn, _ = server.accept()
                with conn:
                    buffer = b""
                    while chunk := conn.recv(4096):
                        buffer += chunk
                        while b"\n" in buffer:
                            line, buffer = buffer.split(b"\n", 1)
                            if line.startswith(b"XYZv3/query=a"):
                                conn.sendall(status)
                            elif line.startswith(b"XYZv3/query="):
                                conn.sendall(b"j:9511,0\n")

        threading.Thread(target=printer, daemon=True).start()
        port = server.getsockname()[1]
        shown = run_cli("xyz", "-d", f"127.0.0.1:{port}", "name", timeout=30)
        data = run_cli("--json", "xyz", "-d", f"127.0.0.1:{port}", "name", timeout=30)
    assert (shown.returncode, shown.stdout) == (0, "—\n"), shown.stderr
    assert json.loads(data.stdout) == {"name": None}


@pytest.mark.parametrize("where", [-1, -100, -2000])  # the checksummed body
def test_a_damaged_print_file_is_refused_before_any_upload(simulator: SimulatorStarter, tmp_path: Path,
                                                           where: int) -> None:
    store = tmp_path / "store"
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000", "--store", str(store))
    good = write_3w(GCODE * 50, find_model("dv1MW0A000"), filename="cube.3w")
    damaged = bytearray(good)
    damaged[where] ^= 0x01
    path = tmp_path / "cube.3w"
    path.write_bytes(bytes(damaged))
    result = run_cli("xyz", "-d", device(sim.url), "print", str(path))
    assert result.returncode == 4, result.stderr
    assert result.stderr.startswith("fabwire: error: cube.3w is damaged: its stored checksum")
    assert result.stderr.count("\n") == 1
    assert not store.exists() or not list(store.iterdir())  # nothing reached the printer


def test_discover_takes_host_and_port_as_every_address_does(simulator: SimulatorStarter) -> None:
    sim = simulator("xyz", "--listen", "127.0.0.1:0")
    address = device(sim.url)
    port = address.rpartition(":")[2]
    for args in (["--host", address], ["--host", "127.0.0.1", "--port", port], ["--host", f"tcp://{address}"]):
        found = run_cli("--json", "xyz", "discover", *args)
        assert found.returncode == 0, found.stderr
        assert [(f["address"], f["model_number"]) for f in json.loads(found.stdout)] == [(address, "dv1MW0A000")]
    serial = run_cli("xyz", "discover", "--host", "/dev/ttyUSB0")
    assert (serial.returncode, serial.stderr) == (4, "fabwire: error: --host takes a host name or address, with an "
                                                     "optional :PORT\n")
    told = run_cli("-v", "xyz", "discover", "--host", "127.0.0.1:1")
    assert told.returncode == 0
    assert "127.0.0.1:1: no printer" in told.stderr


def test_a_print_cancelled_from_elsewhere_ends_the_follow_with_its_own_error(simulator: SimulatorStarter,
                                                                             tmp_path: Path) -> None:
    sim = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1")  # the 600 s job runs far longer than the test
    dev = device(sim.url)
    gcode = tmp_path / "long.gcode"
    gcode.write_bytes(GCODE)
    follow = subprocess.Popen([sys.executable, "-m", "fabwire", "xyz", "-d", dev, "print", str(gcode)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=cli_env(tmp_path))
    try:
        assert follow.stderr is not None
        for line in iter(follow.stderr.readline, ""):  # the job runs: the printer prints it
            if line.startswith("printing"):
                break
        cancelled = run_cli("xyz", "-d", dev, "cancel", "--yes", timeout=120)
        assert cancelled.returncode == 0, cancelled.stderr
        out, err = follow.communicate(timeout=120)
    finally:
        if follow.poll() is None:
            follow.kill()
            follow.wait(10)
    assert follow.returncode == 7, err  # not "idle" and 0: the print did not finish
    assert err.strip().splitlines()[-1].startswith("fabwire: error: the print was cancelled before it finished")
    assert out == ""


def _silent_listener() -> tuple[socket.socket, str]:
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    return server, f"127.0.0.1:{server.getsockname()[1]}"


DISCOVER_MISSES = [  # (what the named host is, how to make it, what discover says of it without -v)
    ("a name that does not resolve", lambda sim: "nosuch.invalid", "cannot resolve host 'nosuch.invalid'"),
    ("nothing listening", lambda sim: "127.0.0.1:1", "nothing listens on port 1"),
    ("a Line-us", lambda sim: device(sim("lineus", "--listen", "127.0.0.1:0").url),
     "it is a Line-us drawing robot (it said 'hello "),
    ("an MMU on TCP", lambda sim: _booted_mmu(sim), "it is a Prusa MMU3"),  # silent first: named from a probe
    ("a web server", lambda sim: _web_server(), "it is a web server"),
    ("a server saying escapes and binary", lambda sim: _junk_server(),
     "it answered b'\\x1b]0;PWNED\\x07\\x1b[2J\\x00\\x01"),  # shown escaped, never raw
]


def _junk_server() -> str:
    """A server that greets every connection with escape sequences and binary bytes, then hangs up."""
    import socketserver

    class Junk(socketserver.BaseRequestHandler):
        def handle(self) -> None:
            self.request.sendall(b"\x1b]0;PWNED\x07\x1b[2J\x00\x01binary junk")

    server = socketserver.ThreadingTCPServer(("127.0.0.1", 0), Junk)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return f"127.0.0.1:{server.server_address[1]}"


def _booted_mmu(simulator: SimulatorStarter) -> str:
    """A simulated MMU that has finished booting (as a real one answers only once booted)."""
    address = device(simulator("mmu", "--listen", "127.0.0.1:0").url)
    assert run_cli("mmu", "-d", address, "version").returncode == 0
    return address


def _web_server() -> str:
    """A real HTTP server (the standard library's), answering in a thread until the test process ends."""
    import http.server

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return f"127.0.0.1:{server.server_address[1]}"


@pytest.mark.parametrize(("what", "make", "said"), DISCOVER_MISSES, ids=[row[0] for row in DISCOVER_MISSES])
def test_discover_says_why_a_named_host_is_no_printer(simulator: SimulatorStarter, what: str,
                                                      make: Callable[[SimulatorStarter], str], said: str) -> None:
    """A host asked for by name gets a line saying why it is not listed (a subnet's empty addresses do not)."""
    printer = device(simulator("xyz", "--listen", "127.0.0.1:0").url)
    address = make(simulator)
    found = run_cli("--json", "xyz", "discover", "--host", address, "--host", printer, "--probe-timeout", "1")
    assert found.returncode == 0, found.stderr
    assert [f["address"] for f in json.loads(found.stdout)] == [printer]
    told = [line for line in found.stderr.splitlines() if line]
    assert len(told) == 1, found.stderr
    assert told[0].startswith(f"{address if ':' in address else address + ':9100'}: not a da Vinci printer: ")
    assert said in told[0]


def test_discover_does_not_list_a_subnets_empty_addresses(simulator: SimulatorStarter) -> None:
    server, address = _silent_listener()
    with server:
        port = address.rpartition(":")[2]
        scanned = run_cli("xyz", "discover", "--subnet", "127.0.0.0/30", "--port", port, "--probe-timeout", "0.5")
    assert scanned.returncode == 0, scanned.stderr
    assert scanned.stdout.strip() == "no printers found"
    assert scanned.stderr == ""
