"""A status query imports only what it uses: no numpy, no rich with --json, no serial or pty support, no crypto,
and none of the printer side (its command parser, the simulator) or the print-file tools. Its value types are
msgspec structs, not dataclasses: a dataclass generates and compiles its methods at every start."""

from __future__ import annotations

import json
import subprocess
import sys

from clitools import SimulatorStarter, cli_env

HEAVY = {"numpy", "rich", "serialx", "termios", "cryptography", "svgelements", "PIL", "shapely", "zeroconf",
         "dataclasses"}
PRINTER_SIDE = {"fabwire.xyz.device", "fabwire.xyz.printer", "fabwire.xyz.sim", "fabwire.xyz.threew",
                "fabwire.xyz.gcodeinfo", "fabwire.xyz.intake"}


def imported_by(argv: list[str]) -> tuple[int, list[str]]:
    code = ("import sys\nfrom fabwire.cli import main\nrc = main(" + repr(argv) + ")\n"
            f"heavy = {{m.split('.')[0] for m in sys.modules}} & {HEAVY!r}\n"
            f"print(sorted(heavy | (set(sys.modules) & {PRINTER_SIDE!r})), file=sys.stderr)\n"
            "sys.exit(rc)\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=cli_env())
    return result.returncode, json.loads(result.stderr.strip().splitlines()[-1].replace("'", '"'))


def test_a_status_query_over_tcp_stays_lean(simulator: SimulatorStarter) -> None:
    address = simulator("xyz", "--listen", "127.0.0.1:0").url
    rc, heavy = imported_by(["xyz", "-d", address, "status", "--json"])
    assert rc == 0
    assert heavy == []
    rc, heavy = imported_by(["xyz", "-d", address, "status"])
    assert rc == 0
    assert heavy == ["dataclasses", "rich"]  # the panel (rich is built on dataclasses)


def test_the_version_needs_no_cli() -> None:
    code = "import sys\nsys.argv = ['fabwire', '--version']\nfrom fabwire.__main__ import run\ntry:\n    run()\n" \
           "except SystemExit:\n    pass\nprint('click' in sys.modules, file=sys.stderr)\n"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=cli_env())
    assert result.stdout.startswith("fabwire, version ")
    assert result.stderr.strip() == "False"


BLAS_THREADS = ("import os, fabwire.__main__, numpy\n"
                "print(os.environ['OPENBLAS_NUM_THREADS'], len(os.listdir('/proc/self/task')))\n")


def test_the_command_line_loads_numpy_with_one_blas_thread() -> None:
    env = {k: v for k, v in cli_env().items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    result = subprocess.run([sys.executable, "-c", BLAS_THREADS], capture_output=True, text=True, timeout=60, env=env)
    assert result.stdout.split() == ["1", "1"]  # the variable, and no thread beside the main one


def test_a_blas_thread_count_the_user_set_is_kept() -> None:
    env = {**cli_env(), "OPENBLAS_NUM_THREADS": "2"}
    result = subprocess.run([sys.executable, "-c", BLAS_THREADS], capture_output=True, text=True, timeout=60, env=env)
    assert result.stdout.split()[0] == "2"
