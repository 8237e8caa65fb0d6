"""The owner's hands from the command line: `fabwire mmu hands` against `fabwire sim mmu --control`, with the MMU
itself served on TCP and on a pty."""

from __future__ import annotations

import json
import selectors
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from clitools import RunningSimulator, cli_env, run_cli
from fabwire.lifeline import spawn
from fabwire.mmu.sim import MMUSimulator
from linktools import loopback_tcp

SPEED = "50"


def start(*args: str) -> tuple[RunningSimulator, str]:
    """`fabwire sim mmu ARGS --control 127.0.0.1:0`: the simulator and its control address."""
    process = spawn([sys.executable, "-m", "fabwire", "sim", "mmu", *args, "--control", "127.0.0.1:0"],
                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=cli_env())
    assert process.stdout is not None
    where: list[str] = []
    control = ""
    with selectors.DefaultSelector() as sel:
        sel.register(process.stdout, selectors.EVENT_READ)
        while not (where and control):
            if not sel.select(30):
                process.kill()
                raise RuntimeError("the simulator did not announce itself")
            line = process.stdout.readline()
            if not line:
                raise RuntimeError(f"the simulator exited: {process.stderr.read() if process.stderr else ''}")
            if " control on " in line:
                control = line.split(" control on ", 1)[1].strip()
            elif " listening on " in line:
                where.append(line.split(" listening on ", 1)[1].split(" (link")[0].strip())
    return RunningSimulator(process, where), control


@pytest.fixture
def tcp_sim() -> Iterator[tuple[str, str]]:
    sim, control = start("--listen", "127.0.0.1:0", "--speed", SPEED, "--fault", "finda-on-boot")
    try:
        yield sim.where[0], control
    finally:
        sim.stop()


def mmu(device: str, *args: str) -> subprocess.CompletedProcess[str]:
    return run_cli("mmu", "-d", device, "--speed", SPEED, *args, timeout=60)


def test_retry_fails_until_the_filament_is_pulled_out(tcp_sim: tuple[str, str]) -> None:
    device, control = tcp_sim
    assert control.startswith("tcp://127.0.0.1:")
    done = run_cli("mmu", "hands", control, "causes")
    assert (done.returncode, done.stdout.strip()) == (0, "causes present: finda-on-boot")
    done = mmu(device, "button", "retry")
    assert done.returncode == 7
    assert "04506 UNLOAD MANUALLY" in done.stderr  # the filament is still under FINDA
    done = run_cli("--json", "mmu", "hands", control, "remove", "finda-on-boot")
    assert json.loads(done.stdout) == {"removed": ["finda-on-boot"], "causes": {}}
    done = mmu(device, "button", "retry")
    assert (done.returncode, done.stdout.strip()) == (0, "retry: X0 finished"), done.stderr
    done = run_cli("mmu", "hands", control, "remove", "finda-on-boot")
    assert (done.returncode, done.stderr.strip()) == (
        4, "fabwire: error: nothing to remove: finda-on-boot is not present (present: none)")


def test_a_stuck_filament_survives_the_hosts_retries(tcp_sim: tuple[str, str]) -> None:
    device, control = tcp_sim
    run_cli("mmu", "hands", control, "remove")
    assert mmu(device, "button", "retry").returncode == 0
    assert mmu(device, "tool-change", "1").returncode == 0
    assert run_cli("mmu", "hands", control, "inject", "finda-stuck").returncode == 0
    done = mmu(device, "unload")
    assert done.returncode == 7
    assert done.stderr.count("04102") >= 1
    assert "retrying automatically" in done.stderr  # the host's three Retries did not heal it
    assert run_cli("mmu", "hands", control, "remove", "finda-stuck").returncode == 0
    done = mmu(device, "button", "retry")
    assert (done.returncode, done.stdout.strip()) == (0, "retry: U0 finished"), done.stderr


def test_buttons_and_power_over_a_pty(tmp_path: Path) -> None:
    link = tmp_path / "ttyMMU"
    sim, control = start("--pty", "--link", str(link), "--speed", SPEED, "--fault", "tmc-overheat-idler")
    try:
        for _ in range(100):  # the boot homing gets to the idler first (a loaded machine may take a while)
            done = mmu(str(link), "status")
            if "04222" in done.stdout:
                break
        assert "04222" in done.stdout, done.stderr  # the idler driver overheated while homing at boot
        for button in ("left", "middle", "right"):
            assert run_cli("mmu", "hands", control, "press", button).returncode == 0
        done = mmu(str(link), "status")
        assert "04222" in done.stdout  # no button clears a driver error
        assert run_cli("mmu", "hands", control, "remove", "tmc-overheat-idler").returncode == 0
        done = run_cli("mmu", "hands", control, "power-cycle")
        assert (done.returncode, done.stdout.strip()) == (0, "MMU power-cycled; causes present: none")
        done = mmu(str(link), "tool-change", "t3")
        assert (done.returncode, done.stdout.strip()) == (0, "T3 finished"), done.stderr
    finally:
        sim.stop()


@pytest.mark.parametrize(("args", "message"), [
    (("press", "up"), "left, middle or right"),
    (("remove", "gremlins"), "unknown MMU fault"),
    (("kick",), "'kick' is not one of"),
])
def test_bad_hands_are_one_line(tcp_sim: tuple[str, str], args: tuple[str, ...], message: str) -> None:
    _, control = tcp_sim
    done = run_cli("mmu", "hands", control, *args)
    assert done.returncode != 0
    assert message in done.stderr
    assert "Traceback" not in done.stderr


def test_no_control_plane_there() -> None:
    done = run_cli("mmu", "hands", "127.0.0.1:1", "causes")
    assert done.returncode != 0
    assert "no simulator control plane at 127.0.0.1:1" in done.stderr


def test_the_mmu_port_is_not_the_control_plane(tcp_sim: tuple[str, str]) -> None:
    device, _ = tcp_sim
    done = run_cli("mmu", "hands", device, "causes", "--timeout", "1")  # the MMU ignores a line it cannot decode
    assert done.returncode != 0
    assert done.stderr.strip().endswith("did not answer within 1 s")


@pytest.mark.parametrize(("sent", "answer"), [
    (b"causes\n", {"ok": True, "causes": {"finda-stuck": -1}}),
    (b"\xff\xfe remove\n", {"ok": False, "error": "unknown action '\ufffd\ufffd'; choose one of remove, press, "
                                                  "power-cycle, inject, causes"}),
    (b"remove gremlins\n", None),
    (b"x" * 300, {"ok": False, "error": "line too long"}),
])
async def test_the_control_plane_answers_every_line_in_one_json_line(sent: bytes, answer: object) -> None:
    sim = MMUSimulator(faults=["finda-stuck"])
    async with loopback_tcp(sim.serve_hands) as link:
        await link.write(sent)
        reply = json.loads(await link.read(4096))
    if answer is None:
        assert reply["ok"] is False
        assert reply["error"].startswith("unknown MMU fault 'gremlins'")
    else:
        assert reply == answer
    assert sim.causes() == {"finda-stuck": -1}  # nothing a bad line says changes the machine
