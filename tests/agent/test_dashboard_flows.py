"""Every maintenance flow on the dashboard, in the distribution's Chromium on desktop and phone sizes, on a bench of
simulators: what the page shows, what it asks first, and what the machines did (through the agent's API)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from playwright.sync_api import Browser, Dialog, Page, expect

from clitools import cli_env

from .agenttools import ANNOUNCEMENT, device_of, summary, wait_for
from .conftest import Bench, start_bench, stop_bench
from .test_dashboard import shot

DOCS = Path(__file__).resolve().parents[2] / "docs" / "images"
MMU_STEP_MS = 120_000
"""A load or eject on the simulated MMU takes seconds; a machine shared with other test runs may stretch that."""
DESKTOP = {"width": 1280, "height": 900}
PHONE = {"width": 390, "height": 844}
NOTED_SVG = (b'<svg xmlns="http://www.w3.org/2000/svg" width="60mm" height="40mm" viewBox="0 0 60 40">'
             b'<path d="M5 5 L55 5 L55 35 L5 35 Z" fill="none" stroke="black"/>'
             b'<foreignObject x="10" y="10" width="20" height="9"><p xmlns="http://www.w3.org/1999/xhtml">not drawn</p>'
             b'</foreignObject></svg>')
"""A drawing whose foreignObject (HTML) the planner leaves out (and says so)."""


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Bench]:
    """One bench for the module: each test leaves the machines idle for the next."""
    running = start_bench(Path(tmp_path_factory.mktemp("flows")) / "state")
    yield running
    stop_bench(running)


@pytest.fixture(params=["desktop", "phone"])
def page(request: pytest.FixtureRequest, browser: Browser, bench: Bench) -> Iterator[Page]:
    size = DESKTOP if request.param == "desktop" else PHONE
    context = browser.new_context(viewport=size, is_mobile=request.param == "phone",
                                  has_touch=request.param == "phone")
    opened = context.new_page()
    opened.answers = []  # type: ignore[attr-defined]  # what each question asked said, in order
    opened.on("dialog", lambda dialog: _answer(opened, dialog))
    opened.goto(bench.agent.url)
    expect(opened.locator("article.card")).to_have_count(3)
    for kind in ("xyz", "lineus", "mmu"):
        expect(opened.locator(f"article[data-kind={kind}] .online")).to_be_visible()
    yield opened
    widths = opened.evaluate("[document.documentElement.scrollWidth, window.innerWidth]")
    assert widths[0] <= widths[1], widths  # after every flow: nothing wider than the screen
    context.close()


def readme_picture(path: Path, name: str | None = None) -> None:
    """With FABWIRE_UPDATE_README_SCREENSHOT set, the picture becomes the README's (docs/images/NAME.png)."""
    if os.environ.get("FABWIRE_UPDATE_README_SCREENSHOT"):
        DOCS.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, DOCS / f"{name or path.stem}.png")


def _answer(page: Page, dialog: Dialog) -> None:
    page.answers.append(dialog.message)  # type: ignore[attr-defined]
    if getattr(page, "refuse", False):
        dialog.dismiss()
    else:
        dialog.accept()


def api(bench: Bench) -> httpx.Client:
    return bench.agent.client()


def idle_printer(bench: Bench) -> str:
    with api(bench) as client:
        printer = device_of(client, "xyz")["id"]
        if summary(client, printer)["state"] == "done":
            client.post(f"/api/v1/devices/{printer}/actions/acknowledge", json={})
        wait_for(lambda: summary(client, printer)["state"] == "idle", "the printer idle")
    return printer


def events(bench: Bench, device: str) -> list[dict[str, Any]]:
    with api(bench) as client:
        return list(client.get(f"/api/v1/devices/{device}/history").json()["events"])


def done_actions(bench: Bench, device: str) -> list[str]:
    return [e["event"].get("action") for e in events(bench, device)
            if e["type"] == "event" and e["event"].get("event") == "action-done"]


