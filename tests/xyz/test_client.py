"""XYZPrinter against the simulator over real TCP sockets and a real pty, every flow, plus injected link faults."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from fabwire.errors import DeviceBusy, DeviceError, InputError, LinkError, RemoteProtocolError
from fabwire.transport import FaultPlan, FaultyTransport, Transport, open_pty, serve_tcp
from fabwire.transport.serial import open_serial
from fabwire.transport.tcp import open_tcp
from fabwire.xyz.client import XYZPrinter
from fabwire.xyz.models import find_model
from fabwire.xyz.protocol import Link
from fabwire.xyz.sim import XYZSimulator
from fabwire.xyz.status import Status
from fabwire.xyz.sync import SyncXYZPrinter
from fabwire.xyz.threew import read_3w, write_3w

GCODE = b";TIME:600\n;LAYER_COUNT:3\n;Filament used: 0.25m\nG28\nG0 X10 Y10\nG1 X20 Y20 E1\nM84\n"
LIMIT = 30


class Rig:
    def __init__(self, sim: XYZSimulator, printer: XYZPrinter) -> None:
        self.sim = sim
        self.printer = printer


@pytest.fixture(params=["tcp", "pty"])
async def rig(request: pytest.FixtureRequest) -> AsyncIterator[Rig]:
    sim = XYZSimulator(speed=1000, gap=0.01)
    if request.param == "tcp":
        server = await serve_tcp(sim.serve, "127.0.0.1", 0)
        transport = await open_tcp("127.0.0.1", server.sockets[0].getsockname()[1])
        printer = XYZPrinter(transport)
        assert printer.link is Link.WIFI
        printer.poll_interval = 0.05
        yield Rig(sim, printer)
        await printer.close()
        server.close()
    else:
        device = open_pty()
        task = asyncio.create_task(sim.serve(device.transport))
        transport = await open_serial(device.path, 115200)
        printer = XYZPrinter(transport)
        assert printer.link is Link.SERIAL
        printer.poll_interval = 0.05
        yield Rig(sim, printer)
        await printer.close()
        task.cancel()
        await device.close()


async def test_status_and_config_changes_visible(rig: Rig) -> None:
    pr = rig.printer
    async with asyncio.timeout(LIMIT):
        st = await pr.status()
        assert st.model is not None
        assert st.model.name == "da Vinci mini w"
        assert st.idle
        await pr.set_buzzer(False)
        await pr.set_autolevel(False)
        await pr.set_zoffset(-469)
        await pr.set_name("Bench")
        await pr.set_language("de")
        await pr.set_energy(6)
        st = await pr.status()
        assert (st.buzzer, st.autolevel, st.zoffset, st.name, st.language) == (False, False, -469, "Bench", "de")
        assert rig.sim.printer.settings.energy == 6
        assert await pr.zoffset() == -469
        assert await pr.nudge_zoffset(True) == -468
        await pr.leave_wifi()
        assert not (await pr.wifi_info()).network.connected  # type: ignore[union-attr]
        await pr.join_wifi("lab", "password", 6)
        net = (await pr.wifi_info()).network
        assert net is not None
        assert net.ssid == "lab"
        await pr.restore_defaults()
        st = await pr.status()
        assert (st.buzzer, st.name, st.zoffset) == (True, "mini w", 245)


async def test_print_gcode_to_completion_byte_exact(rig: Rig, tmp_path: Path) -> None:
    src = tmp_path / "part.gcode"
    src.write_bytes(GCODE * 300)
    seen: list[int] = []
    states: list[int | None] = []
    async with asyncio.timeout(LIMIT):
        final = await rig.printer.print_file(src, progress=lambda done, total: seen.append(done),
                                             on_status=lambda s: states.append(s.state_code))
    assert final.state_code == 9509
    assert 9505 in states
    uploaded = rig.sim.uploads[-1]
    assert uploaded.complete
    assert uploaded.data == write_3w(GCODE * 300, find_model("dv1MW0A000"), filename="part.3w")
    assert read_3w(uploaded.data).gcode.endswith(b"M84\n")
    assert seen[-1] == len(uploaded.data)
    async with asyncio.timeout(LIMIT):
        await rig.printer.acknowledge()
        assert (await rig.printer.status()).idle


async def test_print_3w_pause_resume_cancel(rig: Rig) -> None:
    data = write_3w(b";TIME:100000\n" + GCODE, find_model("dv1MW0A000"))
    pr = rig.printer
    async with asyncio.timeout(LIMIT):
        st = await pr.print_file(data, wait=False, name="long.3w")
        assert st.state_code in (9520, 9505)
        await pr._wait_state(lambda s: s.state_code == 9505, "starting", 10)
        await pr.pause()
        assert (await pr.status()).state_code == 9601
        await pr.resume()
        assert (await pr.status()).state_code == 9505
        with pytest.raises(DeviceBusy, match="busy"):  # a state that passes: exit 4, the API's 409
            await pr.home()
        await pr.cancel()
        await pr._wait_state(lambda s: s.idle, "cancelling", 10)
    assert rig.sim.received("long.3w") == data


async def test_flows(rig: Rig) -> None:
    pr = rig.printer
    prompts: list[str] = []

    async def confirm(message: str) -> None:
        prompts.append(message)

    async with asyncio.timeout(LIMIT):
        assert (await pr.home()).idle
        assert (await pr.jog("z", -5)).idle
        assert (await pr.load_filament(confirm)).idle
        assert (await pr.unload_filament()).idle
        assert (await pr.clean_nozzle(confirm)).idle
        values = await pr.calibrate(confirm)
        assert len(values) == 9
        st = await pr.status()
        assert st.calibration == tuple(str(v) for v in values)
    assert len(prompts) == 4


async def test_load_cancelled_by_user_still_stops_feeding(rig: Rig) -> None:
    async def give_up(message: str) -> None:
        raise InputError("user gave up")

    async with asyncio.timeout(LIMIT):
        with pytest.raises(InputError):
            await rig.printer.load_filament(give_up)
        await rig.printer._wait_state(lambda s: s.idle, "stopping", 5)
    assert rig.sim.printer.target == 0


async def test_no_cartridge_is_a_device_error_in_words(rig: Rig) -> None:
    rig.sim.inject("no-cartridge")
    async with asyncio.timeout(LIMIT):
        with pytest.raises(DeviceError, match="no filament cartridge") as info:
            await rig.printer.print_file(GCODE)
        assert info.value.code == "0x40000206"
        st = await rig.printer.status()
        assert st.filament_mm is None
        assert st.cartridge is not None
        assert not st.cartridge.present


async def test_rejected_file_and_wrong_model(rig: Rig) -> None:
    pr = rig.printer
    pro = write_3w(GCODE, find_model("dv1JP0A000"))
    async with asyncio.timeout(LIMIT):
        with pytest.raises(InputError, match=r"Jr\. 1\.0 Pro"):
            await pr.print_file(pro)
        with pytest.raises(InputError, match="an image \\(PNG\\), not G-code"):
            await pr.print_file(b"\x89PNG\r\n\x1a\n" + bytes(100))
        with pytest.raises(InputError, match="sliced for"):
            await pr.print_file(b"; machine = dv1JP0A000\n" + GCODE)
        rig.sim.inject("file-rejected")
        with pytest.raises(DeviceError, match="rejected the file"):
            await pr.print_file(GCODE)


async def test_heater_failure_stops_the_load(rig: Rig) -> None:
    rig.sim.inject("heater-failure")

    async def confirm(message: str) -> None:
        return None

    async with asyncio.timeout(LIMIT):
        with pytest.raises(DeviceError, match="cannot reach its target"):
            await rig.printer.load_filament(confirm)


# ------------------------------------------------------------------------------------------- link faults


async def _faulty_client(sim: XYZSimulator, plan: FaultPlan) -> tuple[XYZPrinter, asyncio.Server]:
    server = await serve_tcp(sim.serve, "127.0.0.1", 0)
    transport = await open_tcp("127.0.0.1", server.sockets[0].getsockname()[1])
    printer = XYZPrinter(FaultyTransport(transport, plan), link=Link.WIFI)
    printer.poll_interval = 0.05
    return printer, server


async def test_split_writes_and_delayed_acks_still_upload_exactly() -> None:
    sim = XYZSimulator(speed=1000)
    printer, server = await _faulty_client(sim, FaultPlan(chunk=700, delay=0.002, seed=4))
    data = write_3w(GCODE * 200, find_model("dv1MW0A000"))
    try:
        async with asyncio.timeout(LIMIT):
            await printer.print_file(data, wait=False, name="split.3w")
    finally:
        await printer.close()
        server.close()
    assert sim.received("split.3w") == data


async def test_link_drop_mid_upload_is_a_clear_error_never_success() -> None:
    sim = XYZSimulator(speed=1000)
    printer, server = await _faulty_client(sim, FaultPlan(disconnect_after=30000, side="write"))
    data = write_3w(GCODE * 2000, find_model("dv1MW0A000"))
    try:
        async with asyncio.timeout(LIMIT):
            with pytest.raises(LinkError, match="did not receive the whole file"):
                await printer.print_file(data, name="drop.3w")
    finally:
        await printer.close()
        server.close()
    assert sim.received("drop.3w") is None


async def test_printer_side_link_drop_fault() -> None:
    sim = XYZSimulator(speed=1000, faults=("link-drop",))
    server = await serve_tcp(sim.serve, "127.0.0.1", 0)
    printer = XYZPrinter(await open_tcp("127.0.0.1", server.sockets[0].getsockname()[1]))
    try:
        async with asyncio.timeout(LIMIT):
            with pytest.raises(LinkError, match=r"upload of big\.3w failed"):
                await printer.print_file(write_3w(GCODE * 2000, find_model("dv1MW0A000")), name="big.3w")
    finally:
        await printer.close()
        server.close()


def test_sync_facade() -> None:
    with SyncXYZPrinter("sim://xyz?speed=1000&link=wifi") as printer:
        status = printer.status()
        assert isinstance(status, Status)
        assert status.idle
        printer.set_buzzer(False)
        assert printer.status().buzzer is False


async def test_firmware_upload_sends_the_image_without_its_header(rig: Rig) -> None:
    payload = bytes(range(256)) * 80
    async with asyncio.timeout(LIMIT):
        with pytest.raises(InputError, match="confirm"):
            await rig.printer.upload_firmware(b"dv1MW0A000+1.2.4" + payload, confirm=False)
        with pytest.raises(InputError, match="dv1NX0A000"):
            await rig.printer.upload_firmware(b"dv1NX0A000+3.2.1" + payload, confirm=True)
        result = await rig.printer.upload_firmware(b"dv1MW0A000+1.2.4" + payload, confirm=True)
    assert result.size == len(payload)
    assert rig.sim.printer.firmware_images == [payload]
    assert "firmware=temp.bin,20480" in rig.sim.commands


async def test_nano_fw3_print_rides_out_e7_e4_replies() -> None:
    sim = XYZSimulator("nano", speed=100, link=Link.SERIAL)
    device = open_pty()
    task = asyncio.create_task(sim.serve(device.transport))
    printer = XYZPrinter(FaultyTransport(await open_serial(device.path, 115200), FaultPlan(chunk=5, side="read")))
    printer.poll_interval = 0.02
    try:
        async with asyncio.timeout(LIMIT):
            final = await printer.print_file(b";TIME:60\n" + GCODE)
        assert final.state_code == 9509
        assert sim.busy_replies > 0
    finally:
        await printer.close()
        task.cancel()
        await device.close()


def test_usb_ports_are_filtered_by_vendor(monkeypatch: pytest.MonkeyPatch) -> None:
    import serialx

    from fabwire.xyz import discovery

    ports = [
        serialx.SerialPortInfo(device="/dev/ttyACM0", resolved_device="/dev/ttyACM0", vid=0x11F1, pid=0x2519,
                               serial_number="3FNAXPUS5TH7CM0041", manufacturer="XYZprinting", product="nano",
                               bcd_device=None, interface_description=None, interface_num=None, port_number=None),
        serialx.SerialPortInfo(device="/dev/ttyUSB0", resolved_device="/dev/ttyUSB0", vid=0x0403, pid=0x6001,
                               serial_number="X", manufacturer="FTDI", product="FT232", bcd_device=None,
                               interface_description=None, interface_num=None, port_number=None),
    ]
    monkeypatch.setattr(discovery.serialx, "list_serial_ports", lambda: ports)
    found = discovery.usb_printers()
    assert [(f.address, f.serial, f.detail) for f in found] == [
        ("/dev/ttyACM0", "3FNAXPUS5TH7CM0041", "da Vinci nano")]
    with pytest.raises(InputError, match="probe at most"):
        discovery.hosts_in("10.0.0.0/8")


async def test_reconnects_to_a_printer_that_hangs_up_after_every_reply() -> None:
    sim = XYZSimulator("1.1 Plus", speed=1000)
    assert sim.close_after_reply
    server = await serve_tcp(sim.serve, "127.0.0.1", 0)
    printer = await XYZPrinter.connect(f"127.0.0.1:{server.sockets[0].getsockname()[1]}")
    printer.poll_interval = 0.05
    data = write_3w(GCODE, find_model("dvF110B000"))
    try:
        async with asyncio.timeout(LIMIT):
            assert (await printer.status()).idle
            assert (await printer.status("j")).state == (10, None)  # a second connection, old-style idle code
            final = await printer.print_file(data, name="plus.3w")
        assert final.state_code == 9509
        assert final.state == (8, None)
        assert sim.received("plus.3w") == data
    finally:
        await printer.close()
        server.close()


async def test_fw3_raw_replies_wifi_scan_and_in_band_faults() -> None:
    sim = XYZSimulator("nano", speed=1000, link=Link.WIFI)
    server = await serve_tcp(sim.serve, "127.0.0.1", 0)
    printer = await XYZPrinter.connect(f"127.0.0.1:{server.sockets[0].getsockname()[1]}")
    try:
        async with asyncio.timeout(LIMIT):
            signature = await printer.signature()
            assert len(signature) == 32
            assert signature == await printer.signature()  # one fixed value per machine
            assert len(await printer.uid()) == 4
            assert await printer.tag_info() == "3FNAXPUS5TH7CM0041"
            assert await printer.sim_control("fault:no-cartridge:on") == ("no-cartridge",)
            assert (await printer.status()).errors == (0x40000206,)
            with pytest.raises(DeviceError, match="no filament cartridge"):
                await printer.home()
            assert await printer.sim_control("clear") == ()
            with pytest.raises(DeviceError, match="unknown fault"):
                await printer.sim_control("fault:gremlins:on")
            assert (await printer.status()).error_words == ()
    finally:
        await printer.close()
        server.close()


async def test_wifi_scan_and_fw3_commands_refused_by_older_firmware() -> None:
    sim = XYZSimulator("mini w", speed=1000)
    server = await serve_tcp(sim.serve, "127.0.0.1", 0)
    printer = await XYZPrinter.connect(f"127.0.0.1:{server.sockets[0].getsockname()[1]}")
    try:
        async with asyncio.timeout(LIMIT):
            networks = await printer.scan_wifi()
            assert "TUCKER_HOME" in [n["ssid"] for n in networks]
            assert "W" not in (await printer.status()).order  # a scan only when asked
            with pytest.raises(DeviceError):
                await printer.signature()
    finally:
        await printer.close()
        server.close()


async def test_plus_takes_only_status_and_prints() -> None:
    sim = XYZSimulator("1.1 Plus", speed=1000)
    server = await serve_tcp(sim.serve, "127.0.0.1", 0)
    printer = await XYZPrinter.connect(f"127.0.0.1:{server.sockets[0].getsockname()[1]}")
    try:
        async with asyncio.timeout(LIMIT):
            st = await printer.status()
            assert st.idle
            assert st.errors == (2,)
            assert st.error_words == ()
            with pytest.raises(DeviceError, match="only status"):
                await printer.set_buzzer(False)
            with pytest.raises(DeviceError, match="only status"):
                await printer.home()
            assert not any("buzzer" in c for c in sim.commands)
    finally:
        await printer.close()
        server.close()


async def test_a_peer_that_is_not_a_printer_is_named_as_such() -> None:
    async def http(transport: Transport) -> None:
        await transport.read()
        await transport.write(b"HTTP/1.0 400 Bad Request\r\n\r\n")
        await transport.close()

    server = await serve_tcp(http, "127.0.0.1", 0)
    printer = await XYZPrinter.connect(f"127.0.0.1:{server.sockets[0].getsockname()[1]}", timeout=2)
    try:
        async with asyncio.timeout(LIMIT):
            with pytest.raises(RemoteProtocolError, match=r"not an XYZv3 printer.*HTTP/1\.0 400"):
                await printer.status()
    finally:
        await printer.close()
        server.close()


class Writes(Transport):
    """The link as it is, with the size of every write the host makes."""

    def __init__(self, inner: Transport) -> None:
        self.inner, self.url, self.peer = inner, inner.url, inner.peer
        self.sizes: list[int] = []

    async def read(self, max_bytes: int = 65536) -> bytes:
        return await self.inner.read(max_bytes)

    async def write(self, data: bytes) -> None:
        self.sizes.append(len(data))
        await self.inner.write(data)

    async def close(self) -> None:
        await self.inner.close()


async def test_the_blocks_in_flight_go_out_in_one_write(rig: Rig) -> None:
    """A Wi-Fi upload writes the window's blocks at once, then as many as were acknowledged; a serial one writes
    block by block. The printer receives the file exactly either way."""
    printer = rig.printer
    window = printer.upload_window if printer.link is Link.WIFI else 1
    writes = Writes(printer.transport)
    printer.transport = writes
    data = bytes(range(256)) * 1000  # 32 blocks of 8 KiB, the last one short
    async with asyncio.timeout(LIMIT):
        result = await printer.upload(data, "blocks.3w")
    framed = [size for size in writes.sizes if size > 100]  # the blocks, not the commands around them
    assert framed[0] == window * (8192 + 12)
    assert sum(framed) == len(data) + 12 * result.blocks
    assert len(framed) <= result.blocks - window + 1
    assert rig.sim.received("blocks.3w") == data
