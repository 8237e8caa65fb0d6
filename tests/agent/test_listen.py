"""Where `fabwire serve` listens and what it prints to open, one row of `OPEN_AT` per test, with real sockets:
every address printed answers over HTTP, and the IPv6 wildcard takes IPv4 clients too (dual-stack)."""

from __future__ import annotations

import contextlib
import errno
import re
import socket
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from clitools import cli_env, run_cli
from fabwire.agent.command import OPEN_AT, open_at
from fabwire.transport.tcp import BIND_FAILURES

from .agenttools import start_agent

LISTEN = {
    "0.0.0.0": "0.0.0.0:0",
    "::, dual-stack": "[::]:0",
    "one address": "127.0.0.1:0",
}


def _printed(state_dir: Path, listen: str) -> tuple[list[str], str]:
    """The URLs `serve --listen LISTEN` prints to open (the announcement, or for a wildcard the "open it at"
    line), each checked to answer with the token it printed; and its stderr."""
    agent = start_agent(state_dir, "--listen", listen)
    try:
        urls = [agent.url]
        token = None
        wildcard = re.match(r"http://(0\.0\.0\.0|\[::\]):", agent.url) is not None
        while wildcard and agent.process.stderr is not None:  # the token comes before, the addresses after
            line = agent.process.stderr.readline()
            agent.stderr_lines.append(line)
            if (found := re.search(r"access token \(shown once; kept in (.*)\): (\S+)", line)) is not None:
                token = found.group(2)
                assert Path(found.group(1)).read_text().strip() == token  # the file it names holds it
            if not line or line.startswith("fabwire: open it at "):
                urls = line.removeprefix("fabwire: open it at ").strip().split(", ")
                break
        headers = {"X-Api-Key": token} if token else {}
        for url in urls:
            response = httpx.get(url + "api/v1/agent", headers=headers, timeout=10)
            assert response.status_code == 200, (url, response.text)
        return urls, "".join(agent.stderr_lines)
    finally:
        code, stderr = agent.stop()
        assert code == 0, stderr


@pytest.mark.parametrize(("listen", "printed", "source"), [row for row in OPEN_AT if row[0] in LISTEN],
                         ids=[row[0] for row in OPEN_AT if row[0] in LISTEN])
def test_every_address_printed_answers(tmp_path: Path, listen: str, printed: str, source: str) -> None:
    opened, _ = _printed(tmp_path / "state", LISTEN[listen])
    port = opened[0].rstrip("/").rsplit(":", 1)[1]
    if listen == "one address":
        assert opened == [f"http://127.0.0.1:{port}/"]
    elif listen == "0.0.0.0":
        assert opened[0] == f"http://127.0.0.1:{port}/"
        assert not [u for u in opened if u.startswith("http://[")]
    else:
        assert opened[:2] == [f"http://127.0.0.1:{port}/", f"http://[::1]:{port}/"]
        assert not [u for u in opened if "[fe80:" in u]  # link-local: no browser opens it


def test_the_ipv6_wildcard_is_dual_stack() -> None:
    from fabwire.agent.command import _bind

    sock = _bind("::", 0)
    try:
        assert sock.getsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY) == 0
        port = sock.getsockname()[1]
        for host in ("127.0.0.1", "::1"):
            with socket.create_connection((host, port), timeout=5):
                pass
    finally:
        sock.close()


def test_an_ipv6_only_wildcard_prints_only_ipv6_addresses() -> None:
    """The row a system without dual-stack sockets takes: what is printed is what that socket accepts."""
    sock = socket.socket(socket.AF_INET6)
    try:
        sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
        sock.bind(("::", 0))
        sock.listen()
        urls = open_at(sock)
        assert urls[0] == f"http://[::1]:{sock.getsockname()[1]}/"
        assert all(u.startswith("http://[") for u in urls), urls
        for url in urls:
            host = url.removeprefix("http://[").partition("]")[0]
            with socket.create_connection((host, sock.getsockname()[1]), timeout=5):
                pass
    finally:
        sock.close()


def test_one_ipv6_address_is_announced_bracketed(tmp_path: Path) -> None:
    opened, stderr = _printed(tmp_path / "state", "[::1]:0")
    assert len(opened) == 1, opened
    assert opened[0].startswith("http://[::1]:"), opened
    assert "open it at" not in stderr


@contextlib.contextmanager
def _taken() -> Iterator[str]:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        yield f"127.0.0.1:{taken.getsockname()[1]}"


@contextlib.contextmanager
def _given(listen: str) -> Iterator[str]:
    yield listen


BIND_CASES = {
    errno.EADDRINUSE: (_taken, 8),
    errno.EADDRNOTAVAIL: (lambda: _given("192.0.2.254:0"), 8),  # TEST-NET-1: never this computer's own
    socket.EAI_NONAME: (lambda: _given("nonsense.invalid:8765"), 4),
}
"""The rows of BIND_FAILURES a test can bring about as root or not (EACCES needs a user, EAFNOSUPPORT a
computer without IPv6): how, and the exit code."""


@pytest.mark.parametrize("code", list(BIND_CASES), ids=[str(c) for c in BIND_CASES])
def test_a_listener_that_cannot_bind_is_the_same_error_for_serve_and_sim(tmp_path: Path, code: int) -> None:
    """One wording and one exit code for every listener (a port in use is 8, a link failure: a service manager
    tries again)."""
    words, _ = BIND_FAILURES[code]
    make, exit_code = BIND_CASES[code]
    with make() as listen:
        told = [run_cli(*command, "--listen", listen, env=cli_env(tmp_path), timeout=60)
                for command in (("serve", "--state-dir", str(tmp_path / "s")), ("sim", "xyz"))]
    for result in told:
        assert result.returncode == exit_code, result.stderr
        assert result.stderr.strip().splitlines()[-1] == f"fabwire: error: cannot listen on {listen}: {words}", \
            result.stderr
