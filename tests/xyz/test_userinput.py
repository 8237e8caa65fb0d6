"""Every user string that goes into an XYZv3 command: a clear input error or a correct encoding, never a crash."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import run_cli
from fabwire.errors import InputError
from fabwire.xyz import protocol as xp
from fabwire.xyz import userinput
from fabwire.xyz.client import XYZPrinter
from fabwire.xyz.protocol import DeviceDecoder, Link, Received
from fabwire.xyz.sim import XYZSimulator
from linktools import loopback_tcp

GCODE = b";TIME:60\nG28\nG1 X10 Y10 E1 F1200\nM84\n"


@pytest.mark.parametrize(("local", "upload"), [
    ("Würfel.gcode", "Wurfel.3w"),
    ("part, v2.gcode", "part_v2.3w"),
    ("a" * 140 + ".gcode", "a" * 32 + ".3w"),
    ("模型.gcode", "fabwire.3w"),
    ("../../etc/passwd.gcode", "passwd.3w"),
    ("  .gcode", "fabwire.3w"),
])
def test_upload_names_derived_from_any_file_name_are_safe(local: str, upload: str) -> None:
    assert userinput.derived_upload_name(local) == upload
    assert userinput.upload_name(upload) == upload


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=200))
def test_any_local_name_gives_an_upload_command_the_printer_splits_back(local: str) -> None:
    name = userinput.derived_upload_name(local + ".gcode")
    wire = xp.encode(xp.Upload(name, 1234), Link.WIFI)
    events = DeviceDecoder().feed(wire, 0.0)
    assert isinstance(events[0], Received)
    assert events[0].command == xp.Upload(name, 1234)


CHECKS = {
    "printer name": (userinput.printer_name, lambda value: xp.SetName(value)),
    "ssid": (userinput.ssid, lambda value: xp.JoinWifi(value, "password1", 0)),
    "password": (userinput.wifi_password, lambda value: xp.JoinWifi("Lab", value, 0)),
    "upload name": (userinput.upload_name, lambda value: xp.Upload(value, 10)),
}


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(sorted(CHECKS)), st.text(max_size=80))
def test_a_user_string_is_refused_as_input_or_encoded_so_the_device_reads_it_back(which: str, text: str) -> None:
    check, command = CHECKS[which]
    try:
        accepted = check(text)
    except InputError:
        return
    wire = xp.encode(command(accepted), Link.SERIAL)
    events = DeviceDecoder().feed(wire, 0.0)
    assert len(events) == 1
    assert isinstance(events[0], Received)
    assert events[0].command == command(accepted)


@pytest.mark.parametrize(("code", "ok"), [("en", True), ("FR", True), (" jp", True), ("xx", False), ("", False),
                                          ("english", False), ("e]", False)])
def test_languages_are_the_firmwares(code: str, ok: bool) -> None:
    if ok:
        assert userinput.language(code) in userinput.LANGUAGES
    else:
        with pytest.raises(InputError, match="the firmware has en, fr, it, de, es, jp"):
            userinput.language(code)


async def test_the_client_refuses_bad_strings_before_sending_anything() -> None:
    sim = XYZSimulator(speed=1000, gap=0.01)
    async with asyncio.timeout(20), loopback_tcp(sim.serve) as link:
        printer = XYZPrinter(link)
        try:
            for call in (lambda: printer.set_language("xx"), lambda: printer.set_name("a" * 17),
                         lambda: printer.set_name("Drucker-Ü"), lambda: printer.join_wifi("Lab,5G", "password1"),
                         lambda: printer.join_wifi("Lab", "x" * 70), lambda: printer.upload(GCODE, "a,b.3w")):
                with pytest.raises(InputError):
                    await call()
        finally:
            await printer.close()
    assert not any(c.startswith(("config=lang", "config=name", "config=ssid", "upload=")) for c in sim.commands)


def test_cli_name_and_language_refusals_exit_4_without_a_printer(tmp_path: Path) -> None:
    gcode = tmp_path / "part.gcode"
    gcode.write_bytes(GCODE)
    for args in (("language", "xx"), ("name", "x" * 20), ("print", "--name", "a,b", str(gcode)),
                 ("wifi", "join", "Lab", "--password", "p,ssword1")):
        result = run_cli("xyz", "-d", "127.0.0.1:9", *args)
        assert result.returncode == 4, (args, result.stderr)
        assert "Traceback" not in result.stderr


async def test_save_to_sd_and_the_chosen_name_go_on_the_wire() -> None:
    sim = XYZSimulator(speed=1000, gap=0.01)
    async with asyncio.timeout(30), loopback_tcp(sim.serve) as link:
        printer = XYZPrinter(link)
        printer.poll_interval = 0.02
        try:
            await printer.print_file(GCODE, name="Cube_v2.3w", save_to_sd=True, wait=False)
        finally:
            await printer.close()
    assert any(c.startswith("upload=Cube_v2.3w,") and c.endswith(",SaveToSD") for c in sim.commands)
