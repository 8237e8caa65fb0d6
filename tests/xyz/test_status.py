"""Status parsing of real captures (mini w, nano fw 3.2.0, 1.0 Pro, 1.1 Plus) and rendering back to the wire."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fabwire.xyz.status import LETTERS, ErrorWord, Status

DATA = Path(__file__).parent / "data"


def capture(name: str) -> list[str]:
    lines = (DATA / name).read_text().split("\n")
    return [line for line in lines if line and line != "$"]


def test_mini_w_capture_fields() -> None:
    s = Status.parse(capture("mini_w_wifi.txt"))
    assert s.bed == 20
    assert s.calibration == ("336", "374", "377", "355", "373", "371", "364", "377", "356")
    assert s.progress is not None
    assert (s.progress.percent, s.progress.elapsed_min) == (0, 0)
    assert s.errors == (0,)
    assert s.error_words == ()
    assert s.filament_mm == 200000
    assert s.serial == "3FM1WPUS5CA6750022"
    assert (s.state_code, s.substate, s.state_name) == (9511, 0, "idle")
    assert s.lifetime is not None
    assert (s.lifetime.machine_min, s.lifetime.extruder_min, s.lifetime.last_min) == (
        301080, 28581, 66)
    assert s.block_size == 8192
    assert s.autolevel is True
    assert s.model_number == "dv1MW0A000"
    assert s.model is not None
    assert s.model.name == "da Vinci mini w"
    assert s.buzzer is True
    assert s.settings == {"fm": 0, "fd": 0, "sd": "yes", "button": "no", "buzzer": "on"}
    assert (s.extruder, s.extruder_target) == (22, 0)
    assert s.firmware_version == "1.2.3"
    assert s.name == "miniMaker"
    assert s.nozzle is not None
    assert s.nozzle.diameter_mm == 0.4
    assert s.language == "en"
    assert s.zoffset == 245
    assert s.wifi_firmware == "5.0.9"
    assert s.network is not None
    assert s.network.ip == "192.168.1.118"
    assert s.network.ssid == "TUCKER_HOME"
    assert s.network.rssi == 39
    assert s.network.signal_percent == 100
    assert s.network.connected
    assert s.cartridge is not None
    assert s.cartridge.present
    assert s.cartridge.colour == "Clear Tangerine"  # serial char 4 = 'Q'
    assert s.unparsed == {}
    assert s.extra == {}


def test_nano_fw3_capture_fields() -> None:
    s = Status.parse(capture("nano_fw320_usb.txt"))
    assert s.calibration is not None
    assert len(s.calibration) == 12
    assert s.zoffset == -469
    assert s.nozzle is not None
    assert s.nozzle.kind == "75"
    assert s.nozzle.diameter_mm == 0.3
    assert s.model is not None
    assert s.model.model_number == "dv1NX0A000"
    assert s.network is None
    assert s.wifi_firmware is None
    assert s.name == "daVinci Nano"
    assert s.firmware == ("3.2.0",)
    assert s.settings is not None
    assert s.settings["fd"] == 1


def test_pro_capture_fields() -> None:
    s = Status.parse(capture("pro_10.txt"))
    assert s.state == (9511, None)
    assert s.state_name == "idle"
    assert s.temperatures is not None
    assert s.extruder == 16
    assert s.temperatures.target is None
    assert s.extruder_target == 240  # from O:
    assert s.autolevel is False
    assert s.cartridge is not None
    assert not s.cartridge.present
    assert s.cartridge.colour is None
    assert s.doors_open == ()
    assert s.lifetime is not None
    assert s.lifetime.last_min is None


def test_plus_capture_fields() -> None:
    s = Status.parse(capture("plus_11.txt"))
    assert s.bed is None
    assert "b" not in s.unparsed
    assert s.state_code == 9511  # old code 10
    assert s.temperatures is not None
    assert s.temperatures.values == (None, None)
    assert s.firmware == ("1.1.0.19", "1.1.7.3", "N/A")
    assert s.network is not None
    assert s.network.ip == "192.168.1.126"
    assert not s.network.json_form
    assert s.packet is not None
    assert s.packet.autolevel is None
    assert s.packet.c == "0"
    assert s.filament == (1, 0)
    assert s.errors == (2,)
    assert s.error_words == ()  # the 1.1 Plus reports e:2 while idle: not an error
    assert Status.parse(["e:2"]).error_words[0].code == 0x0101  # on other models, old-style code 2


def test_material_and_wifi_scan_forms() -> None:
    assert Status.parse(["k:65"]).material_name == "ABS"  # XYZware reads the hex spelling
    assert Status.parse(["k:50"]).material_name == "PLA"
    assert Status.parse(["k:74"]).material_name is None
    one = Status.parse(['W:{"ssid":"a","bssid":"b","channel":"1","rssiValue":"40","PHY":"n","security":"x"}'])
    assert [n["ssid"] for n in one.wifi_networks] == ["a"]
    assert [n["ssid"] for n in Status.parse(['W:[{"ssid":"a"},{"ssid":"b"}]']).wifi_networks] == ["a", "b"]


@pytest.mark.parametrize("name", ["mini_w_wifi.txt", "nano_fw320_usb.txt", "pro_10.txt", "plus_11.txt"])
def test_render_round_trip(name: str) -> None:
    lines = capture(name)
    rendered = Status.parse(lines).lines()
    assert [r.rstrip() for r in rendered] == [line.rstrip() for line in lines]
    assert Status.parse(rendered).lines() == rendered


def test_name_is_padded_to_sixteen() -> None:
    assert Status(name="Office").lines() == ["n:Office          "]


def test_error_words() -> None:
    w = ErrorWord.decode(1073742342)
    assert (w.source, w.code, w.name) == ("extruder 1", 0x0206, "M_NO_CASSETTE")
    assert "cartridge" in w.meaning
    s = Status.parse(["e:1073742342,1073742345"])
    assert [e.code for e in s.error_words] == [0x0206, 0x0209]
    assert ErrorWord.decode(525).meaning.startswith("unsupported file version")


def test_remaining_unknown_sentinel_and_partial_update() -> None:
    s = Status.parse(["d:12,3,71582788", "j:9505,0"])
    assert s.progress is not None
    assert s.progress.remaining_min is None
    assert s.lines("d") == ["d:12,3,71582788"]
    s2 = s.update(["j:9509,0", "Q:new"])
    assert s2.state_code == 9509
    assert s2.progress == s.progress
    assert s2.extra == {"Q": "new"}


def test_bad_values_are_kept_not_fatal() -> None:
    s = Status.parse(["t:hot", "j:9511,0", "garbage", "s:{not json", "W:[{\"ssid\":\"x\"}]", "ok"])
    assert s.unparsed == {"t": "hot", "s": "{not json"}
    assert s.temperatures is None
    assert s.state_code == 9511
    assert s.networks == [{"ssid": "x"}]
    assert s.lines() == ["t:hot", "j:9511,0", "s:{not json", 'W:[{"ssid":"x"}]']


@given(st.lists(st.text(max_size=40), max_size=30))
def test_parse_is_total(lines: list[str]) -> None:
    s = Status.parse(lines)
    s.to_dict()
    assert isinstance(s.state_name, str)
    Status.parse(s.lines())


_HOSTILE_TEXT = st.lists(st.sampled_from(['"\\ud800"', '"\\udfff x"', '"\\u001b[31m"', "\x1b]0;t\x07", "\x00", "\x9b2J",
                                          '{"wlan":{"ssid":', "}", '"ok"', ",", "1e999", "[", "]", "\xff"]),
                         max_size=8).map("".join)


@given(st.sampled_from(sorted(LETTERS)), _HOSTILE_TEXT)
def test_what_a_status_keeps_can_always_be_written_and_never_drives_a_terminal(letter: str, value: str) -> None:
    status = Status.parse([f"{letter}:{value}", "j:9511,0"])
    shown = json.dumps(status.to_dict(), ensure_ascii=False)
    shown.encode("utf-8")  # no lone surrogate reached the output
    assert not any(ch in shown for ch in "\x00\x07\x1b\x9b")
    for attr in ("name", "serial", "language", "network"):
        str(getattr(status, attr)).encode("utf-8")


def test_a_lone_surrogate_in_a_json_field_keeps_the_line_raw() -> None:
    status = Status.parse(['4:{"wlan":{"ip":"1.2.3.4","ssid":"\\ud800"}}'])
    assert status.network is None
    assert status.to_dict()["raw"]["4"] == '{"wlan":{"ip":"1.2.3.4","ssid":"\\ud800"}}'
    assert Status.parse(["n:ab\x1b[2Jc"]).name == "ab\\x1b[2Jc"
