"""`fabwire lineus …` and `fabwire sim lineus` as real subprocesses over loopback TCP."""

from __future__ import annotations

import contextlib
import json
import socket
import threading
from collections.abc import Callable
from pathlib import Path

import pytest

from clitools import cli_env, run_cli


def cli(url: str, *args: str, json_out: bool = False):
    return run_cli(*(["--json"] if json_out else []), "lineus", "-d", url, *args)


def test_session_through_the_cli(simulator, tmp_path: Path) -> None:
    record = tmp_path / "drawn.svg"
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "inf", "--name", "cli-bot",
                    "--record", str(record))
    url = sim.url
    assert url.startswith("tcp://127.0.0.1:")

    info = cli(url, "info", json_out=True)
    assert info.returncode == 0, info.stderr
    data = json.loads(info.stdout)
    assert data["name"] == "cli-bot"
    assert data["firmware_major"] == 3
    assert data["capabilities"] == {"CONNECTMODE": "ST", "MACHINENAME": "cli-bot"}

    moved = cli(url, "move", "1200", "0", "--pen", "down", json_out=True)
    assert json.loads(moved.stdout) == {"x_mm": 60.0, "y_mm": 0.0, "pen": "down", "clamped": False,
                                        "machine_units": {"x": 1200.0, "y": 0.0, "z": 0.0}}
    # Each CLI call is a new connection: the arm homes (pen up) before greeting, so this stroke starts from a drop.
    assert cli(url, "move", "1200", "-300", "--pen", "down").returncode == 0
    assert cli(url, "move", "1200", "300", "--pen", "down").returncode == 0
    clamped = cli(url, "move", "2500", "0", json_out=True)
    assert json.loads(clamped.stdout)["x_mm"] == 97.5  # the edge of the area: 1950 units
    assert json.loads(clamped.stdout)["clamped"] is True
    assert "outside the drawing area" in clamped.stderr

    position = cli(url, "position")  # a new connection homes the arm first
    assert position.returncode == 0
    assert "X 1000  Y 1000  Z 1000  (pen up)" in position.stdout
    assert "S 135.00°  E 45.00°" in cli(url, "home").stdout + cli(url, "position", "--servos").stdout
    angles = json.loads(cli(url, "position", "--servos", json_out=True).stdout)
    assert (angles["s_deg"], angles["e_deg"]) == (135.0, 45.0)

    gcode = tmp_path / "square.gcode"
    gcode.write_text("; a square\nG54 X0 Y0 S1\nG01 X1100 Y0 Z1000\nG01 X1200 Y0 Z0 ; first side\n\nG01 Z1000\n")
    saved = cli(url, "files", "save", str(gcode), "7", json_out=True)
    assert json.loads(saved.stdout) == {"slot": 7, "lines": 4}
    listing = json.loads(cli(url, "files", "list", json_out=True).stdout)
    assert [row["slot"] for row in listing] == [1, 7]
    assert cli(url, "files", "delete", "7").returncode == 0
    assert "/0000007.txt" not in cli(url, "files", "list").stdout
    missing = cli(url, "files", "delete", "7")
    assert missing.returncode == 7
    assert "no drawing 7" in missing.stderr

    assert cli(url, "name").stdout.strip() == "cli-bot"
    assert cli(url, "name", "renamed").stdout.strip() == "renamed"
    bad_name = cli(url, "name", "bad name!")
    assert bad_name.returncode == 4
    assert "Traceback" not in bad_name.stderr

    assert cli(url, "wifi", "add", "cafe net", "--password", "p w").returncode == 0
    networks = json.loads(cli(url, "wifi", "list", json_out=True).stdout)
    assert {"ssid": "cafe net", "visible": False, "known": True} in networks
    assert cli(url, "wifi", "forget", "--all").returncode == 0
    assert "known" not in cli(url, "wifi", "list").stdout.replace("unknown", "")

    refused = cli(url, "calibrate")
    assert refused.returncode == 4
    assert "--yes" in refused.stderr
    assert cli(url, "calibrate", "--yes").returncode == 0

    sent = cli(url, "send", "M115")
    assert sent.stdout.strip() == "ok CONNECTMODE:ST MACHINENAME:renamed"
    assert cli(url, "send", "G04", "P100").returncode == 4

    trace = tmp_path / "wire.trace"
    assert run_cli("lineus", "-d", url, "--trace", str(trace), "position").returncode == 0
    shown = run_cli("trace", "show", "--no-time", str(trace))
    assert "M114" in shown.stdout
    assert "hello" in shown.stdout

    host, port = url.removeprefix("tcp://").rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=10) as sock:
        stream = sock.makefile("rb")
        assert stream.readline().startswith(b"hello ")
        for command in (b"G01 X1200 Y0 Z0\x00", b"G01 X1400 Y0 Z0\x00", b"G01 Z1000\x00"):
            sock.sendall(command)
            assert stream.read(1) == b"\x00"
            assert stream.readline().startswith(b"ok ")
    sim.process.terminate()
    assert sim.process.wait(10) == 0
    assert sim.process.stderr is not None
    # The three `move --pen down` calls each put the pen down in one place (a dot; the next connection's homing
    # lifts it), and the raw session drew one line.
    assert "recorded 4 stroke(s)" in sim.process.stderr.read()
    svg = record.read_text()
    assert svg.startswith("<?xml")
    assert "1200" in svg