def test_calibrate_asks_first_turns_its_prompts_into_buttons_and_shows_the_map(page: Page, bench: Bench) -> None:
    idle_printer(bench)
    printer = page.locator("article[data-kind=xyz]")
    printer.locator("button[data-action=calibrate]").click()
    assert "lower and raise the detector" in page.answers[-1]  # type: ignore[attr-defined]
    prompt = printer.locator(".prompt")
    expect(prompt).to_contain_text("Lower the calibration detector", timeout=30_000)
    prompt.locator("button[data-action=confirm]", has_text="Detector lowered").click()
    expect(prompt).to_contain_text("Raise the calibration detector", timeout=30_000)
    picture = shot(page, f"flow-calibrate-prompt-{page.viewport_size['width']}")  # type: ignore[index]
    if page.viewport_size == DESKTOP:
        readme_picture(picture, "serve-calibrate")
    prompt.locator("button[data-action=confirm]", has_text="Detector raised").click()
    expect(prompt).to_have_count(0, timeout=30_000)
    cells = printer.locator(".calmap .cell")
    expect(cells).to_have_count(9, timeout=30_000)
    with api(bench) as client:
        state = client.get(f"/api/v1/devices/{device_of(client, 'xyz')['id']}/state").json()
    assert [int(cells.nth(i).inner_text()) for i in range(9)] == state["status"]["calibration"]
    expect(printer.locator(".state")).to_have_attribute("data-state", "idle", timeout=30_000)


def test_load_filament_shows_the_printers_words_and_waits_for_the_filament(page: Page, bench: Bench) -> None:
    printer_id = idle_printer(bench)
    printer = page.locator("article[data-kind=xyz]")
    printer.locator("button[data-action=load_filament]").click()
    assert "heats" in page.answers[-1]  # type: ignore[attr-defined]
    expect(printer.locator(".state")).to_contain_text("load", timeout=30_000)  # the printer's progress words
    button = printer.locator(".prompt button[data-action=confirm]")
    expect(button).to_have_text("Filament comes out", timeout=60_000)
    button.click()
    expect(printer.locator(".state")).to_have_attribute("data-state", "idle", timeout=60_000)
    wait_for(lambda: "load_filament" in done_actions(bench, printer_id), "the load finishing")


def test_clean_nozzle_can_be_stopped_at_its_prompt(page: Page, bench: Bench) -> None:
    idle_printer(bench)
    printer = page.locator("article[data-kind=xyz]")
    printer.locator("button[data-action=clean_nozzle]").click()
    expect(printer.locator(".prompt button[data-action=confirm]")).to_have_text("Nozzle is clean", timeout=60_000)
    printer.locator(".prompt button[data-action=stop_flow]").click()
    assert "cancels it" in page.answers[-1]  # type: ignore[attr-defined]
    expect(printer.locator(".prompt")).to_have_count(0, timeout=30_000)
    expect(page.locator(".toast.bad")).to_contain_text("stopped at", timeout=30_000)
    expect(printer.locator(".state")).to_have_attribute("data-state", "idle", timeout=60_000)


def test_a_refused_question_sends_nothing(page: Page, bench: Bench) -> None:
    idle_printer(bench)
    sent: list[str] = []
    page.on("request", lambda request: sent.append(request.url) if "/actions/" in request.url else None)
    page.refuse = True  # type: ignore[attr-defined]
    printer = page.locator("article[data-kind=xyz]")
    for action in ("calibrate", "load_filament", "clean_nozzle", "home"):
        printer.locator(f"button[data-action={action}]").click()
    mmu = page.locator("article[data-kind=mmu]")
    mmu.locator("button.slot[data-slot='3']").click()
    for action in ("eject", "cut"):
        mmu.locator(f"button[data-action={action}][data-slot='3']").click()
    assert len(page.answers) == 6  # type: ignore[attr-defined]
    assert "slot 3" in page.answers[-1]  # type: ignore[attr-defined]
    page.refuse = False  # type: ignore[attr-defined]
    with page.expect_request_finished(lambda r: "/actions/" in r.url):
        printer.locator("button[data-action=zoffset_step][data-direction=up]").click()  # a question-free action …
    assert [u.rsplit("/", 1)[1] for u in sent] == ["zoffset_step"]  # … is the only request


