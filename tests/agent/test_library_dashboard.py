"""The dashboard's library and queue view (static/library.js) in the distribution's Chromium, driven by
Playwright, on `fabwire serve --demo`: previews, figures, reprint, queue order, and a key request approved."""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from playwright.sync_api import Browser, Page, expect

from .agenttools import ARTIFACTS, RunningAgent, start_agent, wait_for
from .doortools import XYZ, multipart, printing, prusaslicer_gcode, wait_idle

README_SCREENSHOT = Path(__file__).resolve().parents[2] / "docs" / "images" / "serve-library.png"


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningAgent]:
    agent = start_agent(tmp_path_factory.mktemp("library") / "state", "--demo", "--speed", "30")
    yield agent
    agent.stop()


@pytest.fixture
def page(browser: Browser, demo: RunningAgent) -> Iterator[Page]:
    context = browser.new_context(viewport={"width": 1280, "height": 1100})
    opened = context.new_page()
    opened.goto(demo.url)
    yield opened
    context.close()


def keep(client: httpx.Client, name: str, data: bytes) -> None:
    body, ctype = multipart([("print", "false"), ("path", "")], name, data)
    assert client.post("/api/files/local", content=body, headers={"Content-Type": ctype}).status_code == 201


def test_library_and_queue_on_the_dashboard(demo: RunningAgent, page: Page) -> None:
    with demo.client() as client:
        wait_idle(client)
        keep(client, "bracket.gcode", prusaslicer_gcode(thumbs=[(16, 16, "png"), (120, 90, "png")], minutes=42))
        keep(client, "hook.gcode", prusaslicer_gcode(thumbs=[(96, 72, "qoi")], minutes=7))
        keep(client, "clip.gcode", prusaslicer_gcode(thumbs=[(96, 72, "jpg")], minutes=3))
        for name in ("hook.gcode", "clip.gcode"):
            assert client.post(f"/api/v1/devices/{XYZ}/queue", json={"name": name}).status_code == 200
    machine = page.locator(f".library-machine[data-device={XYZ}]")
    expect(machine.locator("tr[data-file]")).to_have_count(3)
    row = machine.locator("tr[data-file='bracket.gcode']")
    expect(row).to_contain_text("42 min")
    expect(row).to_contain_text("prusaslicer")
    for name in ("bracket.gcode", "hook.gcode", "clip.gcode"):  # PNG, QOI (shown as PNG) and JPG previews
        image = machine.locator(f"tr[data-file='{name}'] img.preview")
        expect(image).to_be_visible()
        wait_for(lambda image=image: image.evaluate("i => i.complete && i.naturalWidth > 0"), f"{name} preview drawn")
    expect(machine.locator(".queue-list li")).to_have_text(["hook.gcode ↑↓✕", "clip.gcode ↑↓✕"])
    machine.locator("li[data-queued='clip.gcode'] button[title=earlier]").click()
    expect(machine.locator(".queue-list li")).to_have_text(["clip.gcode ↑↓✕", "hook.gcode ↑↓✕"])
    # an application asks for a key; the owner approves it on the page
    with httpx.Client(base_url=demo.url.rstrip("/"), timeout=30) as anyone:
        asked = anyone.post("/plugin/appkeys/request", json={"app": "PrusaSlicer", "user": "owner"})
        assert asked.status_code == 201
        expect(page.locator(".key-request")).to_contain_text("PrusaSlicer (owner)")
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        shot = ARTIFACTS / "dashboard-library.png"
        page.screenshot(path=str(shot), full_page=True)
        if os.environ.get("FABWIRE_UPDATE_README_SCREENSHOT"):
            shutil.copyfile(shot, README_SCREENSHOT)
        page.locator(".key-request button", has_text="Approve").click()
        expect(page.locator(".key-request")).to_have_count(0)
        assert anyone.get(asked.headers["location"]).json()["api_key"]
    # reprint from the library, once the sample print the demo starts when its page is first opened has ended
    with demo.client() as client:
        wait_idle(client)
    expect(row.locator("button", has_text="Print")).to_be_enabled(timeout=30_000)
    row.locator("button", has_text="Print").click()
    with demo.client() as client:
        wait_for(lambda: printing(client), "printing bracket.gcode from the library")
        assert client.get("/api/v1/jobs", params={"device": XYZ}).json()[0]["filename"] == "bracket.gcode"
    expect(row.locator("button", has_text="Print")).to_be_disabled()
    machine.locator("li[data-queued='hook.gcode'] button[title='remove from the queue']").click()
    expect(machine.locator(".queue-list li")).to_have_text(["clip.gcode ↑↓✕"])


STAR_SVG = (b"<svg xmlns='http://www.w3.org/2000/svg' width='40mm' height='40mm' viewBox='0 0 40 40'>"
            b"<path d='M20 2 L25 15 L38 15 L27 23 L31 37 L20 28 L9 37 L13 23 L2 15 L15 15 Z' fill='none' "
            b"stroke='black'/></svg>")


def test_the_line_us_library_speaks_of_drawings(demo: RunningAgent, page: Page) -> None:
    machine = page.locator(".library-machine[data-device=lineus-demo]")
    expect(machine.locator("p.empty")).to_have_text(
        "No drawings yet: send an SVG or Line-us G-code to this machine's print-host address, "
        f"{demo.url.rstrip('/')}/printers/line-us.")
    with demo.client() as client:
        body, ctype = multipart([("print", "false"), ("path", "")], "star.svg", STAR_SVG)
        kept = client.post("/printers/line-us/api/files/local", content=body, headers={"Content-Type": ctype})
        assert kept.status_code == 201, kept.text
    row = machine.locator("tr[data-file='star.svg']")
    expect(row.locator("button", has_text="Draw")).to_have_count(1)
    expect(machine.locator("button", has_text="Print")).to_have_count(0)
    # a drawing's own figures and the plan's picture, never a 3D printer's columns left empty
    expect(machine.locator("th")).to_have_text(["Preview", "File", "Drawing time", "Pen down", "Strokes", "Size",
                                                "Draws", ""])
    cells = row.locator("td")
    expect(cells.nth(2)).to_have_text(re.compile(r"^\d+ s$"))  # the planner's drawing-time estimate
    expect(cells.nth(3)).to_have_text(re.compile(r"^\d+ mm$"))
    expect(cells.nth(4)).to_have_text("1")  # the star is one stroke
    image = row.locator("img.preview")
    wait_for(lambda: image.evaluate("i => i.complete && i.naturalWidth > 0"), "the plan's picture drawn")
    expect(machine.locator("label", has_text="Queue drawings sent while busy")).to_have_count(1)