def test_errors_are_one_line(tmp_path: Path) -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    refused = run_cli("lineus", "-d", f"127.0.0.1:{port}", "position")
    assert refused.returncode == 8
    assert "connection refused" in refused.stderr
    assert "Traceback" not in refused.stderr
    gcode = tmp_path / "bad.gcode"
    gcode.write_text("G01 X1e5\n")
    bad = run_cli("lineus", "-d", f"127.0.0.1:{port}", "files", "save", str(gcode), "3")
    assert bad.returncode == 4
    assert "line 1" in bad.stderr


def test_not_a_lineus_host(simulator) -> None:
    other = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "inf", "--version", "1.0.1")
    ok = run_cli("--json", "lineus", "-d", other.url, "info")
    assert json.loads(ok.stdout)["firmware_major"] == 1
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        port = listener.getsockname()[1]
        silent = run_cli("lineus", "-d", f"127.0.0.1:{port}", "--timeout", "1", "position", timeout=30)
    assert silent.returncode == 9
    assert "no hello" in silent.stderr


def test_in_process_simulator_url() -> None:
    done = run_cli("--json", "lineus", "-d", "sim://lineus?speed=inf", "move", "1300", "200")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["machine_units"]["x"] == 1300.0


def test_sim_rejects_bad_options(tmp_path: Path) -> None:
    bad = run_cli("sim", "lineus", "--listen", "127.0.0.1:0", "--version", "banana")
    assert bad.returncode == 4
    assert "version" in bad.stderr
    bad_record = run_cli("sim", "lineus", "--listen", "127.0.0.1:0", "--record", str(tmp_path / "x.txt"))
    assert bad_record.returncode == 4


@pytest.mark.timeout(60)
def test_discover_finds_advertised_simulator(simulator) -> None:
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "inf", "--name", "adv-bot", "--advertise")
    port = int(sim.url.rsplit(":", 1)[1])
    found = run_cli("--json", "lineus", "discover", "--wait", "1.5", "--interface", "127.0.0.1")
    assert found.returncode == 0, found.stderr
    expected = {"name": "adv-bot", "host": "adv-bot.local.", "address": "127.0.0.1", "port": port}
    assert expected in json.loads(found.stdout)


def test_firmware_update_needs_yes_and_reports_the_refusal() -> None:
    unconfirmed = run_cli("lineus", "-d", "sim://lineus?speed=inf", "update")
    assert unconfirmed.returncode == 4
    assert "--yes" in unconfirmed.stderr
    refused = run_cli("lineus", "-d", "sim://lineus?speed=inf", "update", "--yes")
    assert refused.returncode not in (0, 4)
    assert "update server unreachable" in refused.stderr
    assert "Traceback" not in refused.stderr


