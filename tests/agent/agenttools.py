"""Running `fabwire serve` as a real subprocess on real simulator processes, and talking to it."""

from __future__ import annotations

import selectors
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from clitools import STARTUP_TIMEOUT, cli_env

ANNOUNCEMENT = "fabwire agent listening on "
ARTIFACTS = Path(__file__).resolve().parents[1] / "artifacts"
"""Screenshots and other things a person may want to look at after a run (ignored by git)."""


@dataclass
class RunningAgent:
    process: subprocess.Popen[str]
    url: str
    state_dir: Path
    token: str | None = None
    stderr_lines: list[str] = field(default_factory=list)

    def client(self, **kwargs: Any) -> httpx.Client:
        headers = {"Authorization": f"Bearer {self.token}"} if self.token else {}
        return httpx.Client(base_url=self.url.rstrip("/"), headers=headers, timeout=30.0, **kwargs)

    @property
    def ws_url(self) -> str:
        return self.url.replace("http://", "ws://").rstrip("/") + "/api/v1/events"

    def stop(self, sig: signal.Signals = signal.SIGTERM) -> tuple[int, str]:
        if self.process.poll() is None:
            self.process.send_signal(sig)
            try:
                self.process.wait(20)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        err = self.process.stderr.read() if self.process.stderr and not self.process.stderr.closed else ""
        for stream in (self.process.stdout, self.process.stderr):
            if stream:
                stream.close()
        return self.process.returncode, "".join(self.stderr_lines) + err


def start_agent(state_dir: Path, *args: str, env: dict[str, str] | None = None,
                constants: dict[str, float] | None = None) -> RunningAgent:
    """`fabwire serve --listen 127.0.0.1:0 --state-dir STATE ARGS…`, waited for until it announces its URL.
    `constants` ({"fabwire.agent.boundary.BODY_GRACE_S": 2.0}) are set in the agent's process before it starts,
    as monkeypatch does in-process: a limit that takes half a minute is reached in seconds."""
    start = ["-m", "fabwire"]
    if constants:
        sets = "".join(f"import {name.rpartition('.')[0]}; {name} = {value!r}; " for name, value in constants.items())
        start = ["-c", f"import sys; sys.argv[0] = 'fabwire'; {sets}from fabwire.__main__ import run; run()"]
    command = [sys.executable, *start, "serve", "--state-dir", str(state_dir), *args]
    if "--listen" not in args:
        command += ["--listen", "127.0.0.1:0"]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env=env or cli_env(state_dir))
    assert process.stdout is not None
    assert process.stderr is not None
    stderr: list[str] = []
    with selectors.DefaultSelector() as sel:
        sel.register(process.stdout, selectors.EVENT_READ)
        deadline = time.monotonic() + STARTUP_TIMEOUT * 2
        while True:
            if not sel.select(max(0.0, deadline - time.monotonic())):
                process.kill()
                raise RuntimeError(f"the agent did not announce itself: {process.stderr.read()}")
            line = process.stdout.readline()
            if not line:
                process.wait(10)
                raise RuntimeError(f"the agent exited with {process.returncode}: {process.stderr.read()}")
            if ANNOUNCEMENT in line:
                return RunningAgent(process, line.split(ANNOUNCEMENT, 1)[1].strip(), state_dir, None, stderr)


def wait_for(check: Callable[[], Any], what: str, timeout: float = 60.0, every: float = 0.2) -> Any:
    """Poll `check` until it returns something truthy; fail saying `what` did not happen."""
    deadline = time.monotonic() + timeout
    last: Any = None
    while time.monotonic() < deadline:
        last = check()
        if last:
            return last
        time.sleep(every)
    raise AssertionError(f"{what} did not happen within {timeout:g} s (last seen: {last!r})")


def device_of(client: httpx.Client, kind: str) -> dict[str, Any]:
    devices = client.get("/api/v1/devices").json()
    found = [d for d in devices if d["kind"] == kind]
    assert len(found) == 1, devices
    return dict(found[0])


def summary(client: httpx.Client, device_id: str) -> dict[str, Any]:
    response = client.get(f"/api/v1/devices/{device_id}/state")
    assert response.status_code == 200, response.text
    return dict(response.json()["summary"])
