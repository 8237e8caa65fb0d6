"""The README's library examples run as written, against simulators standing in for the machines."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from clitools import SimulatorStarter, cli_env

README = Path(__file__).resolve().parents[2] / "README.md"


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.DOTALL)


def test_readme_has_a_sync_and_an_async_example() -> None:
    blocks = python_blocks()
    assert any("open_sync" in b for b in blocks)
    assert any("asyncio.run" in b for b in blocks)


def test_readme_library_examples_run(simulator: SimulatorStarter, tmp_path: Path) -> None:
    arm = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "inf").url.removeprefix("tcp://")
    printer = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "1000").url.removeprefix("tcp://")
    for number, block in enumerate(python_blocks()):
        if "line-us.local" not in block and "192.168.1.50" not in block:
            continue
        script = tmp_path / f"example{number}.py"
        script.write_text(block.replace("line-us.local", arm).replace("192.168.1.50", printer))
        result = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60,
                                env=cli_env(tmp_path))
        assert result.returncode == 0, f"README example {number} failed:\n{block}\n{result.stderr}"
        if "XYZPrinter" in block:
            assert result.stdout.startswith("idle")