DATA = Path(__file__).parent / "data"


def _record_marks(path: Path) -> tuple[int, int]:
    """(polylines, dots) in the strokes group of a recorded SVG."""
    import xml.etree.ElementTree as ET

    ns = {"svg": "http://www.w3.org/2000/svg"}
    group = ET.parse(path).getroot().find("svg:g[@id='strokes']", ns)
    assert group is not None
    return len(group.findall("svg:polyline", ns)), len(group.findall("svg:circle", ns))


def test_dots_reach_the_record(simulator, tmp_path: Path) -> None:
    record = tmp_path / "rec.svg"
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "inf", "--record", str(record))
    drawn = run_cli("lineus", "-d", sim.url, "draw", str(DATA / "gcode" / "dots.gcode"), "--state",
                    str(tmp_path / "s.json"))
    assert drawn.returncode == 0, drawn.stderr
    assert "recorded 4 stroke(s)" in sim.stop()
    assert _record_marks(record) == (1, 3)


def test_firmware1_never_gets_a_target_in_the_body_notch(simulator, tmp_path: Path) -> None:
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "inf", "--version", "1.0.1")
    trace = tmp_path / "wire.jsonl"
    moved = run_cli("--json", "lineus", "-d", sim.url, "--trace", str(trace), "move", "600", "-300", "--pen", "down")
    assert moved.returncode == 0, moved.stderr
    assert json.loads(moved.stdout)["machine_units"]["z"] == 1000.0
    assert "body notch" in moved.stderr
    sent = [json.loads(line)["data"] for line in trace.read_text().splitlines() if '"dir": ">"' in line]
    assert sent
    assert all("X600" not in command for command in sent)
    shell = run_cli("lineus", "-d", sim.url, "shell", input_text="move 1200 0 down\nG01 X650 Y-900 Z0\n")
    assert shell.returncode == 0, shell.stderr
    assert "body notch" in shell.stdout
    assert "collision" not in sim.stop()


CLAMPED_MOVES = [
    # (firmware, target, the one note's words): every way a target is kept out, on both firmware generations
    ("1.0.1", ("600", "-200"), "is in the body notch that firmware 1.0.1 does not keep out of"),  # fabwire's guard
    ("3.1.1", ("600", "-200"), "is in the notch beside the robot's body"),  # the firmware keeps out by itself
    ("1.0.1", ("6000", "-200"), "is outside the drawing area"),
    ("3.1.1", ("2500", "0"), "is outside the drawing area"),
    ("3.1.1", ("-100", "500"), "is outside the drawing area"),
    ("3.1.1", ("-100000", "-100000"), "is outside the drawing area"),  # below and left, but far beyond the notch
]


@pytest.mark.parametrize(("firmware", "target", "said"), CLAMPED_MOVES)
def test_a_clamped_move_is_explained_once(firmware: str, target: tuple[str, str], said: str) -> None:
    url = f"sim://lineus?version={firmware}"
    moved = cli(url, "move", *target)
    assert moved.returncode == 0, moved.stderr
    notes = [line for line in moved.stderr.splitlines() if line.startswith(f"({target[0]}, {target[1]})")]
    assert len(notes) == 1, moved.stderr
    assert said in notes[0]
    shell = run_cli("lineus", "-d", url, "shell", input_text=f"move {target[0]} {target[1]}\n")
    assert shell.returncode == 0, shell.stderr
    notes = [line for line in shell.stdout.splitlines() if f"({target[0]}, {target[1]})" in line]
    assert len(notes) == 1, shell.stdout
    assert said in notes[0]


