"""A server's log never stalls it: a stderr nobody reads costs dropped lines, not a frozen simulator."""

from __future__ import annotations

import logging
import os
import socket
import subprocess
import sys
import threading
import time

import pytest

from clitools import cli_env, start_simulator
from fabwire.logsink import DroppingQueueHandler, non_blocking_handler


def test_logging_to_a_pipe_nobody_reads_returns_at_once_and_counts_what_it_drops() -> None:
    read_end, write_end = os.pipe()
    stream = os.fdopen(write_end, "w", buffering=1)
    handler = non_blocking_handler(stream, logging.Formatter("%(message)s"))
    logger = logging.getLogger("fabwire.test.logsink")
    logger.addHandler(handler)
    logger.propagate = False
    done = threading.Event()

    def spam() -> None:
        for n in range(20_000):  # far more than a pipe buffer and the queue hold
            logger.warning("line %d %s", n, "x" * 100)
        done.set()

    threading.Thread(target=spam, daemon=True).start()
    try:
        assert done.wait(60), "logging blocked on a pipe nobody reads"
        assert isinstance(handler, DroppingQueueHandler)
        assert handler.dropped > 0
    finally:
        logger.removeHandler(handler)
        os.close(read_end)


def test_a_verbose_simulator_with_an_unread_stderr_keeps_serving() -> None:
    sim = start_simulator("-v", "lineus", "--speed", "1000", "--listen", "127.0.0.1:0", env=cli_env())
    try:
        host, _, port = sim.url.removeprefix("tcp://").rpartition(":")
        with socket.create_connection((host, int(port)), timeout=30) as chatty:
            chatty.settimeout(30)
            chatty.recv(1024)  # hello
            for n in range(2500):  # one logged chunk each: several times what a pipe buffer holds
                chatty.sendall(f"G01 X{1000 + n % 300} Y0\r\n".encode())
                reply = b""
                while not reply.endswith(b"\0"):
                    chunk = chatty.recv(1024)
                    assert chunk, "the simulator hung up"
                    reply += chunk
        with socket.create_connection((host, int(port)), timeout=30) as fresh:
            fresh.settimeout(30)
            assert fresh.recv(1024).startswith(b"hello")
    finally:
        sim.stop()
    assert sim.process.returncode is not None


def test_the_last_lines_are_written_before_a_short_command_exits() -> None:
    code = ("import logging, sys\n"
            "from fabwire.cli_support import configure_logging\n"
            "from fabwire.logsink import log_in_background\n"
            "configure_logging(1); log_in_background()\n"
            "logging.getLogger('fabwire.x').warning('the last word')\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=cli_env())
    assert "the last word" in done.stderr


def test_a_stderr_whose_reader_has_gone_costs_no_tracebacks(capfd: pytest.CaptureFixture[str]) -> None:
    """`fabwire sim … 2>&1 | head -1`: once head exits, log lines are dropped without a word, not each followed by
    a 'Logging error' traceback."""
    read_end, write_end = os.pipe()
    stream = os.fdopen(write_end, "w", buffering=1)
    handler = non_blocking_handler(stream, logging.Formatter("%(message)s"))
    logger = logging.getLogger("fabwire.test.logsink.gone")
    logger.addHandler(handler)
    logger.propagate = False
    try:
        os.close(read_end)  # the reader is gone
        for n in range(50):
            logger.warning("line %d", n)
        deadline = time.monotonic() + 10
        while handler.queue.qsize() and time.monotonic() < deadline:  # type: ignore[attr-defined]
            time.sleep(0.01)
        time.sleep(0.1)  # the last record is being written
    finally:
        logger.removeHandler(handler)
    assert "Logging error" not in capfd.readouterr().err