def test_z_offset_up_down_and_set_in_mm(page: Page, bench: Bench) -> None:
    idle_printer(bench)
    printer = page.locator("article[data-kind=xyz]")
    value = printer.locator(".zoffset-value")
    expect(value).to_have_text(re.compile(r"^-?\d+\.\d\d mm$"), timeout=30_000)
    # from a known value: an earlier test's step may still be on its way to the printer
    printer.locator("input.zoffset-input").fill("1.00")
    printer.locator("button[data-action=zoffset]").click()
    expect(value).to_have_text("1.00 mm", timeout=30_000)
    before = 1.0
    printer.locator("button[data-action=zoffset_step][data-direction=up]").click()
    expect(value).to_have_text(f"{before + 0.01:.2f} mm", timeout=30_000)
    printer.locator("button[data-action=zoffset_step][data-direction=down]").click()
    expect(value).to_have_text(f"{before:.2f} mm", timeout=30_000)
    printer.locator("input.zoffset-input").fill("1.37")
    printer.locator("button[data-action=zoffset]").click()
    assert "1.37 mm" in page.answers[-1]  # type: ignore[attr-defined]
    expect(value).to_have_text("1.37 mm", timeout=30_000)


def test_jog_pad_and_home(page: Page, bench: Bench) -> None:
    printer_id = idle_printer(bench)
    printer = page.locator("article[data-kind=xyz]")
    already = done_actions(bench, printer_id).count("jog")
    printer.locator("select.jog-step").select_option("10")
    for axis, sign in (("x", "+"), ("y", "-"), ("z", "+")):
        printer.locator(f"button[data-action=jog][data-axis={axis}][data-sign='{sign}']").click()
        wait_for(lambda n=already: done_actions(bench, printer_id).count("jog") > n, f"the {axis} jog")
        already += 1
    jogs = [e["event"] for e in events(bench, printer_id) if e["type"] == "event"
            and e["event"].get("action") == "jog"]
    assert len(jogs) >= 3
    homes = done_actions(bench, printer_id).count("home")
    printer.locator("button[data-action=home]").click()
    assert "move" in page.answers[-1]  # type: ignore[attr-defined]
    wait_for(lambda: done_actions(bench, printer_id).count("home") > homes, "homing")


@pytest.mark.timeout(600)  # up to three MMU steps on a loaded machine
def test_mmu_one_row_of_slots_and_actions_for_the_chosen_one(page: Page, bench: Bench) -> None:
    mmu = page.locator("article[data-kind=mmu]")
    numbered = mmu.locator("button").filter(has_text=re.compile(r"^\s*\d\s*$"))
    expect(numbered).to_have_count(5)  # the slots are the only numbered buttons
    # in one go: the card may be drawn anew between two separate reads (it follows the MMU's state)
    tops = set(numbered.evaluate_all("buttons => buttons.map(b => Math.round(b.getBoundingClientRect().top))"))
    assert len(tops) == 1  # in one row
    with api(bench) as client:
        mmu_id = device_of(client, "mmu")["id"]
        wait_for(lambda: summary(client, mmu_id)["state"] in ("idle", "error"), "the MMU free")
        if summary(client, mmu_id)["state"] == "error":  # an earlier test's fault: Retry re-runs the check, which
            client.post(f"/api/v1/devices/{mmu_id}/actions/retry", json={})  # passes now (the fault fires once)
        wait_for(lambda: summary(client, mmu_id)["state"] == "idle", "the MMU idle", timeout=90)
    mmu.locator("button.slot[data-slot='2']").click()
    expect(mmu.locator("button.slot[data-slot='2']")).to_have_attribute("aria-pressed", "true")
    mmu.locator("button[data-action=load][data-slot='2']").click()
    finished = mmu.locator(".state", has_text="L2 finished")
    expect(finished.or_(mmu.locator(".error-box")).first).to_be_visible(timeout=MMU_STEP_MS)
    if not finished.count():  # the bench's MMU fails one feed to FINDA: Retry heals it
        mmu.locator("button[data-action=retry]").click()
        expect(mmu.locator(".state")).to_contain_text("L2 finished", timeout=MMU_STEP_MS)
    mmu.locator("button[data-action=eject][data-slot='2']").click()
    assert "slot 2" in page.answers[-1]  # type: ignore[attr-defined]
    expect(mmu.locator(".state")).to_contain_text("E2 finished", timeout=MMU_STEP_MS)


