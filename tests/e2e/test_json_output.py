"""Every JSON line fabwire prints is valid UTF-8 JSON, whatever bytes the input names hold."""

from __future__ import annotations

import io
import json
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import SimulatorStarter, cli_env, run_cli
from fabwire.console import Output

SVG = ('<svg xmlns="http://www.w3.org/2000/svg" width="10mm" height="10mm" viewBox="0 0 10 10">'
       '<path d="M1 1 L9 9" stroke="black"/></svg>')


def test_preview_json_of_a_non_utf8_file_name_is_valid_utf8(tmp_path: Path) -> None:
    raw = os.fsencode(tmp_path) + b"/bad\xffname\xc3.svg"
    Path(os.fsdecode(raw)).write_text(SVG)
    done = subprocess.run([sys.executable, "-m", "fabwire", "lineus", "preview", raw, "--json"],
                          capture_output=True, timeout=60, env=cli_env(tmp_path))
    assert done.returncode == 0, done.stderr
    data = json.loads(done.stdout.decode("utf-8"))  # strict: raises on any raw 0xff
    assert os.fsencode(data["file"]) == raw  # the escapes keep the exact bytes of the name


def _printed(data: object, stream_event: bool) -> bytes:
    buffer = io.BytesIO()
    stdout = io.TextIOWrapper(buffer, encoding="utf-8", errors="surrogateescape", newline="\n")
    saved, sys.stdout = sys.stdout, stdout
    try:
        out = Output(json_mode=True)
        if stream_event:
            out.event(data, "")  # type: ignore[arg-type]
        else:
            out.result(data)
        stdout.flush()
    finally:
        sys.stdout = saved
    return buffer.getvalue()


names = st.one_of(st.text(), st.binary().map(os.fsdecode),
                  st.text(st.characters(exclude_categories=())))  # lone surrogates included


@settings(max_examples=300, deadline=None)
@given(key=names, value=names, raw=st.binary(max_size=40), stream_event=st.booleans())
def test_any_string_prints_as_one_valid_utf8_json_line(key: str, value: str, raw: bytes,
                                                        stream_event: bool) -> None:
    printed = _printed({"file": value, "names": {key: [value]}, "data": raw}, stream_event)
    assert printed.endswith(b"\n")
    assert printed.count(b"\n") == 1
    data = json.loads(printed.decode("utf-8"))
    assert data["file"] == value
    assert data["names"] == {key: [value]}
    assert data["data"] == raw.decode("latin-1")


NON_SI = re.compile(r"_(?:seconds|secs?|minutes|mins?|hours|millis|milliseconds|cm|m_left|percent_s)$")
"""Key endings that would name a unit other than the SI one fabwire uses (`_s`, `_mm`, `_c`, `_percent`)."""
UNITLESS_BYTES = re.compile(r"(?:^|_)(?:size|gap|offset|length|bytes)$|^bytes_")
"""A byte quantity without its unit last (`size`, `gap`, `header_offset`) or a unit without its quantity (`bytes`):
byte counts are named `<quantity>_bytes`."""


DEVICE_WORDS = {"raw", "fields", "machine_units"}
"""Keys whose contents are a device's own words as it reports them (firmware letters, machine units): not named by
fabwire, so not held to its naming."""


def _keys(value: object) -> Iterator[str]:
    if isinstance(value, dict):
        for key, item in value.items():
            yield key
            if key not in DEVICE_WORDS:
                yield from _keys(item)
    elif isinstance(value, list):
        for item in value:
            yield from _keys(item)


def test_json_keys_name_si_units(simulator: SimulatorStarter, tmp_path: Path) -> None:
    svg = tmp_path / "square.svg"
    svg.write_text(SVG)
    gcode = tmp_path / "part.gcode"
    gcode.write_bytes(b"G28\nG1 Z0.2 F600\nG1 X10 Y5 E1\nG0 X0\n")
    image = tmp_path / "image.bin"
    image.write_bytes(b"dv1MW0A000+1.2.4" + bytes(2000))
    xyz = simulator("xyz", "--listen", "127.0.0.1:0").url
    mmu = simulator("mmu", "--listen", "127.0.0.1:0", "--speed", "50").url
    lineus = simulator("lineus", "--listen", "127.0.0.1:0", "--speed", "inf").url
    documents = []
    for args in (("lineus", "preview", str(svg)), ("xyz", "-d", xyz, "status"), ("xyz", "-d", xyz, "zoffset"),
                 ("xyz", "-d", xyz, "energy", "3"), ("xyz", "-d", xyz, "wifi", "info"),
                 ("xyz", "-d", xyz, "wifi", "scan"), ("xyz", "-d", xyz, "jog", "x", "5"),
                 ("mmu", "-d", mmu, "--speed", "50", "status"),
                 ("xyz", "convert", str(gcode), str(tmp_path / "part.3w")), ("xyz", "info", str(tmp_path / "part.3w")),
                 ("xyz", "info", str(gcode)), ("xyz", "-d", xyz, "firmware", "--yes", str(image)),
                 ("lineus", "-d", lineus, "position"), ("lineus", "-d", lineus, "position", "--servos"),
                 ("lineus", "-d", lineus, "move", "1200", "0"), ("lineus", "-d", lineus, "home"),
                 ("lineus", "-d", lineus, "info")):
        done = run_cli("--json", *args, env=cli_env(tmp_path))
        assert done.returncode == 0, (args, done.stderr)
        documents.append(json.loads(done.stdout))
    shell = run_cli("--json", "lineus", "-d", lineus, "shell", input_text="move 1100 100 down\nhome\n",
                    env=cli_env(tmp_path))
    assert shell.returncode == 0, shell.stderr
    documents += [json.loads(line) for line in shell.stdout.splitlines()]
    keys = {key for document in documents for key in _keys(document)}
    assert {"estimated_s", "elapsed_s", "zoffset_mm", "energy_saving_s", "extruder_c", "rssi_dbm", "distance_mm",
            "pulley_mm", "x_mm", "y_mm", "s_deg", "machine_units"} <= keys
    assert sorted(k for k in keys if NON_SI.search(k)) == []
    assert not keys & {"rssi", "distance", "pulley", "zoffset", "energy"}  # quantities always carry their unit
    assert sorted(k for k in keys if len(k) == 1) == []  # a firmware's letter (x, y, z, S …) names no unit
    assert {"size_bytes", "gap_bytes", "header_offset_bytes", "written_bytes", "gcode_bytes"} <= keys
    assert sorted(k for k in keys if (UNITLESS_BYTES.search(k) and not k.endswith("_bytes")) or k == "bytes") == []
