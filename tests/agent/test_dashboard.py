"""The dashboard in the distribution's Chromium, driven by Playwright, on a bench of simulators."""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from playwright.sync_api import Browser, Page, expect

from fabwire.samples import SAMPLE_GCODE, sample_path

from .agenttools import ARTIFACTS
from .conftest import Bench, start_bench, stop_bench

README_SCREENSHOT = Path(__file__).resolve().parents[2] / "docs" / "images" / "serve-dashboard.png"


@pytest.fixture
def bench(tmp_path: Path) -> Iterator[Bench]:
    """The printer heats slowly enough here that the page shows the climb, not just its end."""
    running = start_bench(tmp_path / "state", printer_speed="4")
    yield running
    stop_bench(running)


@pytest.fixture
def page(browser: Browser, bench: Bench) -> Iterator[Page]:
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    opened = context.new_page()
    opened.goto(bench.agent.url)
    expect(opened.locator("article.card")).to_have_count(3)
    for kind in ("xyz", "lineus", "mmu"):
        expect(opened.locator(f"article[data-kind={kind}] .online")).to_be_visible()
    yield opened
    context.close()


def shot(page: Page, name: str) -> Path:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    page.screenshot(path=str(path), full_page=True)
    return path


def card(page: Page, kind: str) -> object:
    return page.locator(f"article[data-kind={kind}]")


def test_page_shows_each_machine_in_words(page: Page) -> None:
    expect(page.locator("#link")).to_have_text("live")
    printer = page.locator("article[data-kind=xyz]")
    expect(printer.locator(".state")).to_have_text("idle")
    expect(printer.locator(".ident")).to_contain_text("da Vinci mini w")
    expect(printer.locator("svg.chart")).to_be_visible()
    expect(page.locator("article[data-kind=mmu] .slot")).to_have_count(5)
    expect(page.locator("article[data-kind=lineus] svg.drawing")).to_be_visible()
    shot(page, "dashboard-overview")


def test_temperatures_rise_during_a_print(page: Page) -> None:
    printer = page.locator("article[data-kind=xyz]")
    start = float(printer.locator(".temp-extruder").get_attribute("data-value") or 0)
    printer.locator("input[type=file]").set_input_files(str(sample_path(SAMPLE_GCODE)))
    printer.locator("button[data-action=upload]").click()
    expect(printer.locator(".progress")).to_be_visible(timeout=30_000)
    seen = [start]
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and seen[-1] < start + 100:
        value = printer.locator(".temp-extruder").get_attribute("data-value")
        if value:
            seen.append(float(value))
        time.sleep(0.3)
    assert seen[-1] >= start + 100, seen
    rising = sorted(set(seen))
    assert len(rising) >= 3, seen  # watched climbing, not jumping to the end
    points = printer.locator("svg.chart polyline.extruder").get_attribute("points") or ""
    assert len(points.split()) >= 3
    expect(printer.locator("svg.chart polyline.extruder-target")).to_have_count(1)
    shot(page, "dashboard-printing")


def test_lineus_drawing_appears_stroke_by_stroke(page: Page) -> None:
    arm = page.locator("article[data-kind=lineus]")
    arm.locator("input[type=text]").fill("fabwire")
    arm.locator("button[data-action=text]").click()
    planned = arm.locator("svg.drawing polyline.planned")
    expect(planned.first).to_be_attached(timeout=30_000)
    total = planned.count()
    assert total >= 5
    counts: list[int] = []
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline:
        counts.append(arm.locator("svg.drawing polyline.ink").count())
        if counts[-1] >= total:
            break
        time.sleep(0.05)
    assert counts[-1] == total, counts
    distinct = sorted(set(counts))
    assert counts == sorted(counts), counts  # ink only grows
    assert len([c for c in distinct if 0 < c < total]) >= 3, distinct  # strokes arrived one by one
    shot(page, "dashboard-drawing")


