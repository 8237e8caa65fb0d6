"""Every form of device id (`fabwire.agent.core.DEVICE_IDS`): a real machine's id, whatever its serial or
address, is never one of the demo's, so a demo never takes a real machine's MQTT topics or history."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fabwire.agent.core import DEVICE_IDS, KINDS, demo_id, device_id, is_demo_id

from .agenttools import start_agent, wait_for

TEXT = st.text(st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=40)
MAKERS = {
    "KIND-SERIAL": lambda kind, text: device_id(kind, text if text.strip() else "demo", "10.0.0.5:9100"),
    "KIND-ADDRESS": lambda kind, text: device_id(kind, None, f"10.0.0.{len(text)}:{text}"),
    "KIND-HOST-ADDRESS": lambda kind, text: device_id(kind, None, f"127.0.0.1:{text}", host=text or "h"),
    "KIND-demo-HASH": lambda kind, text: device_id(kind, "demo", f"10.0.0.5:{text}"),
    "KIND-demo": lambda kind, text: demo_id(kind),
}


@pytest.mark.parametrize(("whose", "form", "source"), DEVICE_IDS, ids=[row[1] for row in DEVICE_IDS])
@given(kind=st.sampled_from(KINDS), text=TEXT)
def test_only_the_demos_ids_are_demo_ids(whose: str, form: str, source: str, kind: str, text: str) -> None:
    made = MAKERS[form](kind, text)
    assert made.startswith(kind)
    assert is_demo_id(made) == (form == "KIND-demo"), made
    assert made not in {demo_id(k) for k in KINDS} or form == "KIND-demo"


@pytest.mark.parametrize("kind", KINDS)
def test_a_machine_whose_serial_is_demo_is_not_the_demo(kind: str) -> None:
    made = device_id(kind, "demo", "10.0.0.5:9100")
    assert made.startswith(f"{kind}-demo-")
    assert made != demo_id(kind) == f"{kind}-demo"
    assert device_id(kind, "demo", "10.0.0.6:9100") != made  # two such machines keep two ids


def test_the_demos_ids_are_the_same_every_run(tmp_path: Path) -> None:
    """`/api/v1/devices/xyz-demo/…` reaches the demo's printer, in a real agent, as the README and scripts say."""
    agent = start_agent(tmp_path / "state", "--demo", "--speed", "30")
    try:
        with agent.client() as client:
            for kind in KINDS:
                found = wait_for(lambda k=kind: (r := client.get(f"/api/v1/devices/{k}-demo/state")).status_code
                                 == 200 and r.json(), f"the demo's {kind} by its id")
                assert found["device"] == demo_id(kind)
            assert client.get("/api/v1/jobs", params={"device": "xyz-demo"}).status_code == 200
    finally:
        code, stderr = agent.stop()
        assert code == 0, stderr
