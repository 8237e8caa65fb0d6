"""Drawing sessions on one Line-us: one drawing at a time across processes, Ctrl-C lifting the pen before the
connection closes, and `--resume` refusing a different plan. Real simulator and CLI processes on loopback TCP."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from clitools import RunningSimulator, cli_env, run_cli, spawn, start_simulator
from fabwire.errors import DeviceBusy
from fabwire.lineus.drawing_lock import DrawingLock, current_drawer

TERM = b"\r\n\x00"
WAIT = 60.0
"""Longest wait for a state to come about (a bound against hanging, never a pass/fail window)."""


def zigzag(path: Path, turns: int = 40) -> Path:
    """One long stroke: the pen stays down for all of it."""
    points = " ".join(f"{0 if i % 2 else 100},{i * 100 / turns:.2f}" for i in range(turns + 1))
    path.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100"><polyline points="{points}" '
                    'fill="none" stroke="black"/></svg>', encoding="utf-8")
    return path


@pytest.fixture
def slow_sim() -> Iterator[RunningSimulator]:
    """A simulator moving at the robot's own speed, so a drawing lasts long enough to interrupt."""
    sim = start_simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "1")
    try:
        yield sim
    finally:
        sim.stop()


def address(sim: RunningSimulator) -> str:
    return sim.url.removeprefix("tcp://")


class Observer:
    """A second connection kept open through the test, reading where the arm is (M114) as the robot reports it."""

    def __init__(self, where: str) -> None:
        host, port = where.rsplit(":", 1)
        self.sock = socket.create_connection((host, int(port)), timeout=WAIT)
        self.buffer = b""
        self.message()  # the hello

    def message(self) -> bytes:
        while TERM not in self.buffer:
            chunk = self.sock.recv(4096)
            assert chunk, "the simulator closed the observer's connection"
            self.buffer += chunk
        line, self.buffer = self.buffer.split(TERM, 1)
        return line

    def position(self) -> dict[str, float]:
        self.sock.sendall(b"M114\x00")
        fields = dict(part.split(":", 1) for part in self.message().decode().split()[1:])
        return {k: float(v) for k, v in fields.items() if k in ("X", "Y", "Z")}

    def close(self) -> None:
        self.sock.close()


