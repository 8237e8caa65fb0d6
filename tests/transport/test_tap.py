"""The trace tap records both directions losslessly, and `trace show` renders captures readably."""

from __future__ import annotations

import asyncio
import json
import os
from pathlib import Path

import pytest

from clitools import run_cli
from fabwire.errors import InputError
from fabwire.transport import TapTransport, memory_pair
from fabwire.transport.tap import FROM_DEVICE, TO_DEVICE, TraceWriter, read_trace, replay_bytes
from fabwire.transport.trace_show import render_trace

ALL_BYTES = bytes(range(256))


async def record(path: Path, to_device: list[bytes], from_device: list[bytes]) -> None:
    host, device = memory_pair("traced")
    tap = TapTransport(host, TraceWriter.to_file(path, url=host.url, peer=host.peer))
    async with asyncio.timeout(5):
        for out, back in zip(to_device, from_device, strict=True):
            await tap.write(out)
            assert await device.read() == out
            await device.write(back)
            assert await tap.read() == back
    await tap.close()


async def test_capture_replays_to_the_identical_bytes(tmp_path: Path) -> None:
    path = tmp_path / "cap.jsonl"
    sent = [b"XYZv3/query=a", ALL_BYTES, b"S0*c6\n"]
    received = [b"j:9511,0\n$\n", ALL_BYTES[::-1], b"ok\r\n\x00"]
    await record(path, sent, received)
    assert replay_bytes(path, TO_DEVICE) == b"".join(sent)
    assert replay_bytes(path, FROM_DEVICE) == b"".join(received)
    records = list(read_trace(path))
    assert [r.direction for r in records[:6]] == [">", "<", ">", "<", ">", "<"]
    assert records[-1].event == "close"
    times = [r.t for r in records]
    assert times == sorted(times)


async def test_capture_header_names_the_link(tmp_path: Path) -> None:
    path = tmp_path / "cap.jsonl"
    await record(path, [b"a"], [b"b"])
    header = json.loads(path.read_text().splitlines()[0])
    assert header["trace"] == "fabwire"
    assert header["url"] == "memory://traced"


def test_render_shows_text_with_escapes_and_binary_as_hexdump(tmp_path: Path) -> None:
    from fabwire.transport.tap import TraceRecord

    records = [
        TraceRecord(0.0, ">", b"XYZv3/query=a\r\n"),
        TraceRecord(0.01, "<", b"b:20\nj:9511,0\n$\n"),
        TraceRecord(0.02, "<", b"ok X:1000 Y:1000 Z:1000\r\n\x00"),
        TraceRecord(0.03, ">", bytes(range(0x80, 0xA0))),
        TraceRecord(0.04, None, event="close"),
    ]
    lines = list(render_trace(records, timestamps=False))
    assert lines[0] == ">XYZv3/query=a\\r\\n"
    assert lines[1:4] == ["<b:20\\n", "<j:9511,0\\n", "<$\\n"]
    assert lines[4] == "<ok X:1000 Y:1000 Z:1000\\r\\n\\0"
    assert lines[5] == "> [32 bytes]"
    assert lines[6].strip().startswith("00000000  80 81 82")
    assert lines[-1] == "-- close"


async def test_trace_show_cli(tmp_path: Path) -> None:
    path = tmp_path / "cap.jsonl"
    await record(path, [b"S0*c6\n"], [b"S0 A3*22\n"])
    result = run_cli("trace", "show", "--no-time", str(path))
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines()[:2] == [">S0*c6\\n", "<S0 A3*22\\n"]
    as_json = run_cli("--json", "trace", "show", str(path))
    assert [json.loads(line)["data"] for line in as_json.stdout.splitlines()] == ["S0*c6\n", "S0 A3*22\n", ""]


def test_a_file_that_is_not_a_trace_is_a_clear_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"trace": "fabwire", "version": 1}\n{"t": 0, "dir": "?", "data": ""}\n')
    with pytest.raises(InputError, match="line 2"):
        list(read_trace(bad))
    result = run_cli("trace", "show", str(bad))
    assert result.returncode == InputError.exit_code
    assert "line 2" in result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("cut", [5, 20])
