"""What tells one da Vinci model and firmware from another on the wire: the status letters and their order, quirks,
the file formats the firmware prints (reference §3 captures; the 1.1 Plus and 1.0 Pro from owners' captures)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from fabwire.xyz.models import FileFormat, PrinterModel, simulated_model
from fabwire.xyz.status import Nozzle


@dataclass(frozen=True, slots=True)
class Personality:
    """What tells one model and firmware from another on the wire."""

    model: PrinterModel
    serial: str
    firmware: tuple[str, ...]
    name: str
    order: str
    """Status letters of a `query=a` reply, in the order this firmware sends them."""
    nozzle: Nozzle
    cartridge: str = "PMP6QTH64R1093"
    second_cartridge: str | None = None
    """The second spool's tag on two-spool models (Jr. 2.0 Mix): `w:2,SN1,SN2` and `f:2,len1,len2`."""
    zoffset: int = 245
    calibration_tail: tuple[str, ...] = ()
    substates: bool = True
    """`j:9511,0` (True) or `j:9511` (1.0 Pro)."""
    target_in_t: bool = True
    """`t:1,22,0` (True) or `t:1,22` + an `O:` line (1.0 Pro)."""
    settings: tuple[tuple[str, Any], ...] = (("fm", 0), ("fd", 0), ("sd", "yes"), ("button", "no"), ("buzzer", "on"))
    accepts: tuple[FileFormat, ...] = ()
    """File formats the firmware prints; empty = the model's own."""
    accepts_gcode: bool = False
    wifi_firmware: str = "5.0.9"
    fw3: bool = False
    """Firmware 3.x extras: `taginfo`, `uid`, `signature` and the `Z:` letter."""
    old_states: bool = False
    """`j:10` idle, `j:11` printing…: the pre-95xx state codes (1.1 Plus)."""
    idle_errors: tuple[int, ...] = (0,)
    """`e:` while nothing is wrong (`e:2` on the 1.1 Plus)."""
    sensors: bool = True
    """False: `b:--` and `t:1,--,--` (the 1.1 Plus reports no temperatures over XYZv3)."""
    cartridge_tags: bool = True
    """False: `w:1,--------------` and `f:1,0` always (no NFC cartridge reading)."""
    packet_c: str = "1"
    autolevel_in_o: bool = True
    """`o:p8,t1,c1,a+` (True) or `o:p8,t1,c0` (1.1 Plus, no auto-level flag)."""
    network_json: bool = True
    """`4:{"wlan":{…}}` (True) or a bare `4:<ip>` (1.1 Plus)."""
    lifetime_last: bool = True
    status_and_upload_only: bool = False
    """Its XYZv3 covers status and printing only; every other config/action is refused."""
    ip: str = "192.168.1.118"
    lifetime: tuple[int, int] = (301080, 28581)
    """Machine and extruder lifetime minutes at power-on."""


_SEED_ORDER = "bcdwefijLmopstvnXlzV4"


def personality(model_text: str = "dv1MW0A000", *, serial: str | None = None) -> Personality:
    """The personality shipped for a model; an unknown model, or one that does not speak XYZv3, is an
    InputError (`simulated_model`)."""
    model = simulated_model(model_text)
    prefix = model.serial_prefixes[0] if model.serial_prefixes else "3FXXXX"
    generated = f"{prefix}US5SIM{sum(model.model_number.encode()) % 1000000:06d}"[:18]
    short = model.name.removeprefix("da Vinci ").strip()
    number = model.model_number
    if number == "dv1NX0A000":
        return Personality(
            model, serial or "3FNAXPUS5TH7CM0041", ("3.2.0",), "daVinci Nano", "bcdwefijLmopstvnXlz",
            Nozzle("75", ("GB-0002-0000-TH-7CG-0270-185",)), cartridge="GB9XZTH988P001", zoffset=-469,
            calibration_tail=("0.0", "0.0", "0.0"),
            settings=(("fm", 0), ("fd", 1), ("sd", "yes"), ("button", "no"), ("buzzer", "on")),
            accepts=(FileFormat.V2, FileFormat.V5), fw3=True,
        )
    if number in ("dvF1W0A000", "dvF1WSA000", "dv1SW0A000"):
        return Personality(
            model, serial or generated, ("1.3.8",), "daVinci Pro. 1w", "bdefijLmoOpstvwnlXzV4",
            Nozzle("77", ("GB-0002-0000-TH-68T-0250-00001",)), substates=False, target_in_t=False,
            settings=(("fm", 1), ("fd", 1), ("dr", {"top": "off", "front": "off"}), ("sd", "yes"), ("eh", "0"),
                      ("of", "1")),
            wifi_firmware="5.1.5",
        )
    if number == "dvF110B000":
        return Personality(
            model, serial or "3F11XPGBXTH5320151", ("1.1.0.19", "1.1.7.3", "N/A"), "da Vinci 1.1 Plus",
            "4befijLnoptvw", Nozzle("1", ()), substates=False, old_states=True, idle_errors=(2,), sensors=False,
            cartridge_tags=False, packet_c="0", autolevel_in_o=False, network_json=False, lifetime_last=False,
            status_and_upload_only=True, settings=(), ip="192.168.1.126", lifetime=(69342, 21785),
        )
    order = _SEED_ORDER if model.wifi else _SEED_ORDER.replace("V4", "")
    second = "PMP6PTH6840596" if model.dual_extruder else None  # two spools: the Jr. 2.0 Mix
    # XYZprint writes v5 files for the Jr line (a Jr. 1.0w file in the Rojman1984 samples; Jr 1.0 on firmware
    # 2.4.8 per mwiens' converter), so their firmware takes both.
    accepts = (FileFormat.V2, FileFormat.V5) if number.startswith(("dv1J", "dv2J")) and model.container == 2 else ()
    return Personality(model, serial or generated, ("1.2.3",), short[:16], order,
                       Nozzle("2", ("GB-0002-0000-TH-68T-0250-28727",)), accepts=accepts, second_cartridge=second)
