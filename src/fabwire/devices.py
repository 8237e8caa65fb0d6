"""The device kinds fabwire speaks to, with the link defaults each one implies."""

from __future__ import annotations

import msgspec


class DeviceKind(msgspec.Struct, frozen=True):
    name: str
    title: str
    default_port: int | None
    """TCP port used when a bare host is given; None when the device has no network link."""
    baudrate: int
    sim_module: str
    """Module whose import registers the in-process simulator for `sim://<name>`."""
    article: str = "a"
    """The indefinite article said before the title: "an XYZprinting da Vinci", "a Line-us"."""

    @property
    def a_title(self) -> str:
        """The title with its article, as a sentence says it: "an XYZprinting da Vinci"."""
        return f"{self.article} {self.title}"


XYZ = DeviceKind("xyz", "XYZprinting da Vinci", 9100, 115200, "fabwire.xyz.sim", "an")
LINEUS = DeviceKind("lineus", "Line-us", 1337, 115200, "fabwire.lineus.sim")
MMU = DeviceKind("mmu", "Prusa MMU3", None, 115200, "fabwire.mmu.sim")

KINDS: dict[str, DeviceKind] = {kind.name: kind for kind in (XYZ, LINEUS, MMU)}
