"""Found on the network: `fabwire serve` announces each printer over mDNS the way OctoPrint and Moonraker do,
on LAN addresses only. The LAN is a pair of virtual Ethernet interfaces inside a network namespace of the test's
own (`ip netns`), so nothing leaves this computer; a browser on the other end lists what is announced."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from clitools import cli_env

from .agenttools import ANNOUNCEMENT

BROWSER = Path(__file__).with_name("mdns_browse.py")
AGENT_ADDRESS, BROWSER_ADDRESS = "10.77.0.1", "10.77.0.2"
TYPES = ("_octoprint._tcp.local.", "_moonraker._tcp.local.", "_http._tcp.local.")


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


@pytest.fixture
def lan() -> Iterator[str]:
    """A namespace with a veth pair: 10.77.0.1 for the agent, 10.77.0.2 for the browser."""
    name = f"fabwire-mdns-{os.getpid()}"
    ip("netns", "add", name)
    try:
        ip("-n", name, "link", "add", "agent0", "type", "veth", "peer", "name", "browser0")
        ip("-n", name, "addr", "add", f"{AGENT_ADDRESS}/24", "dev", "agent0")
        ip("-n", name, "addr", "add", f"{BROWSER_ADDRESS}/24", "dev", "browser0")
        for link in ("lo", "agent0", "browser0"):
            ip("-n", name, "link", "set", link, "up")
        yield name
    finally:
        subprocess.run(["ip", "netns", "del", name], check=False)


def serve_in(namespace: str, listen: str, state: Path) -> subprocess.Popen[str]:
    process = subprocess.Popen(["ip", "netns", "exec", namespace, sys.executable, "-m", "fabwire", "serve", "--demo",
                                "--listen", listen, "--state-dir", str(state)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=cli_env(state))
    assert process.stdout is not None
    for line in process.stdout:
        if ANNOUNCEMENT in line:
            return process
    raise AssertionError(f"the agent did not start: {process.communicate()[1]}")


def browse(namespace: str, seconds: float = 4) -> list[dict[str, Any]]:
    out = subprocess.run(["ip", "netns", "exec", namespace, sys.executable, str(BROWSER), BROWSER_ADDRESS,
                          str(seconds), *TYPES], check=True, capture_output=True, text=True, timeout=60)
    return [json.loads(line) for line in out.stdout.splitlines() if line.strip()]


def browse_until(namespace: str, count: int) -> list[dict[str, Any]]:
    """Browse until `count` services answer, at most five times (announcements take a moment to settle)."""
    found: list[dict[str, Any]] = []
    for _ in range(5):
        found = browse(namespace)
        if len(found) >= count:
            break
    return found


def test_printers_are_announced_on_the_lan_and_never_on_loopback(lan: str, tmp_path: Path) -> None:
    """Two agents in the namespace: one on loopback (announces nothing) and one on the LAN address, which
    announces each machine that takes files (the da Vinci, the Line-us; not the MMU) as `_octoprint._tcp` (TXT
    path, api, version), `_moonraker._tcp` (route_prefix) and `_http._tcp`, at its LAN address and port; the
    default printer's OctoPrint path is the root."""
    local = serve_in(lan, "127.0.0.1:18080", tmp_path / "local")
    remote = serve_in(lan, f"{AGENT_ADDRESS}:18081", tmp_path / "remote")
    try:
        found = browse_until(lan, 6)
        # a machine added while the agent runs is announced once it is online
        token = (tmp_path / "remote" / "access-token").read_text().strip()
        add = ("import httpx, sys; r = httpx.post(sys.argv[1], json={'name': 'desk', 'kind': 'xyz', "
               "'address': 'sim://'}, headers={'Authorization': 'Bearer ' + sys.argv[2]}, timeout=60); "
               "print(r.status_code)")
        added = subprocess.run(["ip", "netns", "exec", lan, sys.executable, "-c", add,
                                f"http://{AGENT_ADDRESS}:18081/api/v1/devices", token],
                               capture_output=True, text=True, timeout=90, check=True)
        assert added.stdout.strip() == "201", added.stderr
        later = browse_until(lan, 9)
    finally:
        for process in (local, remote):
            process.terminate()
            process.communicate(timeout=30)
    assert all(entry["addresses"] == [AGENT_ADDRESS] and entry["port"] == 18081 for entry in found), found
    by_type = {t: sorted(e["name"].split(" on ")[0] for e in found if e["type"] == t) for t in TYPES}
    assert by_type == {t: ["line-us", "printer"] for t in TYPES}
    octoprint = {e["name"].split(" on ")[0]: e["txt"] for e in found if e["type"] == TYPES[0]}
    assert octoprint["printer"]["path"] == "/"
    assert octoprint["line-us"]["path"] == "/printers/line-us/"
    assert {"api", "version", "path"} <= set(octoprint["printer"])
    moonraker = {e["name"].split(" on ")[0]: e["txt"] for e in found if e["type"] == TYPES[1]}
    assert moonraker["line-us"]["route_prefix"] == "printers/line-us"
    desk = [e for e in later if e["name"].startswith("desk on ")]
    assert sorted(e["type"] for e in desk) == sorted(TYPES)
    assert next(e for e in desk if e["type"] == TYPES[0])["txt"]["path"] == "/printers/desk/"