def test_lineus_pen_height_and_stored_drawings(page: Page, bench: Bench) -> None:
    arm = page.locator("article[data-kind=lineus]")
    with api(bench) as client:
        arm_id = device_of(client, "lineus")["id"]
        wait_for(lambda: summary(client, arm_id)["state"] == "idle", "the Line-us idle")
        height = arm.locator("input.pen-height")
        height.evaluate("(el) => { el.value = 450; el.dispatchEvent(new Event('input')); }")
        expect(arm.locator(".pen-height-value")).to_have_text("450")
        arm.locator("button[data-action=pen_height]").click()
        wait_for(lambda: (summary(client, arm_id)["position"] or {}).get("z") == 450, "the pen at 450")
        listed = client.post(f"/api/v1/devices/{arm_id}/actions/list_drawings", json={}).json()["drawings"]
        arm.locator("button[data-action=list_drawings]").click()
        rows = arm.locator("table.drawings tr")
        if not listed:  # the bench's one stored drawing went in an earlier run: the page says there are none
            expect(arm.locator(".stored")).to_have_text("No stored drawings.", timeout=30_000)
            return
        expect(rows).to_have_count(len(listed), timeout=30_000)
        slot = listed[0]["slot"]
        arm.locator(f"button[data-action=delete_drawing][data-slot='{slot}']").click()
        assert f"drawing {slot}" in page.answers[-1]  # type: ignore[attr-defined]
        wait_for(lambda: all(d["slot"] != slot for d in client.post(
            f"/api/v1/devices/{arm_id}/actions/list_drawings", json={}).json()["drawings"]), "the drawing deleted")
        expect(arm.locator(f"table.drawings tr[data-slot='{slot}']")).to_have_count(0)
        client.post(f"/api/v1/devices/{arm_id}/actions/home", json={})


def test_an_uploaded_drawing_shows_what_the_planner_left_out(page: Page, bench: Bench, tmp_path: Path) -> None:
    arm = page.locator("article[data-kind=lineus]")
    expect(arm.locator(".state")).to_have_attribute("data-state", "idle", timeout=60_000)
    drawing = tmp_path / "boxed.svg"
    drawing.write_bytes(NOTED_SVG)
    arm.locator("input[type=file]").set_input_files(str(drawing))
    arm.locator("button[data-action=upload]").click()
    note = "left out 1 foreignObject element(s)"
    expect(arm.locator(".job-notes")).to_contain_text(note, timeout=30_000)  # on the card while it draws
    expect(page.locator("#jobs tr", has_text="boxed.svg").first.locator(".job-notes")).to_contain_text(
        note, timeout=90_000)  # and in the jobs list after
    expect(arm.locator(".state")).to_have_attribute("data-state", "idle", timeout=90_000)


def test_chart_has_a_legend_and_room_for_its_top_label(page: Page) -> None:
    printer = page.locator("article[data-kind=xyz]")
    expect(printer.locator(".legend .key")).to_have_text(["Extruder", "Bed", "dashed: target"])
    labels = printer.locator("svg.chart text")
    tops = labels.evaluate_all("(all) => all.map((t) => t.getBBox().y)")
    assert min(tops) >= 0, tops  # no label cut off at the top of the chart


def test_a_failed_job_keeps_its_reason_in_view(page: Page, bench: Bench, simulator: Any) -> None:
    fussy = simulator("xyz", "--listen", "127.0.0.1:0", "--speed", "30", "--fault", "file-rejected")
    name = "a-rather-long-file-name-as-slicers-write-them_0.2mm_PLA_MINIW_1h23m_" * 2 + ".gcode"
    with api(bench) as client:
        added = client.post("/api/v1/devices", json={"name": "fussy", "kind": "xyz", "address": fussy.url}).json()
        try:
            wait_for(lambda: summary(client, added["id"])["state"] == "idle", "the second printer idle")
            job = client.post(f"/api/v1/devices/{added['id']}/jobs", params={"filename": name},
                              content=(Path(__file__).parents[2] / "src/fabwire/samples/calibration-square.gcode")
                              .read_bytes()).json()
            final = wait_for(lambda: (j := client.get(f"/api/v1/jobs/{job['id']}").json())["state"] == "failed"
                             and j, "the job failing")
            page.reload()
            row = page.locator(f"#jobs tr[data-job='{job['id']}']")
            reason = row.locator("td.message")
            expect(reason).to_have_text(final["message"], timeout=30_000)
            box = reason.bounding_box()
            width = page.viewport_size["width"]  # type: ignore[index]
            assert box is not None
            assert box["x"] >= 0
            assert box["x"] + box["width"] <= width + 1  # the reason fits on the screen, not beyond its edge
            section = page.evaluate("(() => { const s = document.getElementById('jobs-section'); "
                                    "return [s.scrollWidth, s.clientWidth]; })()")
            assert section[0] <= section[1], section  # the table does not run off
        finally:
            client.delete(f"/api/v1/devices/{added['id']}")


