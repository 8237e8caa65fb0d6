"""One machine is monitored once, however its address is spelt: every spelling of one machine (the rows of
SPELLINGS, each with its source) is refused by the agent as the second device, through the library and through
`fabwire serve`; addresses of distinct machines (DISTINCT) are both monitored."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from clitools import cli_env, run_cli
from fabwire.agent.core import Agent, DeviceSpec
from fabwire.errors import InputError


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


SPELLINGS: dict[str, tuple[str, str, str]] = {
    # row: (kind, first address, second address of the same machine), {port} a port nobody listens on
    "localhost": ("xyz", "127.0.0.1:{port}", "localhost:{port}"),  # RFC 6761 §6.3: localhost is the loopback
    "scheme": ("xyz", "127.0.0.1:{port}", "tcp://127.0.0.1:{port}"),  # fabwire's address forms: tcp:// optional
    "ipv4-mapped": ("lineus", "127.0.0.1:{port}", "[::ffff:127.0.0.1]:{port}"),  # RFC 4291 §2.5.5.2
    "case-and-root-dot": ("xyz", "LocalHost:{port}", "localhost.:{port}"),  # RFC 4343 §3; RFC 1034 §3.1
    "default-port": ("xyz", "127.0.0.1", "127.0.0.1:9100"),  # the da Vinci's TCP port is 9100 (XYZv3 reference)
    "same-string": ("mmu", "127.0.0.1:{port}", "127.0.0.1:{port}"),
    "serial-link": ("mmu", "{tty}", "serial://{link}"),  # udev's /dev/serial/by-id links name the same port
    "same-simulator": ("xyz", "sim://xyz?model=nano", "sim://xyz?model=nano"),
}
DISTINCT: dict[str, tuple[str, str, str]] = {
    "other-port": ("xyz", "127.0.0.1:{port}", "127.0.0.1:{other}"),
    "other-simulator": ("xyz", "sim://xyz?model=nano", "sim://xyz?model=nano&serial=OTHER1"),
    "other-serial-port": ("mmu", "{tty}", "{other_tty}"),
}


def addresses(row: tuple[str, str, str], tmp_path: Path) -> tuple[str, str, str]:
    kind, first, second = row
    tty, other_tty = tmp_path / "ttyFAKE0", tmp_path / "ttyFAKE1"
    tty.touch()
    other_tty.touch()
    (tmp_path / "by-id").mkdir(exist_ok=True)
    link = tmp_path / "by-id" / "usb-Prusa_MMU3-if00"
    link.symlink_to(tty)
    fields = {"port": free_port(), "other": free_port(), "tty": tty, "other_tty": other_tty, "link": link}
    return kind, first.format(**fields), second.format(**fields)


@pytest.mark.parametrize("row", SPELLINGS)
async def test_a_second_spelling_of_a_monitored_machine_is_refused(row: str, tmp_path: Path) -> None:
    kind, first, second = addresses(SPELLINGS[row], tmp_path)
    async with Agent(state_dir=tmp_path / "state") as agent:
        await agent.add_device(DeviceSpec("first", kind, first))
        with pytest.raises(InputError, match="reaches the machine already monitored as 'first'"):
            await agent.add_device(DeviceSpec("second", kind, second))
        assert [s.spec.name for s in agent.sessions()] == ["first"]
        await agent.remove_device(agent.sessions()[0].info.id)
        await agent.add_device(DeviceSpec("second", kind, second))  # once the first is gone, the machine is free
        assert [s.spec.name for s in agent.sessions()] == ["second"]


@pytest.mark.parametrize("row", DISTINCT)
async def test_distinct_machines_are_both_monitored(row: str, tmp_path: Path) -> None:
    kind, first, second = addresses(DISTINCT[row], tmp_path)
    async with Agent(state_dir=tmp_path / "state") as agent:
        await agent.add_device(DeviceSpec("first", kind, first))
        await agent.add_device(DeviceSpec("second", kind, second))
        assert sorted(s.spec.name for s in agent.sessions()) == ["first", "second"]


def test_serve_and_devices_add_refuse_one_machine_under_two_spellings(tmp_path: Path) -> None:
    """The same rule at every door: `serve` given a machine twice under two spellings stops before it starts (as
    for the same spelling twice), and `devices add` refuses to name it twice."""
    port = free_port()
    env = cli_env(tmp_path) | {"FABWIRE_CONFIG": str(tmp_path / "devices.toml")}
    twice = run_cli("serve", "--listen", "127.0.0.1:0", "--state-dir", str(tmp_path / "state"),
                    "--device", f"a:xyz=127.0.0.1:{port}", "--device", f"b:xyz=localhost:{port}", env=env, timeout=60)
    assert twice.returncode == 4, twice.stderr
    assert twice.stderr.strip() == (f"fabwire: error: 'localhost:{port}' is given twice, as 'a' and 'b': one machine "
                                    "is monitored once")
    assert run_cli("devices", "add", "desk", f"localhost:{port}", "--kind", "xyz", env=env).returncode == 0
    again = run_cli("devices", "add", "desk2", f"tcp://127.0.0.1:{port}", "--kind", "xyz", env=env)
    assert again.returncode == 4, again.stderr
    assert f"is the machine 'desk' names already (tcp://localhost:{port})" in again.stderr
    assert "desk2" not in (tmp_path / "devices.toml").read_text()


async def test_devices_added_at_once_keep_the_order_they_were_given_in(tmp_path: Path) -> None:
    """Each add looks its machine up first; the order of the devices is still the order they were given in."""
    import asyncio

    specs = [DeviceSpec(f"d{n}", "xyz", f"127.0.0.1:{free_port()}") for n in range(8)]
    async with Agent(state_dir=tmp_path / "state") as agent:
        await asyncio.gather(*(agent.add_device(spec) for spec in specs))
        assert [s.spec.name for s in agent.sessions()] == [spec.name for spec in specs]
