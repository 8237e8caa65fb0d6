"""`fabwire serve` as a real process under pressure: racing uploads, a disk that refuses, half-sent and abandoned
requests, private state, and option values that cannot work."""

from __future__ import annotations

import contextlib
import json
import os
import resource
import socket
import stat
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from clitools import cli_env, run_cli

from .agenttools import RunningAgent, start_agent, wait_for

PRINTER = "p:xyz=sim://xyz?speed=30"
GCODE = b"G28\n" + b"".join(b"G1 X%d Y%d E%d F600\n" % (i % 100, (i * 7) % 100, i) for i in range(60_000))
SMALL = GCODE[:GCODE.rfind(b"\n", 0, 20_000) + 1]
"""A small whole file: its first lines (a file cut inside a line ends in a word without its value, refused)."""
BEGINNING = GCODE[:GCODE.rfind(b"\n", 0, 100) + 1]


def printer_online(agent: RunningAgent) -> str:
    with agent.client() as client:
        return str(wait_for(lambda: next((d["id"] for d in client.get("/api/v1/devices").json()
                                          if d["state"]["online"]), None), "the printer online"))


def raw_request(agent: RunningAgent, head: bytes, body: bytes = b"") -> socket.socket:
    host, port = agent.url.removeprefix("http://").rstrip("/").rsplit(":", 1)
    sock = socket.create_connection((host, int(port)), timeout=60)
    sock.sendall(head + body)
    return sock


def ended_by_server(sock: socket.socket) -> bool:
    """Whether the server closes the connection (end of stream, or a reset for bytes it left unread) while this
    side keeps quiet."""
    sock.settimeout(0.5)
    for _ in range(120):  # (a bound against a hang, not a timing check)
        try:
            if not sock.recv(65536):
                return True
        except TimeoutError:
            continue
        except ConnectionResetError:
            return True
    return False


@pytest.fixture
def agent(tmp_path: Path) -> Iterator[RunningAgent]:
    running = start_agent(tmp_path / "state", "--device", PRINTER)
    yield running
    running.stop()