def test_demo_uses_a_temporary_state_directory_and_gets_busy_once_looked_at(browser: Browser, tmp_path: Path) -> None:
    """`serve --demo` leaves the real state directory alone; its machines stay idle for scripts until the
    dashboard is opened, which then shows work under way, as the README's pictures (taken here) show."""
    home = tmp_path / "home"
    env = {**cli_env(tmp_path), "HOME": str(home), "XDG_STATE_HOME": str(home / "state"),
           "XDG_CONFIG_HOME": str(home / "config")}
    process = subprocess.Popen([sys.executable, "-m", "fabwire", "serve", "--demo", "--listen", "127.0.0.1:0"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        assert ANNOUNCEMENT in line, line
        url = line.split(ANNOUNCEMENT, 1)[1].strip()
        with httpx.Client(base_url=url.rstrip("/"), timeout=30) as client:
            assert client.get("/api/v1/jobs").json() == []  # nobody looked yet: nothing started
            assert client.get("/").status_code == 200  # the page, as a browser asks for it
            wait_for(lambda: {j["device"] for j in client.get("/api/v1/jobs").json()} >= {"xyz-demo", "lineus-demo"},
                     "the demo's print and drawing")
            wait_for(lambda: summary(client, "mmu-demo")["state"] == "error", "the demo's MMU stopping on its fault")
        for name, size in (("serve-demo", DESKTOP), ("serve-phone", PHONE)):
            context = browser.new_context(viewport=size, device_scale_factor=1 if size is DESKTOP else 2)
            opened = context.new_page()
            opened.goto(url)
            expect(opened.locator("article.card")).to_have_count(3)
            expect(opened.locator("article[data-kind=mmu] .error-box")).to_be_visible()
            expect(opened.locator("#jobs tbody tr").first).to_be_visible()
            progress = opened.locator("#jobs tr", has_text="fabwire-logo.svg").locator("td[data-label=Progress]")
            expect(progress).not_to_have_text("0 %", timeout=60_000)  # the list follows the job, not only its start
            readme_picture(shot(opened, name))
            context.close()
    finally:
        process.terminate()
        process.wait(30)
        for stream in (process.stdout, process.stderr):
            if stream:
                stream.close()
    assert process.returncode == 0
    assert not (home / "state").exists()  # nothing in the real state directory


@pytest.mark.parametrize(("kind", "action", "body", "words"), [
    ("xyz", "zoffset", {"mm": 99}, "must be from -20 to 20"),
    ("xyz", "zoffset", {"mm": "2.45"}, "must be a finite number"),
    ("xyz", "zoffset_step", {"direction": "sideways"}, "must be one of up, down"),
    ("xyz", "calibrate", {"points": 9}, "takes no parameter 'points'"),
    ("lineus", "pen_height", {"z": 2000}, "must be from 0 to 1000"),
    ("lineus", "delete_drawing", {"slot": 1}, "send \"confirm\": true"),
    ("lineus", "delete_drawing", {"slot": 40, "confirm": True}, "must be from 1 to 32"),
    ("mmu", "eject", {"slot": 7}, "must be from 0 to 4"),
])
def test_flow_actions_refuse_bad_input_with_a_message(bench: Bench, kind: str, action: str, body: dict[str, Any],
                                                      words: str) -> None:
    with api(bench) as client:
        device = device_of(client, kind)["id"]
        response = client.post(f"/api/v1/devices/{device}/actions/{action}", json=body)
    assert response.status_code == 400, response.text
    assert words in response.json()["message"]
    assert response.json()["exit_code"] == 4
