"""`LineUsSync`: the Line-us client's operations, blocking, for plain scripts.

    with LineUs.open_sync("line-us.local") as arm:
        arm.move(1000, 0)

Each call runs on a private event-loop thread.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from fabwire.lineus import protocol as p
from fabwire.lineus.client import LineUs, Network, Position, StoredDrawing
from fabwire.opening import DeviceTarget, SyncClient


class LineUsSync(SyncClient[LineUs]):
    """`LineUs`'s operations with the same names and arguments, blocking until the Line-us answers."""

    def __init__(self, target: DeviceTarget = None, **options: Any) -> None:
        super().__init__(LineUs.open(target, **options), thread_name="fabwire-lineus")

    @property
    def hello(self) -> p.Hello:
        return self.client.hello

    @property
    def arm(self) -> LineUs:
        return self.client

    # -- motion ---------------------------------------------------------------------------------------------------

    def move(self, x: float | None = None, y: float | None = None, z: float | None = None) -> Position:
        return self._call(self.client.move(x, y, z))

    def rapid(self, x: float | None = None, y: float | None = None, z: float | None = None) -> Position:
        return self._call(self.client.rapid(x, y, z))

    def move_uncalibrated(self, x: float | None = None, y: float | None = None, z: float | None = None,
                          keep: str | None = None) -> Position:
        return self._call(self.client.move_uncalibrated(x, y, z, keep))

    def pen_up(self) -> Position:
        return self._call(self.client.pen_up())

    def lift_after_stop(self) -> Position:
        return self._call(self.client.lift_after_stop())

    def pen_down(self, z: float = 0.0) -> Position:
        return self._call(self.client.pen_down(z))

    def home(self) -> Position:
        return self._call(self.client.home())

    def position(self) -> Position:
        return self._call(self.client.position())

    def set_speed(self, draw: float | None = None, travel: float | None = None) -> None:
        self._call(self.client.set_speed(draw, travel))

    def set_origin(self, x: float = 0.0, y: float = 0.0, scale: float = 1.0) -> None:
        self._call(self.client.set_origin(x, y, scale))

    # -- raw commands ---------------------------------------------------------------------------------------------

    def send(self, command: p.Command, *, timeout: float | None = None) -> p.Reply:
        return self._call(self.client.send(command, timeout=timeout))

    def request(self, command: p.Command, *, timeout: float | None = None) -> p.Reply:
        return self._call(self.client.request(command, timeout=timeout))

    def run(self, commands: Iterable[p.Command]) -> list[p.Reply]:
        return self._call(self.client.run(commands))

    # -- stored drawings ------------------------------------------------------------------------------------------

    def list_drawings(self) -> list[StoredDrawing]:
        return self._call(self.client.list_drawings())

    def save_drawing(self, slot: int, gcode: Sequence[str]) -> int:
        return self._call(self.client.save_drawing(slot, gcode))

    def delete_drawing(self, slot: int) -> None:
        self._call(self.client.delete_drawing(slot))

    def memory_drawing(self, mode: int, channel: str | None = None) -> None:
        self._call(self.client.memory_drawing(mode, channel))

    def timed_demo(self, seconds: float, period: float, drawing: int | None = None) -> None:
        self._call(self.client.timed_demo(seconds, period, drawing))

    def storage(self) -> dict[str, int]:
        return self._call(self.client.storage())

    # -- the machine ----------------------------------------------------------------------------------------------

    def name(self) -> str:
        return self._call(self.client.name())

    def set_name(self, name: str) -> None:
        self._call(self.client.set_name(name))

    def capabilities(self) -> dict[str, str]:
        return self._call(self.client.capabilities())

    def diagnostics(self) -> dict[str, str]:
        return self._call(self.client.diagnostics())

    def servo_angles(self) -> dict[str, float]:
        return self._call(self.client.servo_angles())

    def zmap(self) -> tuple[float, ...]:
        return self._call(self.client.zmap())

    def set_zmap(self, corners: tuple[float, float, float, float] | None) -> None:
        self._call(self.client.set_zmap(corners))

    def gestures(self, on: bool) -> None:
        self._call(self.client.gestures(on))

    def calibrate(self, *, clear: bool = False, confirm: bool = False) -> None:
        self._call(self.client.calibrate(clear=clear, confirm=confirm))

    def factory_reset(self, *, wipe_files: bool = False, confirm: bool = False) -> None:
        self._call(self.client.factory_reset(wipe_files=wipe_files, confirm=confirm))

    def firmware_update(self, *, confirm: bool = False) -> None:
        self._call(self.client.firmware_update(confirm=confirm))

    # -- Wi-Fi ----------------------------------------------------------------------------------------------------

    def wifi_networks(self) -> list[Network]:
        return self._call(self.client.wifi_networks())

    def add_wifi(self, ssid: str, password: str | None = None) -> None:
        self._call(self.client.add_wifi(ssid, password))

    def forget_wifi(self, ssid: str = "*") -> None:
        self._call(self.client.forget_wifi(ssid))
