"""On a terminal, an MMU error that needs a person is offered like the printer's dialog: Retry / Stop."""

from __future__ import annotations

import os
import pty
import select
import subprocess
import sys
import time

from clitools import cli_env


class Terminal:
    """`fabwire ARGS` with stdin/stdout/stderr on a real pseudo-terminal."""

    def __init__(self, *args: str) -> None:
        self.master, slave = pty.openpty()
        self.process = subprocess.Popen([sys.executable, "-m", "fabwire", *args], stdin=slave, stdout=slave,
                                        stderr=slave, env=cli_env(), close_fds=True)
        os.close(slave)
        self.seen = b""

    def expect(self, text: str, limit: float = 60.0, times: int = 1) -> str:
        """Wait until `text` has appeared `times` times in all output so far."""
        end = time.monotonic() + limit
        while self.seen.count(text.encode()) < times:
            if time.monotonic() > end:
                raise AssertionError(f"never saw {text!r}: {self.seen.decode(errors='replace')[-800:]}")
            ready, _, _ = select.select([self.master], [], [], 0.5)
            if ready:
                try:
                    self.seen += os.read(self.master, 4096)
                except OSError:  # the child closed the terminal
                    break
        return self.seen.decode(errors="replace")

    def send(self, line: str) -> None:
        os.write(self.master, line.encode() + b"\r")

    def close(self) -> int:
        code = self.process.wait(timeout=60)
        os.close(self.master)
        return code


def test_an_error_is_offered_with_the_dialogs_choices_until_it_is_solved() -> None:
    term = Terminal("mmu", "-d", "sim://mmu?speed=50&fault=finda-didnt-trigger:5", "tool-change", "1")
    try:
        term.expect("Retry / Stop")  # after the host's three automatic retries
        assert "04101 FINDA DIDN'T TRIGGER (0x8001) during T1" in term.seen.decode(errors="replace")
        term.send("retry")  # the fifth check fails too: asked again
        term.expect("Retry / Stop", times=2)
        term.send("retry")  # the cause is gone now
        term.expect("T1 finished")
        assert term.seen.count(b"Retry / Stop") == 2
        for block in term.seen.split(b"Retry / Stop")[:-1]:  # the error stands once above each prompt
            lines = [line.strip() for line in block.splitlines()]
            assert lines.count(lines[-1]) == 1, block.decode(errors="replace")[-600:]
    finally:
        code = term.close()
    assert code == 0


def test_stop_leaves_the_error_and_fails() -> None:
    term = Terminal("mmu", "-d", "sim://mmu?speed=50&fault=tmc-short-selector", "tool-change", "1")
    try:
        term.expect("Stop")
        assert "04314 TMC DRIVER SHORTED (0x9080)" in term.seen.decode(errors="replace")
        assert b"Retry" not in term.seen.split(b"04314")[-1]  # a driver error offers no Retry
        term.send("stop")
        shown = term.expect("stopped: T1 stays in 04314")
    finally:
        code = term.close()
    assert code == 7
    after = shown.split("stopped: T1 stays in")[-1]
    assert "error:" not in after  # a stop the person chose is not reported as an error
    assert "answer it later with `fabwire mmu -d 'sim://mmu?speed=50&fault=tmc-short-selector' reset --yes`" in after
