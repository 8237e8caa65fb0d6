"""The official `lineus` Python module (PyPI 1.0.3), unchanged, driving the simulator on a free port."""

from __future__ import annotations

import asyncio
import socket

import pytest

lineus = pytest.importorskip("lineus")

HELLO_WORLD = [(900, 300, 0), (900, -300, 0), (900, -300, 1000), (1200, 300, 0), (1200, -300, 0),
               (1200, -300, 1000), (900, 0, 0), (1200, 0, 0), (1200, 0, 1000), (1500, 150, 0), (1500, -300, 0),
               (1500, -300, 1000), (1500, 250, 0), (1500, 300, 0), (1500, 300, 1000)]


def official_session(port: int) -> dict[str, object]:
    arm = lineus.LineUs()
    arm._default_port = port
    out: dict[str, object] = {"connect": arm.connect("127.0.0.1")}
    try:
        out["hello"] = arm.get_hello_string()
        out["g01"] = arm.g01(1000, 0, 1000)
        out["g01_z"] = arm.g01(z=0)
        out["g01_none"] = arm.g01()
        out["speed"] = arm.send_gcode("G94", "S7")
        out["m114"] = arm.send_raw_gcode("M114")
        out["info"] = arm.get_info()
        out["files"] = arm.list_lineus_files()
        out["save"] = arm.save_to_lineus("G28\nG01 X1000 Y0", 2)
        out["files_after"] = arm.list_lineus_files()
        out["timeout"] = (arm.set_timeout(50), arm.set_timeout("bob"))
        out["ping"] = arm.ping("127.0.0.1")
    finally:
        arm.disconnect()
        arm.zeroconf.close()
    return out


async def test_official_module_session(lineus_sim) -> None:
    running = await lineus_sim(speed=50.0)
    out = await asyncio.wait_for(asyncio.to_thread(official_session, running.port), 60)
    assert out["connect"] is True
    assert out["hello"] == {"VERSION": "3.2.0 Nov 17 2019 17:54:57", "NAME": "line-us", "SERIAL": "123456"}
    assert out["g01"] == "ok X:1000.00 Y:0.00 Z:1000.00"
    assert out["g01_z"] == "ok X:1000.00 Y:0.00 Z:0.00"
    assert out["g01_none"] is False
    assert out["speed"] == "ok"
    assert out["m114"] == "ok X:1000.00 Y:0.00 Z:0.00"
    info = out["info"]
    assert isinstance(info, dict)
    assert {"ChipID", "name", "mac", "FS", "ZMap"} <= set(info)
    assert info["ResetReason"] == "External System"
    assert out["files"] == [("1", "156", "/0000001.txt")]
    assert out["save"] == "ok"
    assert out["files_after"] == [("1", "156", "/0000001.txt"), ("2", str(len("G28\nG01 X1000 Y0\n")), "/0000002.txt")]
    assert out["timeout"] == (True, False)
    ping = out["ping"]
    assert isinstance(ping, dict)
    assert set(ping) == {"mean", "min", "max", "stdev"}
    sim = running.sim
    wire = ["G01  X1000 Y0 Z1000", "G01  Z0", "G94 S7", "M114", "M122", "M20", "M28 S2", "G28"]
    assert list(sim.received)[:8] == wire
    assert sim.files[2] == "G28\nG01 X1000 Y0\n"
    assert sim.received.count("M114") == 7  # one explicit, then ping's warm-up and five timed


def hello_world_like_the_example(port: int) -> bytes:
    """What the official HelloWorld example does: NUL-terminated commands, read each reply up to the NUL."""
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:

        def read_reply() -> bytes:
            data = b""
            while not data.endswith(b"\x00"):
                chunk = sock.recv(1)
                assert chunk, "simulator closed the connection"
                data += chunk
            return data

        hello = read_reply()
        for x, y, z in HELLO_WORLD:
            sock.sendall(f"G01 X{x} Y{y} Z{z}".encode() + b"\x00")
            reply = read_reply()
            assert reply.startswith(b"ok ")
            assert reply.endswith(b"\r\n\x00")
        return hello


async def test_hello_world_example_draws_hi(lineus_sim) -> None:
    running = await lineus_sim(speed=100.0)
    hello = await asyncio.wait_for(asyncio.to_thread(hello_world_like_the_example, running.port), 60)
    assert hello.startswith(b"hello VERSION:")
    assert len(running.sim.arm.strokes) == 5


async def test_official_module_finds_advertised_simulator(lineus_sim) -> None:
    from fabwire.lineus.discovery import Advertiser

    running = await lineus_sim()
    advertiser = Advertiser("line-us", "127.0.0.1", running.port)
    await advertiser.start()
    try:
        def browse() -> list[tuple[str, str, str, int]]:
            arm = lineus.LineUs()
            try:
                for _ in range(40):
                    found = arm.get_line_us_list()
                    if found:
                        return list(found)
                    import time

                    time.sleep(0.1)
                return []
            finally:
                arm.zeroconf.close()

        found = await asyncio.wait_for(asyncio.to_thread(browse), 30)
    finally:
        await advertiser.stop()
    if not found:
        pytest.skip("multicast on this host does not reach the official module's all-interface browser")
    assert ("line-us", "line-us.local.", "127.0.0.1", running.port) in found


def keyboard_like_the_example(port: int) -> list[str]:
    """The keyboard example's traffic through the official module, its port set on the class as the module
    allows: G94 P50 (out of range, its reply ignored), then G01 with float Y and a few fixed X."""
    saved = lineus.LineUs._default_port
    lineus.LineUs._default_port = port
    arm = lineus.LineUs()
    try:
        assert arm.connect("127.0.0.1", timeout=50)
        assert arm.get_name() == "127.0.0.1"
        replies = [arm.send_gcode("G94", "P50")]
        for x, y in ((1000, 1216.6666666666667), (1200, -1550.0), (1300, 0.5)):
            replies.append(arm.g01(x, y, 0))
            replies.append(arm.g01(z=1000))
        replies.append(arm.send_gcode("M122"))
        return replies
    finally:
        arm.disconnect()
        arm.zeroconf.close()
        lineus.LineUs._default_port = saved


async def test_keyboard_example_traffic(lineus_sim) -> None:
    running = await lineus_sim(speed=100.0)
    replies = await asyncio.wait_for(asyncio.to_thread(keyboard_like_the_example, running.port), 60)
    assert replies[0].startswith("error INFO:")
    assert replies[1] == "ok X:1000.00 Y:1216.67 Z:0.00"
    assert all(r.startswith("ok X:") for r in replies[2:7])
    assert replies[-1].startswith("ok ChipID:")
    assert list(running.sim.received)[:2] == ["G94 P50", "G01  X1000 Y1216.6666666666667 Z0"]
