"""`SyncXYZPrinter`: every `XYZPrinter` operation, blocking, for plain scripts.

    with XYZPrinter.open_sync("192.168.1.50") as printer:
        print(printer.status().state_name)

Prompts (`ready`, `prompt`) are plain functions here: they run on a worker thread while the link stays alive.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from fabwire.opening import DeviceTarget, SyncClient
from fabwire.xyz.client import StatusCallback, UploadProgress, UploadResult, XYZPrinter
from fabwire.xyz.models import PrinterModel
from fabwire.xyz.protocol import Command, Reply
from fabwire.xyz.status import Status

SyncPrompt = Callable[[str], object]


def _async_prompt(prompt: SyncPrompt) -> Callable[[str], Any]:
    async def ask(message: str) -> None:
        await asyncio.to_thread(prompt, message)

    return ask


class SyncXYZPrinter(SyncClient[XYZPrinter]):
    def __init__(self, target: DeviceTarget = None, **options: Any) -> None:
        super().__init__(XYZPrinter.open(target, **options), thread_name="fabwire-xyz")

    def request(self, command: Command, *, timeout: float | None = None) -> Reply:
        return self._call(self.client.request(command, timeout=timeout))

    def status(self, letters: str = "a") -> Status:
        return self._call(self.client.status(letters))

    def monitor(self, interval: float = 1.0, count: int | None = None) -> Iterator[Status]:
        """Poll every `interval` s, `count` times (for ever without)."""
        polls = self.client.monitor(interval, count)

        async def next_poll() -> Status | None:
            return await anext(polls, None)

        while (status := self._call(next_poll())) is not None:
            yield status

    def model(self) -> PrinterModel:
        return self._call(self.client.model())

    def require_idle(self, doing: str, command: Command | None = None) -> Status:
        return self._call(self.client.require_idle(doing, command))

    def prepare(self, source: Path | bytes, model: PrinterModel, *, override: bool = False) -> bytes:
        return self.client.prepare(source, model, override=override)

    def upload(self, data: bytes | Path, name: str, *, progress: UploadProgress | None = None,
               firmware: bool = False, crc: bool = True, save_to_sd: bool = False) -> UploadResult:
        return self._call(self.client.upload(data, name, progress=progress, firmware=firmware, crc=crc,
                                             save_to_sd=save_to_sd))

    def print_file(self, source: Path | bytes, *, model: PrinterModel | None = None,
                   progress: UploadProgress | None = None, on_status: StatusCallback | None = None,
                   wait: bool = True, name: str | None = None, save_to_sd: bool = False,
                   start_limit: float = 30.0, on_note: Callable[[str], None] | None = None,
                   force: bool = False) -> Status:
        return self._call(self.client.print_file(source, model=model, progress=progress, on_status=on_status,
                                                 wait=wait, name=name, save_to_sd=save_to_sd,
                                                 start_limit=start_limit, on_note=on_note, force=force))

    def follow_job(self, on_status: StatusCallback | None = None, *, limit: float | None = None,
                   on_note: Callable[[str], None] | None = None) -> Status:
        return self._call(self.client.follow_job(on_status, limit=limit, on_note=on_note))

    def pause(self) -> None:
        self._call(self.client.pause())

    def resume(self) -> None:
        self._call(self.client.resume())

    def cancel(self, *, confirm: Callable[[], None] | None = None) -> None:
        self._call(self.client.cancel(confirm=confirm))

    def acknowledge(self) -> None:
        self._call(self.client.acknowledge())

    def home(self, *, limit: float = 120.0) -> Status:
        return self._call(self.client.home(limit=limit))

    def jog(self, axis: str, distance: float, *, limit: float = 120.0) -> Status:
        return self._call(self.client.jog(axis, distance, limit=limit))

    def load_filament(self, ready: SyncPrompt, *, on_status: StatusCallback | None = None, retry: bool = False,
                      limit: float = 360.0) -> Status:
        return self._call(self.client.load_filament(_async_prompt(ready), on_status=on_status, retry=retry,
                                                    limit=limit))

    def cancel_flow(self, flow: str) -> None:
        self._call(self.client.cancel_flow(flow))

    def unload_filament(self, *, on_status: StatusCallback | None = None, retry: bool = False,
                        limit: float = 360.0) -> Status:
        return self._call(self.client.unload_filament(on_status=on_status, retry=retry, limit=limit))

    def clean_nozzle(self, ready: SyncPrompt, *, on_status: StatusCallback | None = None,
                     limit: float = 360.0) -> Status:
        return self._call(self.client.clean_nozzle(_async_prompt(ready), on_status=on_status, limit=limit))

    def calibrate(self, prompt: SyncPrompt, *, on_status: StatusCallback | None = None,
                  on_stop: Callable[[str], None] | None = None, limit: float = 240.0) -> tuple[int, ...]:
        return self._call(self.client.calibrate(_async_prompt(prompt), on_status=on_status, on_stop=on_stop,
                                                limit=limit))

    def set_autolevel(self, on: bool) -> None:
        self._call(self.client.set_autolevel(on))

    def set_buzzer(self, on: bool) -> None:
        self._call(self.client.set_buzzer(on))

    def zoffset(self) -> int:
        return self._call(self.client.zoffset())

    def set_zoffset(self, value: int) -> int:
        return self._call(self.client.set_zoffset(value))

    def nudge_zoffset(self, up: bool) -> int:
        return self._call(self.client.nudge_zoffset(up))

    def set_name(self, name: str) -> None:
        self._call(self.client.set_name(name))

    def set_language(self, code: str) -> None:
        self._call(self.client.set_language(code))

    def set_energy(self, minutes: int) -> None:
        self._call(self.client.set_energy(minutes))

    def restore_defaults(self) -> None:
        self._call(self.client.restore_defaults())

    def wifi_info(self) -> Status:
        return self._call(self.client.wifi_info())

    def scan_wifi(self) -> list[dict[str, Any]]:
        return self._call(self.client.scan_wifi())

    def tag_info(self) -> str:
        return self._call(self.client.tag_info())

    def signature(self) -> bytes:
        return self._call(self.client.signature())

    def uid(self) -> bytes:
        return self._call(self.client.uid())

    def sim_control(self, op: str) -> tuple[str, ...]:
        return self._call(self.client.sim_control(op))

    def join_wifi(self, ssid: str, password: str, channel: int = 0) -> None:
        self._call(self.client.join_wifi(ssid, password, channel))

    def leave_wifi(self) -> None:
        self._call(self.client.leave_wifi())

    def upload_firmware(self, image: bytes, *, confirm: bool, progress: UploadProgress | None = None,
                        name: str = "temp.bin") -> UploadResult:
        return self._call(self.client.upload_firmware(image, confirm=confirm, progress=progress, name=name))
