"""`fabwire serve` as a command: the demo from one command, clean errors for bad options, a graceful stop."""

from __future__ import annotations

import contextlib
import fcntl
import importlib.util
import signal
import socket
import sys
import termios
import threading
import time
from pathlib import Path

import httpx
import pytest

from clitools import cli_env, run_cli

from .agenttools import start_agent, wait_for


def test_demo_starts_three_simulators_and_stops_them(tmp_path: Path) -> None:
    agent = start_agent(tmp_path / "state", "--demo", "--speed", "30")
    try:
        with agent.client() as client:
            devices = wait_for(lambda: (d := client.get("/api/v1/devices").json()) and all(
                x["state"]["online"] for x in d) and d, "the demo's machines online")
            assert [d["kind"] for d in devices] == ["xyz", "lineus", "mmu"]
            assert [d["name"] for d in devices] == ["printer", "line-us", "mmu"]
            # the simulators' ports change every run; the ids (and so the history and bookmarks) do not
            assert [d["id"] for d in devices] == ["xyz-demo", "lineus-demo", "mmu-demo"]
            page = client.get("/")
            assert page.status_code == 200
            assert "<main id=\"devices\"" in page.text
            assert client.get("/static/app.js").status_code == 200
            ports = [int(d["address"].rsplit(":", 1)[1]) for d in devices]
    finally:
        code, stderr = agent.stop()
    assert code == 0, stderr
    assert "Traceback" not in stderr
    for port in ports:  # the simulators went with the agent
        with socket.socket() as sock:
            assert sock.connect_ex(("127.0.0.1", port)) != 0


def test_bad_options_are_one_line_errors(tmp_path: Path) -> None:
    env = cli_env(tmp_path)
    state = ["--state-dir", str(tmp_path / "state")]
    cases = [
        (["serve", "--device", "toaster=1.2.3.4", *state], "--device takes KIND=ADDRESS"),
        (["serve", "--listen", "127.0.0.1:99999", *state], "port must be a number from 0 to 65535"),
    ]
    for args, words in cases:  # usage errors, before anything starts: exit 2 and the one line that says why
        result = run_cli(*args, env=env, timeout=60)
        assert result.returncode == 2, (args, result.stderr)
        errors = [line for line in result.stderr.splitlines() if line.startswith("Error:")]
        assert len(errors) == 1, result.stderr
        assert words in errors[0]
        assert "Traceback" not in result.stderr
        assert not (tmp_path / "state").exists()


def test_a_port_in_use_is_said_plainly(tmp_path: Path) -> None:
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = run_cli("serve", "--listen", f"127.0.0.1:{port}", "--state-dir", str(tmp_path), env=cli_env(tmp_path))
    assert result.returncode == 8  # a link failure, as for a simulator: a service manager tries again
    assert f"cannot listen on 127.0.0.1:{port}: the address is already in use" in result.stderr
    assert "Traceback" not in result.stderr


def test_mqtt_option_needs_the_bridge(tmp_path: Path) -> None:
    if importlib.util.find_spec("fabwire.mqtt") is not None:  # the bridge is installed: it is what --mqtt runs
        from fabwire.mqtt.bridge import run_bridge

        assert callable(run_bridge)
        return
    result = run_cli("serve", "--mqtt", "mqtt://127.0.0.1:1", "--state-dir", str(tmp_path), env=cli_env(tmp_path),
                     timeout=30)
    assert result.returncode == 4
    assert "MQTT support not installed: pip install 'fabwire[mqtt]'" in result.stderr


def test_a_bad_listen_address_fails_before_any_token_is_made(tmp_path: Path) -> None:
    state = tmp_path / "state"
    for listen in ("nonsense", "nonsense.invalid:8765", "[::zz]:1"):
        result = run_cli("serve", "--listen", listen, "--state-dir", str(state), env=cli_env(tmp_path), timeout=60)
        assert result.returncode == 4, result.stderr
        assert "cannot listen on" in result.stderr
        assert "token" not in result.stderr
        assert len(result.stderr.strip().splitlines()) == 1, result.stderr
        assert not state.exists() or not any(state.iterdir())


def test_ctrl_c_is_interrupted_and_a_service_stop_is_success(tmp_path: Path) -> None:
    for sig, code in ((signal.SIGINT, 130), (signal.SIGTERM, 0)):
        agent = start_agent(tmp_path / sig.name)
        with agent.client() as client:
            assert client.get("/api/v1/devices").json() == []
        returned, stderr = agent.stop(sig)
        assert returned == code, stderr
        assert "Traceback" not in stderr
        assert ("interrupted" in stderr) is (sig == signal.SIGINT), stderr