def test_of_simultaneous_http_uploads_one_is_taken_the_rest_told_why(agent: RunningAgent) -> None:
    device = printer_online(agent)
    results: list[tuple[int, dict[str, str]]] = []
    start = threading.Barrier(8)

    def upload(n: int) -> None:
        with agent.client() as client:
            start.wait()
            response = client.post(f"/api/v1/devices/{device}/jobs", params={"filename": f"p{n}.gcode"},
                                   content=GCODE, headers={"content-type": "application/octet-stream"})
            results.append((response.status_code, response.json()))

    threads = [threading.Thread(target=upload, args=(n,)) for n in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert sorted(code for code, _ in results) == [201] + [409] * 7
    [job] = [body for code, body in results if code == 201]
    for code, body in results:
        if code == 409:
            assert body["error"] == "DeviceBusy"
            assert "busy with job" in body["message"] or "taking another job" in body["message"]
    with agent.client() as client:
        assert [j["id"] for j in client.get("/api/v1/jobs").json()] == [job["id"]]
        assert client.get(f"/api/v1/devices/{device}/state").json()["job"]["id"] == job["id"]
    assert sorted(os.listdir(agent.state_dir / "uploads")) == [job["stored"]]


@contextlib.contextmanager
def file_size_limit(limit: int) -> Iterator[None]:
    """Processes started inside inherit a limit on the size of any file they write (RLIMIT_FSIZE: writes past
    it fail with EFBIG, Python ignores SIGXFSZ): a disk that refuses more bytes, without root."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))


def test_a_disk_that_refuses_the_upload_is_507_and_keeps_nothing(tmp_path: Path) -> None:
    with file_size_limit(1024 * 1024):
        agent = start_agent(tmp_path / "state", "--device", PRINTER)
    try:
        device = printer_online(agent)
        with agent.client() as client:
            response = client.post(f"/api/v1/devices/{device}/jobs", params={"filename": "big.gcode"},
                                   content=GCODE, headers={"content-type": "application/octet-stream"})
            assert response.status_code == 507, response.text
            assert response.json()["error"] == "DiskFull"
            assert "no space left on the agent's disk" in response.json()["message"]
            assert "internal error" not in response.text
            assert os.listdir(agent.state_dir / "uploads") == []
            assert client.get("/api/v1/jobs").json() == []
            small = client.post(f"/api/v1/devices/{device}/jobs", params={"filename": "s.gcode"},
                                content=SMALL, headers={"content-type": "application/octet-stream"})
            assert small.status_code == 201  # the machine was released
    finally:
        _, stderr = agent.stop()
    assert "Traceback" not in stderr


def test_an_abandoned_upload_is_one_log_line_and_leaves_nothing(agent: RunningAgent) -> None:
    device = printer_online(agent)
    head = (f"POST /api/v1/devices/{device}/jobs?filename=a.gcode HTTP/1.1\r\nHost: 127.0.0.1\r\n"
            f"Content-Length: {len(GCODE) * 10}\r\n\r\n").encode()
    sock = raw_request(agent, head, GCODE)
    with agent.client() as client:  # the upload holds the machine while it arrives …
        busy = client.post(f"/api/v1/devices/{device}/jobs", params={"filename": "b.gcode"}, content=BEGINNING)
        assert busy.status_code == 409
        sock.close()  # … and lets it go when its client does
        wait_for(lambda: client.post(f"/api/v1/devices/{device}/jobs", params={"filename": "b.gcode"},
                                     content=SMALL).status_code == 201, "the printer free again")
    _, stderr = agent.stop()
    lines = [line for line in stderr.splitlines() if "went away" in line]
    assert len(lines) == 1, stderr
    assert f"/api/v1/devices/{device}/jobs" in lines[0]
    assert "Traceback" not in stderr
    assert len(os.listdir(agent.state_dir / "uploads")) == 1  # the second upload only


def test_half_sent_requests_are_closed_and_the_api_still_answers(agent: RunningAgent) -> None:
    heads = [b"GET /api/v1/devices HTTP/1.1\r\nHost: 127.0.0.1\r\n",  # never finished
             b"POST /api/v1/devices/x/actions/home HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 100000\r\n"
             b"Content-Type: application/json\r\n\r\n{",  # a body over the limit that never comes
             b"GET /api/v1/devices HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: keep-alive\r\n\r\n"]  # then idle
    held = [raw_request(agent, heads[n % len(heads)]) for n in range(60)]
    with agent.client() as client:
        assert client.get("/api/v1/devices").status_code == 200
    for sock in held:  # the agent closes each: the client reads to the end of the stream
        received = b""
        while chunk := sock.recv(65536):
            received += chunk
        sock.close()
        status = received[9:12]
        assert not received or status in (b"200", b"413"), received[:200]  # answered, or closed unanswered
    _, stderr = agent.stop()
    assert "Traceback" not in stderr


def test_the_state_folder_and_its_files_are_the_owners_alone(tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        agent = start_agent(tmp_path / "new" / "state", "--device", PRINTER, "--token")
    finally:
        os.umask(old)
    try:
        agent.token = (agent.state_dir / "access-token").read_text().strip()
        device = printer_online(agent)
        with agent.client() as client:
            assert client.post(f"/api/v1/devices/{device}/jobs", params={"filename": "s.gcode"},
                               content=SMALL).status_code == 201
    finally:
        agent.stop()
    modes = {str(p.relative_to(agent.state_dir)): stat.S_IMODE(p.stat().st_mode)
             for p in agent.state_dir.rglob("*")}
    assert stat.S_IMODE(agent.state_dir.stat().st_mode) == 0o700
    assert modes.pop("uploads") == 0o700
    assert {"access-token", "history.sqlite3"} <= set(modes)
    assert all(mode == 0o600 for mode in modes.values()), modes


BAD_OPTIONS = [
    (("--max-upload", "1e308"), "--max-upload"),   # a number of bytes beyond any disk (overflowed before)
    (("--max-upload", "nan"), "--max-upload"),
    (("--max-upload", "0"), "--max-upload"),
    (("--retention", "1e308"), "--retention"),     # hours past the end of time arithmetic
    (("--speed", "1e300", "--demo"), "--speed"),
    (("--listen", "127.0.0.1:99999"), "--listen"),
    (("--listen", "127.0.0.1:x"), "--listen"),
    (("--device", "printer"), "--device"),
    (("--device", "toaster=127.0.0.1"), "--device"),
    (("--allow-host", "evil example"), "--allow-host"),
    (("--allow-host", "http://printers.lan/"), "--allow-host"),
    (("--allow-host", "printers.lan:8765"), "--allow-host"),  # a name, not an address with a port
    (("--allow-host", ""), "--allow-host"),
    (("--mqtt", "http://broker"), "--mqtt"),
    (("--mqtt", "mqtt://broker:99999"), "--mqtt"),
    (("--mqtt", "mqtt://"), "--mqtt"),
]


@pytest.mark.parametrize(("args", "option"), BAD_OPTIONS)
def test_option_values_that_cannot_work_are_usage_errors(tmp_path: Path, args: tuple[str, ...],
                                                         option: str) -> None:
    result = run_cli("serve", "--state-dir", str(tmp_path / "state"), "--listen", "127.0.0.1:0", *args,
                     env=cli_env(tmp_path), timeout=30)
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert option in result.stderr
    assert "Traceback" not in result.stderr
    assert "listening" not in result.stdout
    assert not (tmp_path / "state").exists()  # nothing started, nothing made


def test_the_events_socket_refuses_a_foreign_page_on_a_real_server(agent: RunningAgent) -> None:
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    printer_online(agent)
    with pytest.raises(InvalidStatus) as refused, connect(agent.ws_url, origin="http://evil.example"):  # type: ignore[arg-type]
        pass
    assert refused.value.response.status_code == 403
    assert json.loads(refused.value.response.body or b"{}")["error"] == "CrossOrigin"
    with connect(agent.ws_url, origin=agent.url.rstrip("/")) as ws:  # type: ignore[arg-type]
        assert json.loads(ws.recv(timeout=30))["type"] == "state"


TRICKLED = {
    "native": ("/api/v1/devices/{device}/jobs?filename=slow.gcode", None),
    "octoprint": ("/api/files/local", [("print", "true"), ("path", "")]),  # PrusaSlicer's OctoPrint upload
    "moonraker": ("/server/files/upload", [("root", "gcodes"), ("print", "true")]),  # SuperSlicer's Moonraker upload
}
"""The uploads that claim the machine before their file arrives: the API's own, and the doors' with print first."""


BURSTS = {
    "small": lambda body: body.index(b"G28\n") + 2000,
    "most-of-the-file": lambda body: len(body) - 10_000,  # a fast burst buys no time for the trickle after it
}
"""How much of the body the client sends at once before it trickles (the end of its first piece)."""


@pytest.mark.parametrize("burst", BURSTS, ids=list(BURSTS))
@pytest.mark.parametrize("door", TRICKLED, ids=list(TRICKLED))
def test_a_trickled_upload_is_408_and_the_machine_is_free_after(tmp_path: Path, door: str, burst: str) -> None:
    """A client that sends a first piece (a little, or nearly all of the file at once) and then 2 bytes now and
    then, with a large Content-Length: past the grace (shortened here) a window brings far under BODY_MIN_RATE, so
    the request is 408 and the machine is taken by the owner's next upload."""
    from .doortools import multipart

    agent = start_agent(tmp_path / "state", "--device", PRINTER, constants={"fabwire.agent.boundary.BODY_GRACE_S": 2.0})
    try:
        device = printer_online(agent)
        path, fields = TRICKLED[door]
        if fields is None:
            body, ctype = GCODE, "application/octet-stream"
        else:
            body, ctype = multipart(fields, "slow.gcode", GCODE)
        first = body[:BURSTS[burst](body)]
        head = (f"POST {path.format(device=device)} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: {ctype}\r\n"
                f"Content-Length: {len(body)}\r\n\r\n").encode()
        sock = raw_request(agent, head, first)
        with agent.client() as client:
            busy = client.post(f"/api/v1/devices/{device}/jobs", params={"filename": "b.gcode"}, content=BEGINNING)
            assert busy.status_code == 409, busy.text  # the trickle holds the machine …
            answer = b""
            for _ in range(240):  # (a bound against a hang, not a timing check)
                sock.settimeout(0.5)
                try:
                    answer += sock.recv(65536)
                except TimeoutError:
                    with contextlib.suppress(OSError):
                        sock.sendall(b";\n")
                    continue
                if b"\r\n\r\n" in answer and answer.endswith(b"}"):
                    break
            closed = ended_by_server(sock)
            sock.close()
            status, _, rest = answer.partition(b"\r\n\r\n")
            assert status.startswith(b"HTTP/1.1 408"), answer
            # the rest of the body may still be on its way: the answer ends the connection (RFC 9110 §15.5.9)
            assert b"\r\nconnection: close\r\n" in status.lower() + b"\r\n", status
            assert closed
            assert "arrives too slowly" in json.dumps(json.loads(rest)), rest  # (each door's own error shape)
            mine = client.post(f"/api/v1/devices/{device}/jobs", params={"filename": "mine.gcode"},
                               content=SMALL, headers={"content-type": "application/octet-stream"})
            assert mine.status_code == 201, mine.text  # … until it is refused, then the owner's upload is taken
            assert [j["id"] for j in client.get("/api/v1/jobs").json()] == [mine.json()["id"]]
    finally:
        _, stderr = agent.stop()
    assert "Traceback" not in stderr
