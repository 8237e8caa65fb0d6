"""The lines `--help` and completion show for commands not loaded yet are each command's own, for every lazy group
in the tree; and what `--help`, completion, a status query and the file commands import, as a table of command lines."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import click
import pytest

from clitools import SimulatorStarter, cli_env
from fabwire.cli import cli
from fabwire.cli_support import Lazy, LazyGroup
from fabwire.extras import EXTRA_OF
from fabwire.xyz.models import find_model
from fabwire.xyz.threew import convert_gcode_file


def lazy_groups(group: click.Group, path: str) -> Iterator[tuple[str, LazyGroup]]:
    """Every lazy group under `group`, loading each subcommand to walk the real tree."""
    ctx = click.Context(group)
    if isinstance(group, LazyGroup):
        yield path, group
    for name in group.list_commands(ctx):
        command = group.get_command(ctx, name)
        if isinstance(command, click.Group):
            yield from lazy_groups(command, f"{path} {name}")


ENTRIES = [(f"{path} {name}", group, name, entry) for path, group in lazy_groups(cli, "fabwire")
           for name, entry in group._lazy.items()]


def test_the_tree_has_lazy_commands_at_every_level() -> None:
    paths = {path.rsplit(" ", 1)[0] for path, *_ in ENTRIES}
    assert {"fabwire", "fabwire sim", "fabwire xyz", "fabwire lineus"} <= paths


@pytest.mark.parametrize(("path", "group", "name", "entry"), ENTRIES, ids=[e[0] for e in ENTRIES])
def test_each_lazy_line_is_the_commands_own(path: str, group: LazyGroup, name: str, entry: Lazy) -> None:
    module, _, attr = entry.target.partition(":")
    command = getattr(__import__(module, fromlist=[attr]), attr)
    assert command.name == name
    assert entry.summary == command.get_short_help_str(limit=1 << 16)
    assert entry.extra in {"", *EXTRA_OF.values()}


@pytest.mark.parametrize("width", [60, 80, 120])
@pytest.mark.parametrize("path", [["fabwire"], ["fabwire", "sim"], ["fabwire", "xyz"], ["fabwire", "lineus"]],
                         ids=" ".join)
def test_help_lists_commands_as_if_loaded(path: list[str], width: int) -> None:
    group: click.Group = cli
    for name in path[1:]:
        found = group.get_command(click.Context(group), name)
        assert isinstance(found, click.Group)
        group = found
    shown, loaded = (click.Context(group, info_name=path[-1], terminal_width=width).make_formatter() for _ in "ab")
    group.format_commands(click.Context(group), shown)
    click.Group.format_commands(group, click.Context(group), loaded)  # click's own: loads each command
    assert shown.getvalue() == loaded.getvalue()


def test_completion_offers_commands_as_if_loaded() -> None:
    ctx = click.Context(cli)
    assert [(i.value, i.help) for i in cli.shell_complete(ctx, "")] == \
        [(i.value, i.help) for i in click.Group.shell_complete(cli, ctx, "")]


DEVICE_CODE = {"fabwire.xyz", "fabwire.lineus", "fabwire.mmu", "fabwire.agent", "fabwire.mqtt", "fabwire.demo",
               "fabwire.vpype", "fabwire.devices_cli", "fabwire.samples", "fabwire.config"}
"""Packages and modules that implement commands; `fabwire --help` and top-level completion load none."""
HEAVY = {"numpy", "rich", "serialx", "termios", "cryptography", "svgelements", "PIL", "shapely", "zeroconf",
         "fastapi", "uvicorn", "aiomqtt", "dataclasses"}
XYZ_PRINTER_SIDE = {"fabwire.xyz.device", "fabwire.xyz.printer", "fabwire.xyz.sim", "fabwire.xyz.threew",
                    "fabwire.xyz.gcodeinfo", "fabwire.xyz.intake", "fabwire.xyz.threew_cli"}
NOT_XYZ = {"fabwire.lineus", "fabwire.mmu", "fabwire.agent", "fabwire.mqtt", "fabwire.demo", "fabwire.vpype"}
DEVICE_SIDE = {"asyncio", "ssl", "concurrent.futures", "socket", "fabwire.transport", "fabwire.simserve",
               "fabwire.xyz.client", "fabwire.xyz.live", "fabwire.xyz.maintenance", "fabwire.xyz.sim",
               "fabwire.xyz.device", "fabwire.xyz.printer", "fabwire.xyz.discovery", "fabwire.sync"}
"""The event loop and what reaches a device (links, client, live view, simulator): a command on files loads none."""
STATUS_SPARES = {"random", "click.shell_completion", "concurrent.futures.thread"}
"""Loaded only where needed: fault injection, completion, a thread pool."""
DEVICES = ('[devices.office]\nkind = "xyz"\nurl = "10.0.0.5"\n[devices.bench]\nkind = "mmu"\nurl = "/dev/ttyACM0"\n'
           '[devices.otto]\nkind = "lineus"\nurl = "10.0.0.7"\n')

IMPORTS: list[tuple[str, str, set[str]]] = [
    # (how it is run, the command line, what it must not import: a package stands for its modules)
    ("run", "--help", DEVICE_CODE | HEAVY),
    ("run", "sim --help", DEVICE_CODE | HEAVY - {"fabwire.config"}),
    ("run", "xyz --help", NOT_XYZ | XYZ_PRINTER_SIDE | HEAVY),
    ("run", "lineus --help", {"numpy", "svgelements", "PIL", "shapely", "zeroconf", "fabwire.lineus.plot",
                              "fabwire.lineus.client", "fabwire.lineus.kinematics", "fabwire.xyz", "fabwire.mmu"}),
    ("run", "mmu --help", {"numpy", "rich", "fabwire.mmu.sim", "fabwire.xyz", "fabwire.lineus"}),
    ("complete", "fabwire x", DEVICE_CODE - {"fabwire.config"} | HEAVY),
    ("complete", "fabwire -d o", DEVICE_CODE - {"fabwire.config"} | HEAVY),
    ("complete", "fabwire sim ", DEVICE_CODE | HEAVY),
    ("complete", "fabwire xyz status -d o", NOT_XYZ | XYZ_PRINTER_SIDE | HEAVY),
    ("complete", "fabwire xyz co", NOT_XYZ | XYZ_PRINTER_SIDE | HEAVY),
    ("complete", "fabwire lineus -d o", {"numpy", "svgelements", "PIL", "fabwire.lineus.client", "fabwire.xyz"}),
    ("complete", "fabwire mmu -d b", {"numpy", "rich", "fabwire.mmu.sim", "fabwire.xyz", "fabwire.lineus"}),
    ("status", "xyz -d {address} status --json", NOT_XYZ | XYZ_PRINTER_SIDE | HEAVY | STATUS_SPARES),
    ("status", "xyz -d {address} status",  # the panel: rich, which loads random itself
     NOT_XYZ | XYZ_PRINTER_SIDE | HEAVY - {"rich", "dataclasses"} | STATUS_SPARES - {"random"}),
    # a .3w printed with standard error on a pipe: plain lines (no rich), the file checked without G-code scanning
    # and without the table of slicer wordings
    ("status", "xyz -d {address} print {job} --no-wait",
     NOT_XYZ | {"numpy", "rich", "fabwire.xyz.gcodeinfo", "fabwire.xyz.printer", "fabwire.xyz.sim",
                "fabwire.xyz.slicerfigures"}),
    # the file commands: G-code to .3w and back, and what a file holds
    ("file", "xyz convert {gcode} {out}.3w --model miniMaker", NOT_XYZ | DEVICE_SIDE),
    ("file", "xyz convert {job} {out}.gcode", NOT_XYZ | DEVICE_SIDE),
    ("file", "xyz info {gcode}", NOT_XYZ | DEVICE_SIDE),
    ("file", "xyz info --json {job}", NOT_XYZ | DEVICE_SIDE),
]


def imported(how: str, line: str, config: Path, address: str) -> tuple[int, str, set[str]]:
    """Run one command line in a fresh interpreter: its exit code, output and every module it imported."""
    env = cli_env()
    env["FABWIRE_CONFIG"] = str(config)
    argv = line.format(address=address, job=config.with_name("part.3w"), gcode=config.with_name("part.gcode"),
                       out=config.with_name("out")).split()
    if how == "complete":
        env.update(_FABWIRE_COMPLETE="bash_complete", COMP_WORDS=line,
                   COMP_CWORD=str(len(argv) - (0 if line.endswith(" ") else 1)))
        argv = []
    code = ("import sys\nsys.argv = ['fabwire', *" + repr(argv) + "]\nfrom fabwire.__main__ import run\n"
            "try:\n    run()\nexcept SystemExit as exc:\n    rc = exc.code\n"
            "print('\\n' + repr(sorted(sys.modules)), file=sys.stderr)\nsys.exit(rc)\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=env)
    modules = set(json.loads(result.stderr.strip().splitlines()[-1].replace("'", '"')))
    return result.returncode, result.stdout, modules


@pytest.mark.parametrize(("how", "line", "forbidden"), IMPORTS, ids=[f"{h}: {x}" for h, x, _ in IMPORTS])
def test_a_command_imports_only_what_it_uses(how: str, line: str, forbidden: set[str], tmp_path: Path,
                                             simulator: SimulatorStarter) -> None:
    config = tmp_path / "devices.toml"
    config.write_text(DEVICES)
    if "{job}" in line or "{gcode}" in line:
        gcode = tmp_path / "part.gcode"
        gcode.write_text(";FLAVOR:Marlin\nG28\nG1 X10 Y10 E1 F1800\nG1 X20 Y10 E2\n")
        convert_gcode_file(gcode, tmp_path / "part.3w", find_model("dv1MW0A000"))
    address = simulator("xyz", "--listen", "127.0.0.1:0").url if how == "status" else ""
    rc, out, modules = imported(how, line, config, address)
    assert rc == 0
    assert out  # it did its work: help, completions or the status
    if how == "complete" and "-d" in line:
        assert out.splitlines()[0].split(",", 1)[1] in ("office", "bench", "otto")
    loaded = sorted(m for m in modules if any(m == f or m.startswith(f + ".") for f in forbidden))
    assert loaded == []


def test_make_bytecode_compiles_what_a_command_loads() -> None:
    """An editable install runs the sources in place: `make bytecode` (part of the install, `make demo` and
    `make bench`) writes the bytecode each module loads from, current for its source."""
    root = Path(__file__).resolve().parents[2]
    made = subprocess.run(["make", "--no-print-directory", "-s", "bytecode", f"BIN={Path(sys.executable).parent}"],
                          cwd=root, capture_output=True, text=True, timeout=300)
    assert made.returncode == 0, made.stderr
    code = ("import importlib.util, sys\nfrom fabwire.cli import main\nmain(['--help'])\n"
            "for name, module in sorted(sys.modules.items()):\n"
            "    if name.startswith('fabwire') and getattr(module, '__cached__', None):\n"
            "        print(name, module.__file__, module.__cached__, file=sys.stderr)\n")
    env = cli_env()
    env["PYTHONDONTWRITEBYTECODE"] = "1"  # nothing written during this run: what loads was there before
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=env)
    assert result.returncode == 0, result.stderr
    rows = [line.split() for line in result.stderr.splitlines()]
    assert len(rows) > 5
    for name, source, cached in rows:
        data = Path(cached).read_bytes()  # the pyc header: magic, flags, source mtime, source size
        stat = Path(source).stat()
        assert int.from_bytes(data[8:12], "little") == int(stat.st_mtime) & 0xFFFFFFFF, name
        assert int.from_bytes(data[12:16], "little") == stat.st_size & 0xFFFFFFFF, name
