"""The version check at the start of every MMU link: S0-S3, exact match of major, minor and revision.

Reference §6.1 (`MK3:Firmware/mmu2_protocol_logic.cpp` `ProcessVersionResponse`): a reply that does not answer
the `S` just sent is asked again at no cost; a version byte no accepted version has costs one of 6 tries shared
by the whole sequence; then the link stops with VERSION_MISMATCH (04504). S3 (the build) is stored, not checked.
"""

from __future__ import annotations

from collections.abc import Iterable

from fabwire.mmu.codes import FirmwareVersion
from fabwire.mmu.protocol import Accepted, Response, Version

VERSION_RETRIES = 6


class Handshake:
    """One run of S0..S3. `step(response)` says what to do next: a request to send, the version, or a refusal."""

    def __init__(self, accepted: Iterable[tuple[int, int, int]]) -> None:
        self.accepted = sorted(set(accepted))
        self.stage = 0
        self.version: list[int] = []
        self.retries = VERSION_RETRIES

    @property
    def request(self) -> Version:
        return Version(self.stage)

    def step(self, response: Response) -> Version | FirmwareVersion | str:
        """The next `S` to send (the same one to ask again), the firmware version when done, or why it failed."""
        if not response.answers(self.request) or not isinstance(response, Accepted):
            return self.request
        value = response.number
        if self.stage == 3:
            major, minor, revision = self.version
            return FirmwareVersion(major, minor, revision, value)
        wanted = {v[self.stage] for v in self.accepted if list(v[: self.stage]) == self.version}
        if value not in wanted:
            self.retries -= 1
            if self.retries <= 0:
                parts = [*self.version, value]
                got = ".".join([*(str(v) for v in parts), *("x" * (3 - len(parts)))])
                return (f"MMU firmware {got} is not one of "
                        f"{', '.join('.'.join(map(str, v)) for v in self.accepted)}")
            return self.request
        self.version.append(value)
        self.stage += 1
        return self.request