def _unread(fd: int) -> int:
    return int.from_bytes(fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0"), sys.byteorder)


def test_a_verbose_agent_with_an_unread_stderr_keeps_serving(tmp_path: Path) -> None:
    """-vv logs every byte on the demo machines' wires: far more than a pipe buffer holds, and nobody reads it."""
    agent = start_agent(tmp_path / "state", "--demo", "--speed", "30", "-vv")
    try:
        assert agent.process.stderr is not None
        fd = agent.process.stderr.fileno()
        capacity = fcntl.fcntl(fd, fcntl.F_GETPIPE_SZ)
        with agent.client() as client:
            wait_for(lambda: _unread(fd) > capacity - 4096, "the agent's stderr pipe to fill", timeout=60.0, every=0.5)
            for _ in range(10):  # its log has nowhere to go now: the agent must answer all the same
                assert client.get("/api/v1/devices").status_code == 200
                time.sleep(0.2)
    finally:
        agent.stop()


def test_an_agent_with_no_machines_on_every_address_says_what_to_do_and_where_to_open_it(tmp_path: Path) -> None:
    agent = start_agent(tmp_path / "state", "--listen", "0.0.0.0:0")
    port = agent.url.rstrip("/").rsplit(":", 1)[1]
    assert agent.url.startswith("http://0.0.0.0:")
    with httpx.Client(base_url=f"http://127.0.0.1:{port}") as client:  # serving (this needs its token: 401)
        assert client.get("/api/v1/devices").status_code == 401
    code, stderr = agent.stop()
    assert code == 0, stderr
    assert "no machines to watch: add one with `fabwire devices add NAME ADDRESS --kind KIND`" in stderr
    assert f"open it at http://127.0.0.1:{port}/" in stderr  # 0.0.0.0 is no address a browser opens


def test_an_agent_with_machines_on_loopback_says_neither(tmp_path: Path) -> None:
    agent = start_agent(tmp_path / "state", "--demo", "--speed", "30")
    with agent.client() as client:
        assert client.get("/api/v1/devices").status_code == 200
    code, stderr = agent.stop()
    assert code == 0, stderr
    assert "no machines to watch" not in stderr
    assert "open it at" not in stderr


def test_a_printer_that_never_answers_gets_each_connection_closed_before_the_next(tmp_path: Path) -> None:
    """A machine that accepts TCP and says nothing: every attempt's link is shut when its handshake fails, before
    the agent tries again (never left open for the garbage collector, with its reader task pending)."""
    server = socket.create_server(("127.0.0.1", 0))
    accepted: list[socket.socket] = []
    closed: list[threading.Event] = []
    open_when_next: list[bool] = []

    def read_until_closed(conn: socket.socket, gone: threading.Event) -> None:
        with contextlib.suppress(OSError):
            while conn.recv(4096):
                pass
        gone.set()

    def accept() -> None:
        with contextlib.suppress(OSError):
            while True:
                conn, _ = server.accept()
                if closed:
                    open_when_next.append(not closed[-1].wait(5.0))
                accepted.append(conn)
                closed.append(threading.Event())
                threading.Thread(target=read_until_closed, args=(conn, closed[-1]), daemon=True).start()

    threading.Thread(target=accept, daemon=True).start()
    port = server.getsockname()[1]
    agent = start_agent(tmp_path / "state", "--device", f"mute:xyz=127.0.0.1:{port}")
    try:
        wait_for(lambda: len(open_when_next) >= 2, "three connection attempts", timeout=90.0)
    finally:
        code, stderr = agent.stop()
        server.close()
        for conn in accepted:
            conn.close()
    assert open_when_next[:2] == [False, False]
    assert "Task was destroyed" not in stderr
    assert code == 0, stderr


TWICE = [  # (what is given twice, the devices file, the --device options, what the one line says)
    ("a name, twice on the command line", "", ["a:xyz=127.0.0.1:19593", "a:xyz=127.0.0.1:19594"],
     "a device named 'a' is given twice"),
    ("a name, in the file and on the command line", '[devices.office]\nurl = "127.0.0.1:19595"\nkind = "xyz"\n',
     ["office:xyz=127.0.0.1:19596"], "a device named 'office' is given twice"),
    ("a machine, written two ways", "", ["a:xyz=127.0.0.1:19593", "b:xyz=tcp://127.0.0.1:19593"],
     "is given twice, as 'a' and 'b': one machine is monitored once"),
    ("a machine, in the file and unnamed on the command line", '[devices.office]\nurl = "127.0.0.1:19595"\n'
     'kind = "xyz"\n', ["xyz=127.0.0.1:19595"], "is given twice, as 'office' and 'xyz-1'"),
]


@pytest.mark.parametrize(("what", "file", "options", "said"), TWICE, ids=[row[0] for row in TWICE])
def test_a_name_or_machine_given_twice_is_refused_before_serving(tmp_path: Path, what: str, file: str,
                                                                 options: list[str], said: str) -> None:
    config = tmp_path / "devices.toml"
    config.write_text(file)
    args = ["serve", "--listen", "127.0.0.1:0", "--state-dir", str(tmp_path / "state"), "--config", str(config)]
    for option in options:
        args += ["--device", option]
    done = run_cli(*args, env=cli_env(tmp_path))
    assert done.returncode == 4, done.stderr
    assert done.stderr.startswith("fabwire: error: ")
    assert said in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "state").exists()
