"""A broken devices.toml stops only the commands that need it (a device name, the default device, `devices …`);
a command given an address works, with the file's problem as one warning line on stderr."""

from __future__ import annotations

import json
import random
import tempfile
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import RunningSimulator, cli_env, run_cli, start_simulator
from fabwire.config import resolve_target
from fabwire.devices import LINEUS, XYZ, DeviceKind
from fabwire.errors import ConfigError, ConfigWarning

OFFICE = '[devices.office]\nkind = "xyz"\nurl = "sim://xyz"\n'
BROKEN = {
    "misspelt key": (OFFICE + "defualt = true\n", "unknown key 'defualt' (did you mean 'default'?)"),
    "bad TOML": (OFFICE + "default = yes\n", "not valid TOML"),
    "two defaults": (OFFICE + "default = true\n[devices.shop]\nkind = \"xyz\"\nurl = \"sim://xyz\"\n"
                     "default = true\n", "devices 'office' and 'shop' are both the default"),
    "unknown kind": ('[devices.office]\nkind = "xzy"\nurl = "sim://xyz"\n', "(did you mean 'xyz'?)"),
    "not a file": (None, "cannot read config file"),
}


def broken_config(tmp_path: Path, breakage: str) -> tuple[dict[str, str], str]:
    """An environment whose FABWIRE_CONFIG is broken in the given way, and the words its error says."""
    text, words = BROKEN[breakage]
    path = tmp_path / "devices.toml"
    if text is None:
        path.mkdir()
    else:
        path.write_text(text)
    env = cli_env()
    env["FABWIRE_CONFIG"] = str(path)
    return env, words


@pytest.fixture(scope="module")
def bare_host_sim() -> Iterator[tuple[str, RunningSimulator]]:
    """An XYZ simulator on the printer's own port 9100 of a loopback address of its own, so `-d HOST` (no port,
    no scheme: the form that could be a device name) reaches it."""
    host = f"127.{random.randrange(1, 255)}.{random.randrange(1, 255)}.{random.randrange(2, 255)}"
    sim = start_simulator("xyz", "--listen", f"{host}:9100", "--speed", "1000")
    try:
        yield host, sim
    finally:
        sim.stop()


@pytest.mark.parametrize("breakage", sorted(BROKEN))
def test_a_bare_address_works_past_a_broken_config_with_one_warning(
        breakage: str, tmp_path: Path, bare_host_sim: tuple[str, RunningSimulator]) -> None:
    env, words = broken_config(tmp_path, breakage)
    host, _ = bare_host_sim
    result = run_cli("xyz", "-d", host, "status", "--json", env=env)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["state_name"] == "idle"
    warning, = result.stderr.splitlines()
    assert warning.startswith("fabwire: warning: ")
    assert str(tmp_path / "devices.toml") in warning
    assert words in warning
    assert warning.endswith(f"the file is skipped and '{host}' taken as an address")


def test_a_bare_address_of_another_device_kind_warns_once(tmp_path: Path,
                                                          bare_host_sim: tuple[str, RunningSimulator]) -> None:
    """The Line-us resolves its target for the link and for the greeting: still one warning line. The host is the
    printer simulator's own loopback address, where no Line-us port is open whatever else runs on the machine."""
    env, words = broken_config(tmp_path, "misspelt key")
    host, _ = bare_host_sim
    result = run_cli("lineus", "position", "-d", host, "--timeout", "2", env=env)
    assert result.returncode == 8  # the address was tried: nothing of the Line-us listens there
    warning, error = result.stderr.splitlines()
    assert words in warning
    assert error.startswith(f"fabwire: error: connection refused by {host}:1337")


@pytest.mark.parametrize("breakage", sorted(BROKEN))
@pytest.mark.parametrize("line", [
    ["xyz", "-d", "office", "status"],
    ["xyz", "-d", "offce", "status"],
    ["xyz", "status"],
    ["devices", "list"],
    ["devices", "show", "office"],
], ids=["name", "misspelt-name", "default", "devices-list", "devices-show"])
def test_commands_that_need_the_config_fail_with_its_precise_error(breakage: str, line: list[str],
                                                                   tmp_path: Path) -> None:
    env, words = broken_config(tmp_path, breakage)
    result = run_cli(*line, env=env)
    assert result.returncode == ConfigError.exit_code, result.stderr
    error, = result.stderr.splitlines()
    assert error.startswith("fabwire: error: ")
    assert words in error
    assert result.stdout == ""


def test_the_library_warns_and_uses_the_address(tmp_path: Path) -> None:
    path = tmp_path / "devices.toml"
    path.write_text(OFFICE + "defualt = true\n")
    with pytest.warns(ConfigWarning, match="unknown key 'defualt'"):
        target = resolve_target("printer.local", XYZ, path)
    assert (target.endpoint.host, target.endpoint.port) == ("printer.local", 9100)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ConfigError, match="unknown key 'defualt'"):
            resolve_target("office", XYZ, path)
        with pytest.raises(ConfigError, match="unknown key 'defualt'"):
            resolve_target(None, XYZ, path)


hosts = st.one_of(st.ip_addresses(v=4).map(str),
                  st.from_regex(r"\A[a-z][a-z0-9-]{0,15}(\.[a-z][a-z0-9-]{0,10}){1,3}\Z"))


@settings(max_examples=200, deadline=None)
@given(host=hosts, kind=st.sampled_from([XYZ, LINEUS]))
def test_any_dotted_host_or_ip_is_an_address_past_a_broken_config(host: str, kind: DeviceKind) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "devices.toml"
        path.write_text(OFFICE + "defualt = true\n")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            target = resolve_target(host, kind, path)
    assert (target.endpoint.host, target.endpoint.port) == (host, kind.default_port)
    assert [type(w.message) for w in caught] == [ConfigWarning]
    assert "unknown key 'defualt'" in str(caught[0].message)