def start_drawing(sim: RunningSimulator, svg: Path, state: Path, env: dict[str, str]) -> subprocess.Popen[str]:
    return spawn([sys.executable, "-m", "fabwire", "lineus", "-d", address(sim), "draw", str(svg), "--state",
                  str(state)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def wait_for(condition: object, what: str) -> None:
    deadline = time.monotonic() + WAIT
    while not condition():  # type: ignore[operator]
        assert time.monotonic() < deadline, f"gave up waiting for {what}"
        time.sleep(0.05)


def test_ctrl_c_lifts_the_pen_before_the_connection_closes(slow_sim: RunningSimulator, tmp_path: Path) -> None:
    observer = Observer(address(slow_sim))
    try:
        drawing = start_drawing(slow_sim, zigzag(tmp_path / "zigzag.svg"), tmp_path / "state.json",
                                cli_env(tmp_path))
        wait_for(lambda: observer.position().get("Z", 1000) < 500, "the pen to go down")
        drawing.send_signal(signal.SIGINT)
        _, err = drawing.communicate(timeout=WAIT)
        assert drawing.returncode != 0
        assert "interrupted" in err
        where = observer.position()
        assert where["Z"] == 1000, f"the pen was left down at {where}"
        assert (where["X"], where["Y"]) != (1000, 1000)  # lifted where it stopped, not sent home
    finally:
        observer.close()


def test_a_second_drawing_is_refused_naming_the_first(slow_sim: RunningSimulator, tmp_path: Path) -> None:
    env = cli_env(tmp_path)
    first = start_drawing(slow_sim, zigzag(tmp_path / "zigzag.svg"), tmp_path / "state.json", env)
    try:
        wait_for(lambda: (tmp_path / "state.json").exists() and current_drawer(_robot(slow_sim)) is not None,
                 "the first drawing to start")
        elsewhere = env | {"XDG_RUNTIME_DIR": str(tmp_path / "other-session"), "HOME": str(tmp_path / "other-home")}
        second = run_cli("lineus", "-d", address(slow_sim), "text", "Hi", "--state", str(tmp_path / "s2.json"),
                         env=elsewhere)  # another session (or the agent's service) on the same host
        assert second.returncode == 4, second.stderr
        line, = second.stderr.strip().splitlines()  # the refusal alone: no plan of a drawing that will not be made
        assert "is drawing already" in line
        assert f"process {first.pid}" in line
        assert "zigzag.svg" in line
        assert "fabwire lineus -d" in line  # the command that draws
        for moving in (["move", "1000", "0"], ["home"], ["send", "G01", "X1000", "Y0"]):  # nor moves the arm
            refused = run_cli("lineus", "-d", address(slow_sim), *moving, env=env)
            assert refused.returncode == 4, refused.stderr
            assert f"process {first.pid}" in refused.stderr
        asked = run_cli("lineus", "-d", address(slow_sim), "position", env=env)  # reading it is fine
        assert asked.returncode == 0, asked.stderr
        # a name for the same robot is the same robot
        port = address(slow_sim).rsplit(":", 1)[1]
        third = run_cli("lineus", "-d", f"localhost:{port}", "text", "Hi", "--state", str(tmp_path / "s3.json"),
                        env=env)
        assert third.returncode == 4, third.stderr
    finally:
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=WAIT)
    assert current_drawer(_robot(slow_sim)) is None  # released when the drawing ends


def test_status_names_who_is_drawing_and_where_the_pen_is(slow_sim: RunningSimulator, tmp_path: Path) -> None:
    env = cli_env(tmp_path)
    idle = run_cli("--json", "lineus", "-d", address(slow_sim), "status", env=env)
    assert idle.returncode == 0, idle.stderr
    before = json.loads(idle.stdout)
    assert before["drawing"] is None
    assert before["position"]["pen"] == "up"
    assert before["firmware"]
    assert "idle: no program of this host is drawing on it" in run_cli(
        "lineus", "-d", address(slow_sim), "status", env=env).stdout
    first = start_drawing(slow_sim, zigzag(tmp_path / "zigzag.svg"), tmp_path / "state.json", env)
    try:
        wait_for(lambda: current_drawer(_robot(slow_sim)) is not None, "the drawing to start")
        busy = run_cli("--json", "lineus", "-d", address(slow_sim), "status", env=env)
        assert busy.returncode == 0, busy.stderr
        drawing = json.loads(busy.stdout)["drawing"]
        assert drawing["pid"] == first.pid
        assert "zigzag.svg" in drawing["what"]
        assert drawing["command"].startswith("fabwire lineus -d")
        assert 0 <= drawing["progress_percent"] <= 100
        told = run_cli("lineus", "-d", address(slow_sim), "status", env=env).stdout
        assert f"process {first.pid}" in told
    finally:
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=WAIT)


def _robot(sim: RunningSimulator) -> str:
    return address(sim)