def test_shell_keeps_one_connection(simulator, tmp_path: Path) -> None:
    record = tmp_path / "rec.svg"
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "inf", "--record", str(record))
    script = "\n".join(["help", "move 1200 0 down", "move 1400 0", "position", "up", "M114", "speed 10 20",
                        "G01 X1400 Y300 Z0", "m 1200 300", "home", "history", "quit", "move 1000 0 down"]) + "\n"
    session = run_cli("lineus", "-d", sim.url, "shell", input_text=script)
    assert session.returncode == 0, session.stderr
    out = session.stdout.splitlines()
    assert "X 1400  Y 0  Z 0  (pen down)" in out  # no homing between moves: one connection
    assert "ok X:1400.00 Y:0.00 Z:1000.00" in out  # raw G-code gets the raw reply
    assert "  12  quit" not in out
    assert "   3  move 1400 0" in out
    assert "Traceback" not in session.stderr
    sim.stop()
    assert _record_marks(record) == (2, 0)  # (1200,0)-(1400,0) and (1400,300)-(1200,300); nothing after quit
    bad = run_cli("lineus", "-d", sim.url.replace("tcp://", ""), "shell", input_text="jump\n")
    assert bad.returncode != 0


def test_shell_reports_bad_lines_and_goes_on(simulator) -> None:
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "inf")
    session = run_cli("lineus", "-d", sim.url, "shell", input_text="fly 1 2\nmove 1200 abc\nG04 P1\nZ9\npos\n")
    assert session.returncode == 4
    assert session.stdout.strip().splitlines()[-1] == "X 1000  Y 1000  Z 1000  (pen up)"
    errors = [line for line in session.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 4
    assert any("G04" in line for line in errors)
    assert "4 line(s) of the session failed" in session.stderr


def test_shell_speaks_json_lines(simulator) -> None:
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "inf")
    script = "move 1200 0 down\nM114\nfly\nmove 5000 5000\nhelp\n"
    session = run_cli("--json", "lineus", "-d", sim.url, "shell", input_text=script)
    assert session.returncode == 4
    events = [json.loads(line) for line in session.stdout.splitlines()]
    assert events[0] == {"line": "move 1200 0 down", "position": {
        "x_mm": 60, "y_mm": 0, "pen": "down", "machine_units": {"x": 1200, "y": 0, "z": 0}}}
    assert events[1]["line"] == "M114"
    assert events[1]["reply"]["ok"] is True
    assert events[1]["reply"]["fields"]["X"] == "1200.00"
    assert events[2] == {"line": "fly", "error": "unknown command 'fly' (type help)"}
    assert events[3] == {"notice": "(5000, 5000) is outside the drawing area"}
    assert events[4]["line"] == "move 5000 5000"
    assert events[4]["position"]["pen"] == "up"
    assert events[-1]["line"] == "help"
    assert "history" in events[-1]["text"]


def test_preview_writes_gcode_that_files_save_accepts_and_draw_replays(simulator, tmp_path: Path) -> None:
    svg = DATA / "svg" / "arcs.svg"
    plan_gcode = tmp_path / "plan.gcode"
    made = run_cli("lineus", "preview", str(svg), "-o", str(plan_gcode), "--pen-z", "300")
    assert made.returncode == 0, made.stderr
    assert made.stdout.splitlines()[-1] == f"wrote {plan_gcode}"  # said, as `xyz convert` says it
    lines = plan_gcode.read_text().splitlines()
    assert lines[0] == "G01 Z1000"
    assert "G01 Z300" in lines
    record = tmp_path / "rec.svg"
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "inf", "--record", str(record))
    saved = run_cli("--json", "lineus", "-d", sim.url, "files", "save", str(plan_gcode), "5")
    assert saved.returncode == 0, saved.stderr
    assert json.loads(saved.stdout) == {"slot": 5, "lines": len(lines)}
    replay = run_cli("--json", "lineus", "-d", sim.url, "draw", str(plan_gcode), "--state", str(tmp_path / "s.json"))
    assert replay.returncode == 0, replay.stderr
    sim.stop()
    from fabwire.lineus.plot import plan_file

    planned = plan_file(svg)
    assert _record_marks(record) == (len(planned.strokes), 0)
    assert json.loads(replay.stdout)["strokes"] == len(planned.strokes)


