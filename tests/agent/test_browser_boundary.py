"""A stranger's page in a real browser (Debian's Chromium) against the loopback agent: it is served from another
loopback origin (127.0.0.2, as any web site would be another origin) and tries everything a page can do without
the user: fetch in no-cors and cors mode, HTML form posts of each encoding, and the live WebSocket. Nothing may
reach a machine, and nothing may be read."""

from __future__ import annotations

import functools
import http.server
import json
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from playwright.sync_api import Browser

from .agenttools import RunningAgent, start_agent, wait_for

EVIL_PAGE = """<!doctype html><title>cat pictures</title>
<body>
<iframe name="sink"></iframe>
<script>
const AGENT = new URLSearchParams(location.search).get("agent");
const PRINTER = new URLSearchParams(location.search).get("printer");
const ARM = new URLSearchParams(location.search).get("arm");
const results = {};
const gcode = "M104 S215\\nG28\\nG1 Z0.3 F3000\\nG1 X10 Y10 E1 F1200\\n";
function attempt(name, promise) {
  return promise.then(r => { results[name] = r && r.type ? r.type + " " + r.status : String(r); },
                      e => { results[name] = "blocked " + e; });
}
function form(action, enctype, fields) {
  const f = document.createElement("form");
  f.method = "POST"; f.action = AGENT + action; f.enctype = enctype; f.target = "sink";
  for (const [k, v] of Object.entries(fields)) {
    const i = document.createElement("input"); i.type = "hidden"; i.name = k; i.value = v; f.appendChild(i);
  }
  document.body.appendChild(f); f.submit();
}
async function run() {
  await Promise.all([
    attempt("upload no-cors", fetch(`${AGENT}/api/v1/devices/${PRINTER}/jobs?filename=cat.gcode`,
                                    {method: "POST", mode: "no-cors", body: gcode})),
    attempt("upload blob no-cors", fetch(`${AGENT}/api/v1/devices/${PRINTER}/jobs?filename=cat.gcode`,
                                         {method: "POST", mode: "no-cors", body: new Blob([gcode])})),
    attempt("text no-cors", fetch(`${AGENT}/api/v1/devices/${ARM}/actions/text`,
                                  {method: "POST", mode: "no-cors", body: '{"text": "pwned"}'})),
    attempt("home json cors", fetch(`${AGENT}/api/v1/devices/${ARM}/actions/home`,
                                    {method: "POST", headers: {"Content-Type": "application/json"}, body: "{}"})),
    attempt("read devices", fetch(`${AGENT}/api/v1/devices`).then(r => r.text())),
  ]);
  form(`/api/v1/devices/${ARM}/actions/text`, "text/plain", {'{"text": "pwned", "x': '"}'});
  form(`/api/v1/devices/${PRINTER}/jobs?filename=cat.gcode`, "multipart/form-data", {g: gcode});
  form(`/api/v1/devices/${ARM}/actions/home`, "application/x-www-form-urlencoded", {a: "1"});
  results.socket = await new Promise(done => {
    const ws = new WebSocket(AGENT.replace("http", "ws") + "/api/v1/events");
    const seen = [];
    ws.onopen = () => seen.push("open");
    ws.onmessage = m => seen.push("message " + m.data.slice(0, 80));
    ws.onclose = () => done(seen.concat("closed"));
    ws.onerror = () => seen.push("error");
    setTimeout(() => done(seen.concat("timeout")), 5000);
  });
  await new Promise(r => setTimeout(r, 1000));  // the form posts land
  window.results = results;
}
run();
</script>
"""


class Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:
        pass


@pytest.fixture
def stranger(tmp_path: Path) -> Iterator[str]:
    """A web site on another loopback address: the page's origin is http://127.0.0.2:PORT."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "cats.html").write_text(EVIL_PAGE, encoding="utf-8")
    server = http.server.ThreadingHTTPServer(("127.0.0.2", 0), functools.partial(Quiet, directory=str(site)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.2:{server.server_address[1]}/cats.html"
    server.shutdown()
    server.server_close()


@pytest.fixture
def agent(tmp_path: Path) -> Iterator[RunningAgent]:
    running = start_agent(tmp_path / "state", "--device", "p:xyz=sim://xyz?speed=30",
                          "--device", "a:lineus=sim://lineus?speed=inf")
    yield running
    running.stop()


def test_a_strangers_page_reaches_no_machine(browser: Browser, stranger: str, agent: RunningAgent) -> None:
    with agent.client() as client:
        devices = wait_for(lambda: (d := client.get("/api/v1/devices").json()) and all(
            x["state"]["online"] for x in d) and d, "both machines online")
        ids = {d["kind"]: d["id"] for d in devices}
        before = {d["id"]: client.get(f"/api/v1/devices/{d['id']}/history").json()["events"] for d in devices}
    context = browser.new_context()
    page = context.new_page()
    page.goto(f"{stranger}?agent={agent.url.rstrip('/')}&printer={ids['xyz']}&arm={ids['lineus']}")
    page.wait_for_function("window.results !== undefined", timeout=30_000)
    results = page.evaluate("window.results")
    frame = page.frame(name="sink")
    refusal = frame.content() if frame else ""
    context.close()

    assert results["home json cors"].startswith("blocked"), results  # no preflight is ever granted
    assert results["read devices"].startswith("blocked"), results  # nothing is readable cross-origin
    assert results["socket"][0] in ("error", "closed"), results  # the handshake is refused: no open …
    assert not any(s.startswith("message") for s in results["socket"]), results  # … and no event
    assert "CrossOrigin" in refusal  # the last form post's answer, shown in the frame: refused
    with agent.client() as client:
        assert client.get("/api/v1/jobs").json() == []
        for device_id, events in before.items():
            after = client.get(f"/api/v1/devices/{device_id}/history").json()["events"]
            assert [e for e in after if e not in events and e["type"] != "offline"] == [], json.dumps(after)[:500]
        assert client.get(f"/api/v1/devices/{ids['xyz']}/state").json()["summary"]["state"] == "idle"
    assert not list((agent.state_dir / "uploads").iterdir()) if (agent.state_dir / "uploads").exists() else True