def test_the_lock_is_released_when_the_holder_dies(tmp_path: Path) -> None:
    robot = f"127.0.0.1:{os.getpid() % 50000 + 10000}"
    child = spawn([sys.executable, "-c", (
        "import sys, time\n"
        "from fabwire.lineus.drawing_lock import DrawingLock\n"
        f"lock = DrawingLock({robot!r}, 'a test drawing', command='holder')\n"
        "lock.acquire()\n"
        "print('held', flush=True)\n"
        "time.sleep(600)\n")], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "held"
        holder = current_drawer(robot)
        assert holder is not None
        assert (holder.pid, holder.command) == (child.pid, "holder")
        with pytest.raises(DeviceBusy, match=f"process {child.pid}"):
            DrawingLock(robot, "mine").acquire()
    finally:
        child.kill()
        child.wait()
    assert current_drawer(robot) is None
    with DrawingLock(robot, "mine") as lock:
        lock.update(50.0, "stroke 2 of 4")
        again = current_drawer(robot)
        assert again is not None
        assert (again.progress, again.pid) == ("stroke 2 of 4", os.getpid())




def test_the_agent_and_the_cli_draw_one_at_a_time(slow_sim: RunningSimulator, tmp_path: Path) -> None:
    from agent.agenttools import device_of, start_agent, summary
    from agent.agenttools import wait_for as wait_until

    config = tmp_path / "devices.toml"
    config.write_text(f'[devices.arm]\nkind = "lineus"\nurl = "{slow_sim.url}"\n', encoding="utf-8")
    agent = start_agent(tmp_path / "state", "--config", str(config))
    drawing: subprocess.Popen[str] | None = None
    try:
        with agent.client() as client:
            arm = wait_until(lambda: (d := device_of(client, "lineus"))["state"]["online"] and d, "the arm online")
            drawing = start_drawing(slow_sim, zigzag(tmp_path / "zigzag.svg"), tmp_path / "state.json",
                                    cli_env(tmp_path))
            shown = wait_until(lambda: (s := summary(client, arm["id"]))["state"] == "drawing" and s,
                               "the agent to show the CLI's drawing")
            assert "another program" in shown["state_text"]
            assert f"process {drawing.pid}" in shown["state_text"]
            assert "zigzag.svg" in shown["state_text"]
            assert shown["busy"] is True
            assert shown["actions"] == []
            moved = client.post(f"/api/v1/devices/{arm['id']}/actions/move", json={"x": 1000, "y": 0})
            assert moved.status_code == 409, moved.text
            assert f"process {drawing.pid}" in moved.text

            drawing.send_signal(signal.SIGINT)
            drawing.communicate(timeout=WAIT)
            drawing = None
            wait_until(lambda: summary(client, arm["id"])["state"] == "idle", "the agent to show the arm idle")

            job = client.post(f"/api/v1/devices/{arm['id']}/actions/text",
                              json={"text": "a long line of words"}).json()["job"]
            wait_until(lambda: client.get(f"/api/v1/jobs/{job['id']}").json()["state"] == "running",
                       "the agent's drawing running")
            wait_until(lambda: current_drawer(address(slow_sim)) is not None, "the agent to hold the robot")
            second = run_cli("lineus", "-d", address(slow_sim), "text", "Hi", "--state", str(tmp_path / "s2.json"),
                             env=cli_env(tmp_path))
            assert second.returncode == 4, second.stderr
            assert "fabwire serve (arm)" in second.stderr
            assert "'a long line of words'" in second.stderr

            cancel = client.post(f"/api/v1/jobs/{job['id']}/cancel", json={"confirm": True})
            assert cancel.status_code < 300, cancel.text
            wait_until(lambda: client.get(f"/api/v1/jobs/{job['id']}").json()["state"] == "cancelled",
                       "the agent's drawing cancelled")
            # a job keeps what the planner said about it, as `lineus text` prints it
            noted = client.post(f"/api/v1/devices/{arm['id']}/actions/text", json={"text": "I 漢"}).json()["job"]
            finished = wait_until(lambda: (j := client.get(f"/api/v1/jobs/{noted['id']}").json())["state"]
                                  in ("done", "failed") and j, "the short drawing to finish")
            assert finished["state"] == "done", finished
            assert "cannot draw '漢'" in finished["message"]
    finally:
        if drawing is not None:
            drawing.kill()
            drawing.communicate()
        agent.stop()


# -- --resume never starts over by itself ---------------------------------------------------------------------------

DATA = Path(__file__).parent / "data" / "svg"


@pytest.fixture(scope="module")
def interrupted(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Path]]:
    """A Line-us simulator and the progress file of a drawing of arcs.svg (default options) whose link dropped
    part way through."""
    sim = start_simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "0")
    folder = tmp_path_factory.mktemp("interrupted")
    state = folder / "progress.json"
    try:
        first = run_cli("lineus", "-d", address(sim), "--inject", "disconnect_after=5000", "draw",
                        str(DATA / "arcs.svg"), "--state", str(state), env=cli_env(folder))
        assert first.returncode == 8, first.stderr
        yield address(sim), state
    finally:
        sim.stop()