def test_local_names_resolve_by_mdns_with_the_advertised_port(simulator) -> None:
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "inf", "--name", "mdns-bot", "--advertise")
    where = run_cli("--json", "lineus", "-d", "mdns-bot.local", "position")
    assert where.returncode == 0, where.stderr
    assert json.loads(where.stdout)["x_mm"] == 50.0
    missing = run_cli("lineus", "-d", "no-such-bot.local", "--timeout", "1", "position")
    assert missing.returncode == 8
    assert "no-such-bot.local" in missing.stderr
    assert "Traceback" not in missing.stderr
    sim.stop()


def test_silent_robot_and_interrupted_draw_print_one_line(simulator, tmp_path: Path) -> None:
    import contextlib
    import signal
    import subprocess
    import sys
    import threading
    import time

    from clitools import cli_env

    hello = b'hello VERSION:"3.2.0 Nov 17 2019 17:54:57" NAME:line-us SERIAL:123456\r\n\x00'
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        port = listener.getsockname()[1]

        def greet_then_nothing() -> None:
            with contextlib.suppress(OSError):
                conn, _ = listener.accept()
                conn.sendall(hello)
                while conn.recv(4096):
                    pass

        threading.Thread(target=greet_then_nothing, daemon=True).start()
        silent = run_cli("lineus", "-d", f"127.0.0.1:{port}", "home", timeout=60)
    assert silent.returncode == 9
    assert len(silent.stderr.strip().splitlines()) == 1
    assert "never retrieved" not in silent.stderr
    assert "Traceback" not in silent.stderr

    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0.5")
    state = tmp_path / "state.json"
    draw = subprocess.Popen([sys.executable, "-m", "fabwire", "lineus", "-d", sim.url, "draw",
                             str(DATA / "svg" / "arcs.svg"), "--state", str(state)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=cli_env(tmp_path))
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (state.exists() and json.loads(state.read_text())["done"] >= 1):
        time.sleep(0.05)  # the first stroke is done: the interrupt lands in a later one
    time.sleep(0.3)
    draw.send_signal(signal.SIGINT)
    _, err = draw.communicate(timeout=60)
    assert draw.returncode == 130
    assert "interrupted" in err
    assert "--resume" in err
    assert "never retrieved" not in err
    assert "Traceback" not in err
    saved = json.loads(state.read_text())
    assert saved["done"] >= 1
    assert saved["done"] + (saved["point"] > 0) <= len(saved["strokes"])
    sim.stop()


@pytest.mark.parametrize(("where", "reason"), [
    ("missing/drawn.png", "No such file or directory"),
    ("a-file/drawn.svg", "Not a directory"),
    ("/proc/drawn.png", ""),  # a folder nobody can create files in, not even root
], ids=["missing-folder", "folder-is-a-file", "read-only-folder"])
def test_sim_record_path_that_cannot_be_written_is_refused_at_start(tmp_path: Path, where: str,
                                                                   reason: str) -> None:
    (tmp_path / "a-file").write_text("not a folder")
    target = Path(where) if where.startswith("/") else tmp_path / where
    result = run_cli("sim", "lineus", "--listen", "127.0.0.1:0", "--record", str(target), timeout=30)
    assert result.returncode == 4
    assert result.stderr.startswith(f"fabwire: error: --record {target}: cannot write there: {reason}")
    assert len(result.stderr.strip().splitlines()) == 1
    assert "listening" not in result.stdout + result.stderr  # refused before serving anything
    assert not target.exists()


HELLO = b'hello VERSION:"3.2.0 Nov 17 2019 17:54:57" NAME:line-us SERIAL:123456\r\n\0'


class LyingLineUs:
    """A TCP peer that greets like a Line-us and then answers every command the way `answer` says."""

    def __init__(self, answer: Callable[[socket.socket, bytes], bool]) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.address = f"127.0.0.1:{self.server.getsockname()[1]}"
        self.answer = answer
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        with contextlib.suppress(OSError):
            while True:
                peer, _ = self.server.accept()
                threading.Thread(target=self._talk, args=(peer,), daemon=True).start()

    def _talk(self, peer: socket.socket) -> None:
        with peer, contextlib.suppress(OSError):
            peer.sendall(HELLO)
            buffered = b""
            while data := peer.recv(4096):
                buffered += data.replace(b"\n", b"\0")
                *lines, buffered = buffered.split(b"\0")
                for line in filter(None, (raw.strip() for raw in lines)):
                    if not self.answer(peer, line):
                        return


def _refuse(peer: socket.socket, line: bytes) -> bool:
    peer.sendall(b"error\r\n\0")
    return True


def _hang_up(peer: socket.socket, line: bytes) -> bool:
    return False


def _babble(peer: socket.socket, line: bytes) -> bool:
    peer.sendall(b"banana split\r\n\0")
    return True


def _bare_ok(peer: socket.socket, line: bytes) -> bool:
    peer.sendall(b"ok\r\n\0")
    return True


@pytest.mark.parametrize(("answer", "code", "words"), [
    (_refuse, 7, "the Line-us refused 'G01 X1200 Y0'"),
    (_hang_up, 8, "the Line-us closed the connection with 1 command(s) unanswered (first: 'G01 X1200 Y0')"),
    (_babble, 6, "reply starts with 'banana', not ok/error/hello"),
    (_bare_ok, 6, "reply 'ok' does not carry X, Y and Z"),
])
def test_a_line_us_that_does_not_do_the_move_is_never_a_success(answer: Callable[[socket.socket, bytes], bool],
                                                                 code: int, words: str) -> None:
    device = LyingLineUs(answer)
    for args in (("move", "1200", "0"), ("--json", "move", "1200", "0")):
        result = run_cli("--timeout", "5", "lineus", "-d", device.address, *args)
        assert result.returncode == code, result.stderr
        assert result.stdout == ""
        assert result.stderr.splitlines() == [f"fabwire: error: {words}"]


def test_text_from_standard_input_and_named_in_the_json(simulator, tmp_path: Path) -> None:
    sim = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "inf")
    env = cli_env(tmp_path)
    piped = run_cli("--json", "lineus", "-d", sim.url, "text", "-", input_text="hi there\n", env=env)
    assert piped.returncode == 0, piped.stderr
    assert json.loads(piped.stdout)["text"] == "hi there"
    typed = run_cli("--json", "lineus", "-d", sim.url, "text", "hi there", env=env)
    assert json.loads(typed.stdout)["strokes"] == json.loads(piped.stdout)["strokes"]
    again = run_cli("lineus", "-d", sim.url, "text", "-", "--resume", input_text="hi there", env=env)
    assert again.stdout == "'hi there' has been drawn completely already; use --restart to draw it again\n"
    too_long = run_cli("lineus", "-d", sim.url, "text", "-", input_text="x" * 70_000, env=env)
    assert too_long.returncode == 4
    assert too_long.stderr == "fabwire: error: the text on standard input is longer than 65536 characters\n"