async def test_a_capture_cut_off_mid_record_shows_what_it_holds(tmp_path: Path, cut: int) -> None:
    path = tmp_path / "cap.jsonl"
    await record(path, [b"S0*c6\n"], [b"S0 A3*22\n"])
    whole = path.read_bytes()
    path.write_bytes(whole[:-cut])  # the capturing process killed while writing its last line
    result = run_cli("trace", "show", "--no-time", str(path))
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines()[:2] == [">S0*c6\\n", "<S0 A3*22\\n"]
    assert result.stderr.endswith("the last record is cut off (the capture stopped while writing it)\n")
    with pytest.raises(InputError, match="not a fabwire trace record"):  # the library call keeps it an error
        list(read_trace(path))
    middle = tmp_path / "middle.jsonl"
    lines = whole.decode().splitlines(keepends=True)
    middle.write_text("".join([*lines[:-2], lines[-2][:-cut] + "\n", lines[-1]]))
    broken = run_cli("trace", "show", str(middle))  # damage inside the file is no cut-off end
    assert broken.returncode == InputError.exit_code
    path.write_bytes(whole[:-1])  # only the final newline missing: the record is whole
    assert run_cli("trace", "show", str(path)).stderr == ""


async def test_closing_a_tap_twice_records_one_close(tmp_path: Path) -> None:
    path = tmp_path / "cap.jsonl"
    host, _device = memory_pair()
    tap = TapTransport(host, TraceWriter.to_file(path, url=host.url, peer=host.peer))
    await tap.close()
    await tap.close()
    assert [r.event for r in read_trace(path)] == ["close"]


def test_deeply_nested_json_is_a_clear_error_not_a_crash(tmp_path: Path) -> None:
    bad = tmp_path / "nested.jsonl"
    bad.write_text('{"trace": "fabwire", "version": 1}\n' + "[" * 100000 + "]" * 100000 + "\n")
    with pytest.raises(InputError, match="line 2"):
        list(read_trace(bad))


def test_a_block_of_nuls_is_a_hexdump_with_repeats_folded() -> None:
    from fabwire.transport.tap import TraceRecord

    header = b"3DPFNKG13WTW" + bytes(8192 - 12)
    lines = list(render_trace([TraceRecord(0.0, ">", header), TraceRecord(0.1, "<", b"ok\r\n\x00")],
                              timestamps=False))
    assert lines[0] == "> [8192 bytes]"
    assert lines[1].strip().startswith("00000000  33 44 50 46")
    assert lines[3].strip() == "*"
    assert lines[4].strip() == "00002000"
    assert lines[5] == "<ok\\r\\n\\0"  # a reply's one trailing NUL is still text
    assert len(lines) == 6


def test_records_stream_before_a_later_bad_line(tmp_path: Path) -> None:
    path = tmp_path / "cap.jsonl"
    path.write_text('{"trace": "fabwire", "version": 1}\n{"t": 0, "dir": ">", "data": "M114\\u0000"}\n'
                    '{"t": 1, "dir": "<"\n')
    records = read_trace(path)
    assert next(records).data == b"M114\x00"
    with pytest.raises(InputError, match="line 3"):
        next(records)


def test_a_capture_that_cannot_be_written_any_more_is_one_clear_error() -> None:
    """The disk fills or the reader of a pipe goes away mid-session: the next record says so, naming the capture."""
    read_end, write_end = os.pipe()
    writer = TraceWriter(open(write_end, "w", encoding="utf-8"), url="tcp://127.0.0.1:1", peer="x")  # noqa: SIM115
    os.close(read_end)
    with pytest.raises(InputError, match="cannot write trace file stream: Broken pipe"):
        writer.chunk(TO_DEVICE, b"Q0*ea\n")
    writer.close()  # quietly: the failure was reported once


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_a_trace_on_a_full_disk_is_one_line_of_bad_input() -> None:
    done = run_cli("mmu", "--trace", "/dev/full", "-d", "sim://mmu?speed=100", "--speed", "100", "version")
    assert done.returncode == 4, done.stderr
    assert done.stderr == "fabwire: error: cannot write trace file /dev/full: No space left on device\n"