# (options given to the resume, what the refusal names)
CHANGED = [
    (["--margin", "5"], "--margin 2 (now 5)"),
    (["--rotate", "90"], "--rotate 0 (now 90)"),
    (["--rotate", "auto"], "--rotate 0 (now auto)"),
    (["--no-fit"], "--fit default (now off)"),
    (["--clip"], "--clip off (now on)"),
    (["--full-area"], "--full-area off (now on)"),
    (["--no-optimize"], "--no-optimize off (now on)"),
]


@pytest.mark.parametrize(("options", "named"), CHANGED, ids=[" ".join(o) for o, _ in CHANGED])
def test_resume_with_other_options_is_refused_naming_them(interrupted: tuple[str, Path], tmp_path: Path,
                                                          options: list[str], named: str) -> None:
    where, saved = interrupted
    state = tmp_path / "progress.json"
    state.write_bytes(saved.read_bytes())
    done = run_cli("lineus", "-d", where, "draw", str(DATA / "arcs.svg"), "--state", str(state), "--resume",
                   *options, env=cli_env(tmp_path))
    assert done.returncode == 4, done.stderr
    line = done.stderr.strip().splitlines()[-1]
    assert named in line
    assert "--restart" in line
    assert state.read_bytes() == saved.read_bytes()  # nothing drawn, nothing overwritten


def test_resume_without_progress_is_refused(interrupted: tuple[str, Path], tmp_path: Path) -> None:
    where, _ = interrupted
    done = run_cli("lineus", "-d", where, "draw", str(DATA / "arcs.svg"), "--state", str(tmp_path / "lost.json"),
                   "--resume", env=cli_env(tmp_path))
    assert done.returncode == 4, done.stderr
    assert "nothing to resume" in done.stderr
    assert "--restart" in done.stderr
    assert not (tmp_path / "lost.json").exists()


def test_resume_of_another_drawing_is_refused(interrupted: tuple[str, Path], tmp_path: Path) -> None:
    where, saved = interrupted
    state = tmp_path / "progress.json"
    state.write_bytes(saved.read_bytes())
    other = zigzag(tmp_path / "zigzag.svg")
    done = run_cli("lineus", "-d", where, "draw", str(other), "--state", str(state), "--resume", env=cli_env(tmp_path))
    assert done.returncode == 4, done.stderr
    assert "is for another drawing" in done.stderr
    assert "--restart" in done.stderr


def test_resume_with_the_same_options_carries_on(interrupted: tuple[str, Path], tmp_path: Path) -> None:
    where, saved = interrupted
    state = tmp_path / "progress.json"
    state.write_bytes(saved.read_bytes())
    done = run_cli("--json", "lineus", "-d", where, "draw", str(DATA / "arcs.svg"), "--state", str(state),
                   "--resume", "--margin", "2", env=cli_env(tmp_path))
    assert done.returncode == 0, done.stderr
    assert '"resumed_at"' in done.stdout
    left = re.search(r"about (.+) left", done.stderr)
    assert left is not None, done.stderr
    assert f"estimated drawing time {left.group(1)}\n" in done.stderr  # the figures are those of what is left
    strokes = re.search(r"resuming .* at stroke (\d+) of (\d+)", done.stderr)
    assert strokes is not None
    assert f"strokes {int(strokes.group(2)) - int(strokes.group(1)) + 1}," in done.stderr


def test_text_resume_names_a_changed_size_and_font(interrupted: tuple[str, Path], tmp_path: Path) -> None:
    where, _ = interrupted
    state = tmp_path / "text.json"
    env = cli_env(tmp_path)
    first = run_cli("lineus", "-d", where, "--inject", "disconnect_after=3000", "text", "Hello there", "--state",
                    str(state), env=env)
    assert first.returncode == 8, first.stderr
    done = run_cli("lineus", "-d", where, "text", "Hello there", "--state", str(state), "--resume", "--size", "8",
                   "--font", "timesr", env=env)
    assert done.returncode == 4, done.stderr
    assert "--size largest (now 8)" in done.stderr
    assert "--font futural (now timesr)" in done.stderr