PREVIEW_OUTPUT_REFUSALS = [  # (output name, what the one-line refusal says): every output is checked first
    ("q4.jpg", "a picture file ends in .svg or .png (or .gcode for the plan), not '.jpg'"),
    ("q5.PDF", "not '.PDF'"),
    ("p8", "and this name has no extension"),
    ("nodir/q2.png", "there is no folder"),
]


@pytest.mark.parametrize(("name", "said"), PREVIEW_OUTPUT_REFUSALS)
def test_preview_checks_every_output_before_writing_any(tmp_path: Path, name: str, said: str) -> None:
    first = tmp_path / "first.png"
    done = run_cli("lineus", "preview", str(DATA / "svg" / "arcs.svg"), "-o", str(first), "-o", str(tmp_path / name))
    assert done.returncode == 4
    assert said in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert not first.exists()


def test_preview_says_which_outputs_it_wrote_before_one_failed(tmp_path: Path) -> None:
    first = tmp_path / "first.svg"
    done = run_cli("lineus", "preview", str(DATA / "svg" / "arcs.svg"), "-o", str(first), "-o", "/proc/self/x.png")
    assert done.returncode == 4
    assert f"wrote {first}" in done.stderr
    assert "cannot write /proc/self/x.png" in done.stderr
    assert first.read_text().startswith("<")
