"""Every model in the table: the .3w fabwire writes for it is identified as that model and printed by a simulated
printer of that model; files the vendor's own software writes are printed too."""

from __future__ import annotations

import asyncio
import struct
import zlib

import pytest

from fabwire.xyz.client import XYZPrinter
from fabwire.xyz.models import MODELS, PrinterModel, find_model, model_for_file_id, models_for_file_id
from fabwire.xyz.personas import personality
from fabwire.xyz.printer import Printer
from fabwire.xyz.sim import XYZSimulator
from fabwire.xyz.threew import BODY_OFFSET, MAGIC, TAG_ECB, inspect_3w, read_3w, write_3w
from linktools import loopback_tcp

GCODE = b";TIME:60\n;LAYER_COUNT:2\nG28\nG1 Z0.3 F3000\nG1 X10 Y10 E1 F1200\nG1 X10 Y20 E2\nM84\n"
SPEAKS_XYZV3 = [m for m in MODELS if m.v3_protocol]


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.model_number)
def test_a_file_written_for_a_model_names_that_model(model: PrinterModel) -> None:
    info = inspect_3w(write_3w(GCODE, model))
    assert info.machine == model.file_id
    assert model in models_for_file_id(info.machine)
    assert model_for_file_id(info.machine, model) is model
    read_back = read_3w(write_3w(GCODE, model)).model
    assert read_back is not None
    assert read_back.file_id == model.file_id
    if len(models_for_file_id(model.file_id)) == 1:
        assert read_back is model


def test_the_3in1_file_id_is_not_the_open_filament_model() -> None:
    three_in_one = find_model("dv1JS0A000")
    assert three_in_one.file_id == "dv1JSOA000"  # letter O, as in XYZware's table
    assert model_for_file_id("dv1JSOA000") is three_in_one
    assert model_for_file_id("daVinciJR10S") is find_model("dv1JSOA000")
    assert "Open filament" not in (read_3w(write_3w(GCODE, three_in_one)).model or three_in_one).name


@pytest.mark.parametrize("model", SPEAKS_XYZV3, ids=lambda m: m.model_number)
def test_the_simulated_model_accepts_the_file_written_for_it(model: PrinterModel) -> None:
    verdict = Printer(personality(model.model_number)).check_file(write_3w(GCODE, model))
    assert verdict.ok, verdict.reason


@pytest.mark.parametrize("number", ["dv1JS0A000", "dv1JSOA000", "dvF110B000"])
async def test_a_file_written_for_the_model_prints_on_its_simulator(number: str) -> None:
    sim = XYZSimulator(number, speed=5000, gap=0.01, close_after_reply=False)
    async with asyncio.timeout(60), loopback_tcp(sim.serve) as link:
        printer = XYZPrinter(link)
        printer.poll_interval = 0.02
        try:
            final = await printer.print_file(write_3w(GCODE, find_model(number)))
        finally:
            await printer.close()
    assert final.state_code in (9509, 9511)
    assert sim.uploads[-1].complete


def xyzprint_v5(model: PrinterModel, gcode: bytes) -> bytes:
    """A v5 file in XYZprint's compact layout: an 8-byte gap, the exact header length, a CRLF plaintext header at
    0x70 and an AES-256-ECB body at 0x2000 (the layout of XYZprint's own files)."""
    standard = write_3w(gcode, model, container=5)
    body = standard[BODY_OFFSET:]
    header = read_3w(standard).header.replace(b"\n", b"\r\n")
    preamble = (MAGIC + bytes([1, 5, 0, 0]) + struct.pack(">I", 8) + bytes(8) + TAG_ECB
                + struct.pack(">III", len(header), 68, 1) + struct.pack(">I", zlib.crc32(body)))
    assert len(preamble) == 0x34
    out = preamble + bytes(0x70 - len(preamble)) + header
    return out + bytes(BODY_OFFSET - len(out)) + body


@pytest.mark.parametrize("number", ["dv1J00A000", "dv1JW0A000", "dv1JA0A000", "dv1JS0A000", "dv2JW0A000",
                                    "dv1NX0A000"])
def test_the_jr_line_and_the_nano_take_xyzprints_v5_files(number: str) -> None:
    model = find_model(number)
    data = xyzprint_v5(model, GCODE)
    info = inspect_3w(data)
    assert (info.container, info.gap, info.header_offset, info.crc_ok) == (5, 8, 0x70, True)
    verdict = Printer(personality(number)).check_file(data)
    assert verdict.ok, verdict.reason
    assert verdict.print_time == 60


@pytest.mark.parametrize(("data", "reason"), [
    (b"GCDE\x01\x00" + bytes(40), "binary G-code"),
    (b"PK\x03\x04" + bytes(40), "zip archive"),
    (b"G28\nG1 X1 Y1\n", "G-code text"),
])
def test_the_simulated_firmware_names_what_it_was_sent(data: bytes, reason: str) -> None:
    verdict = Printer(personality("dv1MW0A000")).check_file(data)
    assert not verdict.ok
    assert verdict.reason.startswith(reason)


def test_a_base64_3w_is_decoded_by_the_host_not_the_printer() -> None:
    import base64

    verdict = Printer(personality("dv1MW0A000")).check_file(base64.b64encode(write_3w(GCODE, "dv1MW0A000")))
    assert not verdict.ok
    assert "base64" in verdict.reason