def test_mmu_fault_shows_its_error_and_retry_recovers(page: Page) -> None:
    mmu = page.locator("article[data-kind=mmu]")
    mmu.locator("button.slot[data-slot='0']").click()  # choose the slot, then what to do with it
    mmu.locator("button[data-action=tool_change][data-slot='0']").click()
    expect(mmu.locator(".state")).to_contain_text("T0 finished", timeout=30_000)
    mmu.locator("button.slot[data-slot='1']").click()
    mmu.locator("button[data-action=tool_change][data-slot='1']").click()
    error = mmu.locator("[role=alert]")
    explained = ("04101 FINDA DIDN'T TRIGGER (0x8001) during T1 — FINDA didn't trigger; check the filament path, "
                 "then Retry")
    expect(error).to_have_text(explained, timeout=30_000)
    expect(mmu.locator(".state")).to_have_attribute("data-state", "error")
    expect(mmu.locator(".state")).to_have_text(explained)
    expect(mmu.locator(".error-box")).to_have_count(1)  # the fault is said once, not once more in a box below
    assert mmu.inner_text().count("04101 FINDA DIDN'T TRIGGER") == 1
    expect(mmu.locator("button[data-action=stop]")).to_be_visible()
    shot(page, "dashboard-mmu-error")
    mmu.locator("button[data-action=retry]").click()
    expect(mmu.locator(".state")).to_contain_text("T1 finished", timeout=30_000)
    expect(error).to_have_count(0)
    expect(mmu.locator(".slot.active")).to_have_attribute("data-slot", "1")


def test_usable_on_a_phone(browser: Browser, bench: Bench) -> None:
    context = browser.new_context(viewport={"width": 390, "height": 844}, device_scale_factor=2, is_mobile=True,
                                  has_touch=True)
    phone = context.new_page()
    phone.goto(bench.agent.url)
    expect(phone.locator("article.card")).to_have_count(3)
    widths = phone.evaluate("[document.documentElement.scrollWidth, window.innerWidth]")
    assert widths[0] <= widths[1], widths  # nothing wider than the screen
    boxes = [phone.locator("article.card").nth(i).bounding_box() for i in range(3)]
    assert all(b is not None and b["width"] <= 390 for b in boxes)
    assert boxes[0]["y"] < boxes[1]["y"] < boxes[2]["y"]  # type: ignore[index]  # one column
    button = phone.locator("article[data-kind=mmu] button").first.bounding_box()
    assert button is not None
    assert button["height"] >= 36  # large enough for a finger
    shot(phone, "dashboard-phone")
    context.close()


def test_readme_screenshot(page: Page) -> None:
    """The picture in the README: a print heating, a drawing under way, the MMU stopped in an error."""
    page.locator("article[data-kind=xyz] input[type=file]").set_input_files(str(sample_path(SAMPLE_GCODE)))
    page.locator("article[data-kind=xyz] button[data-action=upload]").click()
    mmu = page.locator("article[data-kind=mmu]")
    mmu.locator("button.slot[data-slot='0']").click()  # choose the slot, then what to do with it
    mmu.locator("button[data-action=tool_change][data-slot='0']").click()
    expect(mmu.locator(".state")).to_contain_text("T0 finished", timeout=30_000)
    mmu.locator("button.slot[data-slot='1']").click()
    mmu.locator("button[data-action=tool_change][data-slot='1']").click()
    page.locator("article[data-kind=lineus] input[type=text]").fill("fabwire")
    page.locator("article[data-kind=lineus] button[data-action=text]").click()
    expect(mmu.locator(".error-box")).to_be_visible(timeout=30_000)
    expect(page.locator("article[data-kind=lineus] svg.drawing polyline.ink").nth(4)).to_be_attached(timeout=60_000)
    expect(page.locator("article[data-kind=xyz] .progress")).to_be_visible(timeout=30_000)
    time.sleep(3)  # a few seconds of temperature curve
    path = shot(page, "readme-dashboard")
    if os.environ.get("FABWIRE_UPDATE_README_SCREENSHOT"):
        README_SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, README_SCREENSHOT)
    assert path.stat().st_size > 20_000
