"""What the host logic reports: link state, the MMU's status as last polled, and typed events.

`fabwire.mmu.host.HostLogic` emits these; `fabwire.mmu.client.MMU` turns them into awaitable operations.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from fabwire.mmu import codes
from fabwire.mmu.errors import ErrorInfo, format_error


class Link(enum.Enum):
    CONNECTING = "connecting"
    READY = "ready"
    RESTARTING = "restarting"
    FAILED = "failed"
    """Version mismatch: the link is stopped until `start` is called again."""


@dataclass(frozen=True, slots=True)
class Status:
    command: str = ""
    """The command the MMU echoes in Q0 replies, e.g. 'T1' (X0 after boot)."""
    kind: str = ""
    """'P' running, 'E' error, 'F' finished, 'B' button."""
    value: int = 0
    finda: bool | None = None
    selector: int | None = None
    idler: int | None = None
    drive_errors: int | None = None
    pulley: int | None = None

    @property
    def words(self) -> str:
        if self.kind == "P":
            return codes.progress_words(self.value)
        if self.kind == "E":
            return format_error(self.value)
        if self.kind == "F":
            return "finished" if self.value == 0 else "cancelled"
        if self.kind == "B":
            return f"{codes.BUTTON_WORDS.get(self.value, self.value)} button pressed"
        return ""


# ------------------------------------------------------------------------------------------------ events


@dataclass(frozen=True, slots=True)
class LinkUp:
    version: codes.FirmwareVersion


@dataclass(frozen=True, slots=True)
class LinkLost:
    reason: str
    drop_outs: int


@dataclass(frozen=True, slots=True)
class LinkFailed:
    """Surfaced after the drop-out filter (or at once for a version mismatch)."""

    code: int
    info: ErrorInfo
    detail: str = ""


@dataclass(frozen=True, slots=True)
class ProgressChanged:
    command: str
    code: int

    @property
    def name(self) -> str:
        return codes.progress_name(self.code)

    @property
    def words(self) -> str:
        return codes.progress_words(self.code)


@dataclass(frozen=True, slots=True)
class ErrorRaised:
    command: str
    code: int
    info: ErrorInfo
    auto_retry: bool
    """The host is pressing Retry by itself; when False a person (or the caller) must act."""
    retries_left: int


@dataclass(frozen=True, slots=True)
class CommandFinished:
    command: str
    result: int


@dataclass(frozen=True, slots=True)
class CommandRejected:
    command: str
    attempts: int


@dataclass(frozen=True, slots=True)
class CommandInterrupted:
    """The MMU reported a different command finished (e.g. `X0 F0` after it rebooted)."""

    command: str
    reported: str


@dataclass(frozen=True, slots=True)
class ButtonPushed:
    command: str
    button: int


@dataclass(frozen=True, slots=True)
class RegisterRead:
    address: int
    value: int | None
    """None when the MMU rejected the read."""


@dataclass(frozen=True, slots=True)
class RegisterWritten:
    address: int
    value: int
    accepted: bool


@dataclass(frozen=True, slots=True)
class ButtonSent:
    button: int


@dataclass(frozen=True, slots=True)
class StatusUpdated:
    status: Status


HostEvent = (LinkUp | LinkLost | LinkFailed | ProgressChanged | ErrorRaised | CommandFinished | CommandRejected
             | CommandInterrupted | ButtonPushed | RegisterRead | RegisterWritten | ButtonSent | StatusUpdated)
