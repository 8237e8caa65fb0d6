"""`SyncMMU`: the MMU client's operations, blocking, for plain scripts.

    with MMU.open_sync("sim://mmu?speed=50") as mmu:
        mmu.tool_change(2)

Each call runs on a private event-loop thread; `on_event` callbacks are called on that thread.
"""

from __future__ import annotations

from typing import Any

from fabwire.mmu import codes
from fabwire.mmu.client import MMU, EventCallback
from fabwire.mmu.host import CommandFinished, Link, Status
from fabwire.mmu.protocol import Request
from fabwire.opening import DeviceTarget, SyncClient


class SyncMMU(SyncClient[MMU]):
    """`MMU`'s operations with the same names and arguments, blocking until each is done."""

    def __init__(self, target: DeviceTarget = None, **options: Any) -> None:
        super().__init__(MMU.open(target, **options), thread_name="fabwire-mmu")

    @property
    def mmu(self) -> MMU:
        return self.client

    def status(self) -> Status:
        """The state the link's heartbeat (Q0 every second) keeps current: read, not asked for."""
        return self._call(self.mmu.status())

    def version(self) -> codes.FirmwareVersion:
        """The firmware version the handshake read (S0-S3)."""
        return self._call(self.mmu.version())

    @property
    def link_state(self) -> Link:
        return self.mmu.link_state

    def tool_change(self, slot: int, **kwargs: Any) -> CommandFinished:
        return self._call(self.mmu.tool_change(slot, **kwargs))

    def load(self, slot: int, **kwargs: Any) -> CommandFinished:
        return self._call(self.mmu.load(slot, **kwargs))

    def unload(self, **kwargs: Any) -> CommandFinished:
        return self._call(self.mmu.unload(**kwargs))

    def eject(self, slot: int, **kwargs: Any) -> CommandFinished:
        return self._call(self.mmu.eject(slot, **kwargs))

    def cut(self, slot: int, **kwargs: Any) -> CommandFinished:
        return self._call(self.mmu.cut(slot, **kwargs))

    def home(self, **kwargs: Any) -> CommandFinished:
        return self._call(self.mmu.home(**kwargs))

    def set_mode(self, stealth: bool, **kwargs: Any) -> CommandFinished:
        return self._call(self.mmu.set_mode(stealth, **kwargs))

    def run(self, request: Request, *, on_event: EventCallback | None = None, timeout: float | None = None,
            confirm_eject: bool = True) -> CommandFinished:
        return self._call(self.mmu.run(request, on_event=on_event, timeout=timeout, confirm_eject=confirm_eject))

    def follow(self, *, on_event: EventCallback | None = None, timeout: float | None = None,
               confirm_eject: bool = False) -> CommandFinished:
        return self._call(self.mmu.follow(on_event=on_event, timeout=timeout, confirm_eject=confirm_eject))

    def answer(self, choice: str, *, on_event: EventCallback | None = None,
               timeout: float | None = None) -> CommandFinished | None:
        return self._call(self.mmu.answer(choice, on_event=on_event, timeout=timeout))

    def press(self, button: int | str, timeout: float | None = 10.0) -> None:
        self._call(self.mmu.press(button, timeout))

    def refresh(self, timeout: float | None = 10.0) -> Status:
        return self._call(self.mmu.refresh(timeout))

    def read_register(self, register: int | str, timeout: float | None = 10.0) -> int:
        return self._call(self.mmu.read_register(register, timeout))

    def write_register(self, register: int | str, value: int, timeout: float | None = 10.0) -> int:
        return self._call(self.mmu.write_register(register, value, timeout))

    def reset(self, timeout: float | None = 30.0, *, erase: bool = False) -> codes.FirmwareVersion:
        return self._call(self.mmu.reset(timeout, erase=erase))
