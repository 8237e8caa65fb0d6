"""The file library on its own: names, retention, persistence and what the intake says about a file, on an
in-process agent with an in-process da Vinci simulator (`sim://`)."""

from __future__ import annotations

import asyncio
import io
import json
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fabwire.agent.core import Agent, DeviceSpec
from fabwire.agent.library import NAME_MAX, FileNotInLibrary, clean_name
from fabwire.errors import InputError

from .doortools import prusaslicer_gcode


@given(st.text(max_size=300), st.text(max_size=60))
def test_a_library_name_never_leaves_the_library(name: str, folder: str) -> None:
    """Any name and folder a client sends gives a relative name without `.`/`..` parts, control characters or
    empty parts, at most NAME_MAX long, or InputError; nothing else."""
    try:
        cleaned = clean_name(name, folder)
    except InputError:
        return
    parts = cleaned.split("/")
    assert all(p and p not in (".", "..") and p == p.strip() for p in parts)
    assert not any(ord(c) < 32 or c == "\\" for c in cleaned)
    assert len(cleaned) <= NAME_MAX


@pytest.fixture
async def agent(tmp_path: Path) -> AsyncIterator[Agent]:
    async with Agent(state_dir=tmp_path / "state") as running:
        info = await running.add_device(DeviceSpec("desk", "xyz", "sim://"))
        for _ in range(100):
            if running.state(info.id)["summary"]["state"] == "idle":
                break
            await asyncio.sleep(0.1)
        yield running


async def test_kept_files_carry_the_intakes_figures_and_survive_a_restart(agent: Agent, tmp_path: Path) -> None:
    added = await agent.library.add("desk", "bracket.gcode", io.BytesIO(prusaslicer_gcode(minutes=12, seconds=30)))
    entry = added["file"]
    assert added["job"] is None
    assert entry["meta"] == {"print_time_s": 750, "filament_mm": pytest.approx(43.21), "layers": 3,
                             "slicer": "prusaslicer"}
    assert [(t["width"], t["height"]) for t in entry["thumbnails"]] == [(16, 16), (220, 124)]
    device_id = agent.session("desk").info.id
    index = json.loads((tmp_path / "state" / "library" / device_id / "index.json").read_text())
    assert index["files"]["bracket.gcode"]["sha256"] == entry["sha256"]
    fresh = type(agent.library)(agent, tmp_path / "state" / "library")
    assert fresh.get(device_id, "bracket.gcode")["meta"] == entry["meta"]


async def test_a_file_the_intake_refuses_is_not_kept(agent: Agent, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no commands"):
        await agent.library.add("desk", "empty.gcode", io.BytesIO(b"; only a comment\n"))
    device_id = agent.session("desk").info.id
    with pytest.raises(FileNotInLibrary):
        agent.library.get(device_id, "empty.gcode")
    assert list((tmp_path / "state" / "library" / device_id / "files").iterdir()) == []


async def test_the_oldest_files_go_beyond_the_limit_but_never_a_queued_one(agent: Agent, tmp_path: Path) -> None:
    agent.library.keep = 2
    device_id = agent.session("desk").info.id
    for name in ("a.gcode", "b.gcode"):
        await agent.library.add("desk", name, io.BytesIO(prusaslicer_gcode()))
    await agent.library.set_queue("desk", order=["a.gcode"])
    await agent.library.add("desk", "c.gcode", io.BytesIO(prusaslicer_gcode()))
    assert sorted(e["name"] for e in agent.library.files(device_id)) == ["a.gcode", "c.gcode"]
    await agent.library.add("desk", "c.gcode", io.BytesIO(prusaslicer_gcode(minutes=9)))  # replaced, not added
    assert len(agent.library.files(device_id)) == 2
    stored = list((tmp_path / "state" / "library" / device_id / "files").iterdir())
    assert len(stored) == 2


async def test_a_drawing_carries_its_plans_figures_and_picture(tmp_path: Path) -> None:
    """A Line-us's library shows a drawing's own figures (the planner's, as `lineus preview` gives them) and a
    picture of the plan, since an SVG carries no preview of its own."""
    from fabwire.lineus.plot import PlanOptions
    from fabwire.lineus.plot.intake import drawing_from_bytes
    from fabwire.lineus.plot.plan import plan_drawing

    svg = (b"<svg xmlns='http://www.w3.org/2000/svg' width='40mm' height='40mm' viewBox='0 0 40 40'>"
           b"<path d='M2 2 H38 V38 H2 Z M10 10 H30' fill='none' stroke='black'/></svg>")
    async with Agent(state_dir=tmp_path / "state") as running:
        info = await running.add_device(DeviceSpec("arm", "lineus", "sim://lineus?speed=inf"))
        for _ in range(100):
            if running.state(info.id)["online"]:
                break
            await asyncio.sleep(0.1)
        entry = (await running.library.add("arm", "square.svg", io.BytesIO(svg)))["file"]
        expected = plan_drawing(drawing_from_bytes("square.svg", svg), PlanOptions()).figures().as_dict()
        assert entry["meta"]["strokes"] == expected["strokes"] == 2
        assert entry["meta"]["pen_down_mm"] == pytest.approx(expected["pen_down_length_mm"])
        assert entry["meta"]["print_time_s"] == pytest.approx(expected["estimated_s"], rel=0.2)
        assert set(entry["meta"]) == {"print_time_s", "pen_down_mm", "strokes"}
        image, media = running.library.thumbnail(info.id, "square.svg")
        assert media == "image/png"
        assert image.startswith(b"\x89PNG\r\n\x1a\n")
        assert [(t["width"], t["height"]) for t in entry["thumbnails"]] == [
            (int.from_bytes(image[16:20], "big"), int.from_bytes(image[20:24], "big"))]
