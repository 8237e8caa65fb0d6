// The fabwire dashboard: one card per machine, fed by /api/v1 and the live WebSocket. No libraries, no build.
"use strict";

const API = "/api/v1";
const CHART_WINDOW_S = 600;          // the temperature chart shows the last ten minutes
const SVG_NS = "http://www.w3.org/2000/svg";
const LINEUS_AREA = [500, -1574, 1950, 1574];   // the arm's reach in its own units (x0, y0, x1, y1)
const cards = new Map();             // device id -> {root, device, state, samples, preview, ink}
let token = localStorage.getItem("fabwire.token") || "";

// ---------------------------------------------------------------------------------------------- helpers

function el(tag, attrs = {}, ...children) {
  const node = tag.startsWith("svg:") ? document.createElementNS(SVG_NS, tag.slice(4)) : document.createElement(tag);
  for (const [key, value] of Object.entries(attrs)) {
    if (value === null || value === undefined || value === false) continue;
    if (key === "onclick" || key === "onsubmit" || key === "onchange") node.addEventListener(key.slice(2), value);
    else node.setAttribute(key, value === true ? "" : value);
  }
  for (const child of children.flat()) {
    if (child !== null && child !== undefined) node.append(child instanceof Node ? child : String(child));
  }
  return node;
}

function toast(text, bad = false) {
  const box = el("div", {class: bad ? "toast bad" : "toast"}, text);
  document.getElementById("toasts").append(box);
  setTimeout(() => box.remove(), bad ? 9000 : 4000);
}

function duration(seconds) {
  if (seconds === null || seconds === undefined) return "";
  const s = Math.max(0, Math.round(seconds));
  const h = Math.floor(s / 3600), m = Math.floor((s % 3600) / 60);
  return h ? `${h} h ${m} min` : m ? `${m} min ${s % 60} s` : `${s % 60} s`;
}

function number(value, unit) {
  return value === null || value === undefined ? "–" : `${Math.round(value)}${unit}`;
}

async function call(method, path, body, raw) {
  const headers = {};
  if (token) headers.Authorization = `Bearer ${token}`;
  // a file goes as it is, whatever type the system gives its name (an upload is never read as a form)
  if (body !== undefined) headers["Content-Type"] = raw ? "application/octet-stream" : "application/json";
  const response = await fetch(API + path, {method, headers, body: raw ? body : body === undefined ? undefined
    : JSON.stringify(body)});
  if (response.status === 401) { askToken(); throw new Error("this agent needs its access token"); }
  const data = response.status === 204 ? null : await response.json();
  if (!response.ok) throw new Error(data && data.message ? data.message : `HTTP ${response.status}`);
  return data;
}

function askToken() {
  const form = document.getElementById("token-form");
  form.hidden = false;
  form.onsubmit = (event) => {
    event.preventDefault();
    token = document.getElementById("token").value.trim();
    localStorage.setItem("fabwire.token", token);
    form.hidden = true;
    start();
  };
}

// ---------------------------------------------------------------------------------------------- actions

async function act(card, action, params = {}, confirmText = null) {
  if (confirmText && !window.confirm(confirmText)) return;
  try {
    const body = confirmText ? {...params, confirm: true} : params;
    const result = await call("POST", `/devices/${encodeURIComponent(card.device.id)}/actions/${action}`, body);
    if (result && result.started) toast(`${card.device.name}: ${action.replace("_", " ")} started`);
  } catch (error) {
    toast(`${card.device.name}: ${error.message}`, true);
  }
}

async function cancelJob(card) {
  const job = card.state && card.state.job;
  if (!job) return act(card, "cancel", {}, `Cancel the print on ${card.device.name}? It cannot be resumed.`);
  if (!window.confirm(`Cancel the job on ${card.device.name}? It cannot be resumed.`)) return;
  try {
    await call("POST", `/jobs/${job.id}/cancel`, {confirm: true});
  } catch (error) {
    toast(error.message, true);
  }
}

async function upload(card, input) {
  const file = input.files[0];
  if (!file) return toast("choose a file first", true);
  try {
    const job = await call("POST", `/devices/${encodeURIComponent(card.device.id)}/jobs?filename=`
      + encodeURIComponent(file.name), file, true);
    toast(`${card.device.name}: ${file.name} started (job ${job.id})`);
    input.value = "";
    loadJobs();
  } catch (error) {
    toast(`${card.device.name}: ${error.message}`, true);
  }
}

const LABELS = {pause: "Pause", resume: "Resume", cancel: "Cancel", acknowledge: "Taken off the bed",
  home: "Home", unload_filament: "Unload filament", retry: "Retry", continue: "Continue", stop: "Stop",
  unload: "Unload", pen_up: "Pen up", pen_down: "Pen down", reset: "Restart MMU"};
const CONFIRM = {reset: "Restart the MMU? A running command is lost."};

function actionButtons(card, applicable) {
  const out = [];
  for (const action of applicable) {
    if (["jog", "move", "text", "load", "eject", "cut"].includes(action)) continue;  // need parameters: own UI
    if (action === "tool_change") continue;
    const danger = ["cancel", "stop", "reset"].includes(action);
    const primary = ["retry", "continue", "resume"].includes(action);
    const handler = action === "cancel" ? () => cancelJob(card) : () => act(card, action, {}, CONFIRM[action] || null);
    out.push(el("button", {type: "button", "data-action": action, class: danger ? "danger" : primary ? "primary" : null,
      onclick: handler}, LABELS[action] || action));
  }
  return out;
}

// ---------------------------------------------------------------------------------------------- charts

function chart(samples, now) {
  const width = 320, height = 120, left = 28, bottom = 14;
  const svg = el("svg:svg", {class: "chart", viewBox: `0 0 ${width} ${height}`, preserveAspectRatio: "none",
    role: "img", "aria-label": "temperatures against targets, last ten minutes"});
  const recent = samples.filter((s) => now - s.t <= CHART_WINDOW_S);
  // the window grows with the history it has, from two minutes to ten, so a fresh curve is not squashed
  const span = Math.min(CHART_WINDOW_S, Math.max(120, recent.length ? now - recent[0].t : 0));
  const values = recent.flatMap((s) => [s.e, s.et, s.b, s.bt]).filter((v) => v !== null && v !== undefined);
  const top = Math.max(40, Math.ceil((Math.max(0, ...values) + 10) / 40) * 40);
  const x = (t) => left + (width - left - 2) * (1 - (now - t) / span);
  const y = (v) => (height - bottom) * (1 - v / top) + 2;
  for (let v = 0; v <= top; v += top / 4) {
    svg.append(el("svg:line", {class: "grid", x1: left, x2: width, y1: y(v), y2: y(v)}),
      el("svg:text", {x: 2, y: y(v) + 3}, `${Math.round(v)}°`));
  }
  svg.append(el("svg:text", {x: left, y: height - 2}, `−${Math.round(span / 60)} min`), el("svg:text", {x: width - 24, y: height - 2}, "now"));
  for (const [key, cls] of [["et", "extruder-target"], ["bt", "bed-target"], ["e", "extruder"], ["b", "bed"]]) {
    const points = recent.filter((s) => s[key] !== null && s[key] !== undefined)
      .map((s) => `${x(s.t).toFixed(1)},${y(s[key]).toFixed(1)}`);
    if (points.length) svg.append(el("svg:polyline", {class: cls, points: points.join(" ")}));
  }
  return svg;
}

function addSample(card, summary, t) {
  if (summary.extruder_temp_c === null && summary.bed_temp_c === null) return;
  card.samples.push({t, e: summary.extruder_temp_c, et: summary.extruder_target_c, b: summary.bed_temp_c,
    bt: summary.bed_target_c});
  while (card.samples.length && t - card.samples[0].t > CHART_WINDOW_S + 60) card.samples.shift();
}

// ---------------------------------------------------------------------------------------------- Line-us drawing

function drawingView(card) {
  const all = card.preview.concat(card.ink).flat();
  const pos = card.state && card.state.summary.position;
  if (pos) all.push([pos.x, pos.y]);
  let [x0, y0, x1, y1] = LINEUS_AREA;
  if (card.preview.length) {
    x0 = Math.min(...all.map((p) => p[0])); x1 = Math.max(...all.map((p) => p[0]));
    y0 = Math.min(...all.map((p) => p[1])); y1 = Math.max(...all.map((p) => p[1]));
  }
  const pad = Math.max(x1 - x0, y1 - y0) * 0.06 + 10;
  // machine y points up: flip it so the drawing reads as on paper
  const svg = el("svg:svg", {class: "drawing", viewBox: `${x0 - pad} ${-y1 - pad} ${x1 - x0 + 2 * pad} ${y1 - y0 + 2 * pad}`,
    role: "img", "aria-label": "drawing: planned strokes in grey, ink as drawn"});
  const path = (stroke, cls) => el("svg:polyline", {class: cls, points: stroke.map((p) => `${p[0]},${-p[1]}`).join(" ")});
  for (const stroke of card.preview) svg.append(path(stroke, "planned"));
  const inkLayer = el("svg:g", {class: "ink-layer"});
  for (const stroke of card.ink) inkLayer.append(path(stroke, "ink"));
  svg.append(inkLayer);
  if (pos) svg.append(el("svg:circle", {class: "pen", cx: pos.x, cy: -pos.y, r: pad / 3}));
  return svg;
}

function addInk(card, stroke) {
  card.ink.push(stroke);
  const layer = card.root.querySelector("svg.drawing .ink-layer");
  if (layer) layer.append(el("svg:polyline", {class: "ink", points: stroke.map((p) => `${p[0]},${-p[1]}`).join(" ")}));
}

// ---------------------------------------------------------------------------------------------- cards

function kindSection(card, s) {
  const kind = card.device.kind;
  const parts = [];
  if (kind === "xyz") {
    parts.push(el("div", {class: "temps"},
      el("span", {class: "extruder"}, "Extruder ", el("b", {class: "temp-extruder", "data-value": s.extruder_temp_c ?? ""},
        number(s.extruder_temp_c, " °C")), ` / ${number(s.extruder_target_c, " °C")}`),
      el("span", {class: "bed"}, "Bed ", el("b", {class: "temp-bed"}, number(s.bed_temp_c, " °C")),
        s.bed_target_c !== null ? ` / ${number(s.bed_target_c, " °C")}` : ""),
      s.filament_left_mm !== null ? el("span", {class: "facts"}, `filament ${(s.filament_left_mm / 1000).toFixed(1)} m`) : null));
    parts.push(chart(card.samples, Date.now() / 1000));
  }
  if (kind === "mmu") {
    parts.push(el("div", {class: "slots"}, [0, 1, 2, 3, 4].map((i) => el("div", {
      class: `slot${s.active_slot === i ? " active" : ""}${s.selector_slot === i ? " selector" : ""}`,
      "data-slot": i, title: s.active_slot === i ? "loaded" : ""}, `${i}`))));
    parts.push(el("div", {class: "facts"}, `Filament: ${s.filament_position || "–"} · FINDA ${s.finda ? "on" : "off"}`
      + (s.active_slot !== null ? ` · slot ${s.active_slot} loaded` : "")));
  }
  if (kind === "lineus") parts.push(drawingView(card));
  return parts;
}

function progressSection(card, s) {
  const job = card.state.job;
  const percent = job ? job.progress_percent : s.progress_percent;
  if (!(s.busy || job) || percent === null || percent === undefined) return null;
  const left = job && job.time_left_s !== null ? job.time_left_s : s.time_left_s;
  return el("div", {class: "progress-block"},
    el("div", {class: "progress", role: "progressbar", "aria-valuenow": Math.round(percent), "aria-valuemin": 0,
      "aria-valuemax": 100}, el("div", {style: `width:${Math.min(100, percent)}%`})),
    el("div", {class: "progress-text"}, `${Math.round(percent)} %`, left ? ` · ${duration(left)} left` : "",
      job && job.message ? ` · ${job.message}` : ""));
}

function controls(card, s) {
  const kind = card.device.kind;
  const out = [el("div", {class: "buttons"}, actionButtons(card, s.actions))];
  if (kind === "mmu" && s.actions.includes("tool_change")) {
    out.push(el("div", {class: "buttons"}, [0, 1, 2, 3, 4].map((i) => el("button", {type: "button",
      "data-action": "tool_change", "data-slot": i, onclick: () => act(card, "tool_change", {slot: i})}, `T${i}`))));
  }
  const accepts = {xyz: ".gcode,.gco,.g,.3w", lineus: ".svg,.svgz,.gcode,.gc,.nc,.ngc"}[kind];
  if (accepts && card.state.online && !s.busy && !card.state.job) {
    const input = el("input", {type: "file", accept: accepts, "aria-label": "file to send"});
    out.push(el("div", {class: "upload"}, input, el("button", {type: "button", class: "primary", "data-action": "upload",
      onclick: () => upload(card, input)}, kind === "xyz" ? "Print" : "Draw")));
  }
  if (kind === "lineus" && s.actions.includes("text")) {
    const text = el("input", {type: "text", placeholder: "text to write", maxlength: 80, "aria-label": "text to write"});
    out.push(el("div", {class: "upload"}, text, el("button", {type: "button", "data-action": "text",
      onclick: () => text.value.trim() && act(card, "text", {text: text.value.trim()})}, "Write")));
  }
  return out;
}

function render(card) {
  const {device, state} = card;
  const s = state.summary;
  const stateClass = !state.online ? "offline" : s.state === "error" ? "error" : "";
  const live = [
    el("header", {},
      el("h3", {}, device.name), el("span", {class: "kind"}, {xyz: "da Vinci", lineus: "Line-us", mmu: "MMU3"}[device.kind]),
      el("span", {class: state.online ? "online" : "offline"}, state.online ? "online" : "offline"),
      el("div", {class: "ident"}, [device.model, device.serial && `serial ${device.serial}`,
        device.firmware && `firmware ${device.firmware}`].filter(Boolean).join(" · "))),
    el("div", {class: `state ${stateClass}`, "data-state": s.state}, s.state_text || s.state),
    s.error ? el("div", {class: "error-box", role: "alert"}, s.error) : null,
    progressSection(card, s),
    ...(state.online ? kindSection(card, s) : []),
  ];
  card.live.replaceChildren(...live.filter(Boolean));
  // the controls hold a chosen file or typed text: rebuild them only when what applies has changed
  const key = JSON.stringify([state.online, s.actions, s.busy, Boolean(state.job)]);
  if (key !== card.controlsKey) {
    card.controlsKey = key;
    card.controls.replaceChildren(...(state.online ? controls(card, s) : []));
  }
  card.root.dataset.state = s.state;
}

function ensureCard(device) {
  let card = cards.get(device.id);
  if (!card) {
    const live = el("div", {class: "live"}), controlsBox = el("div", {class: "controls"});
    const root = el("article", {class: "card", "data-device": device.id, "data-kind": device.kind}, live, controlsBox);
    card = {root, live, controls: controlsBox, controlsKey: "", device, state: device.state, samples: [], preview: [],
      ink: [], pending: false};
    cards.set(device.id, card);
    const main = document.getElementById("devices");
    main.querySelector(".empty")?.remove();
    main.append(root);
  }
  return card;
}

function scheduleRender(card) {
  if (card.pending) return;       // many events in one frame: draw once
  card.pending = true;
  requestAnimationFrame(() => { card.pending = false; render(card); });
}

// ---------------------------------------------------------------------------------------------- live events

function onEvent(event) {
  const card = cards.get(event.device);
  if (!card) { if (event.type === "online") loadDevices(); return; }
  if (event.type === "state") {
    const previousJob = card.state.job;
    card.state = event.state;
    addSample(card, event.state.summary, Date.parse(event.state.ts) / 1000);
    if (!previousJob && event.state.job) { card.preview = []; card.ink = []; }
    scheduleRender(card);
  } else if (event.type === "online") {
    card.device = {...card.device, ...event.info};
  } else if (event.type === "job") {
    if (event.preview) { card.preview = event.preview; card.ink = []; }
    card.state = {...card.state, job: ["done", "failed", "cancelled"].includes(event.job.state) ? null : event.job};
    if (event.stroke) addInk(card, event.stroke);
    if (event.preview || !event.stroke) scheduleRender(card);
    if (!event.stroke && event.job.state !== "running") loadJobs();
  } else if (event.type === "error") {
    toast(`${card.device.name}: ${event.message}`, true);
  }
}

let socket = null, retry = 500;

function connect() {
  const link = document.getElementById("link");
  const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}${API}/events`;
  socket = new WebSocket(url, token ? ["fabwire", `fabwire.token.${token}`] : ["fabwire"]);
  socket.onopen = () => { link.textContent = "live"; link.className = "link up"; retry = 500; };
  socket.onmessage = (message) => onEvent(JSON.parse(message.data));
  socket.onclose = () => {
    link.textContent = "reconnecting…"; link.className = "link down";
    setTimeout(connect, retry);
    retry = Math.min(retry * 2, 10000);
  };
}

// ---------------------------------------------------------------------------------------------- loading

async function loadHistory(card) {
  if (card.device.kind !== "xyz") return;
  const since = new Date(Date.now() - CHART_WINDOW_S * 1000).toISOString();
  const data = await call("GET", `/devices/${encodeURIComponent(card.device.id)}/history?since=${since}`);
  const older = data.samples.map((s) => ({t: Date.parse(s.ts) / 1000, e: s.extruder_temp_c, et: s.extruder_target_c,
    b: s.bed_temp_c, bt: s.bed_target_c})).filter((s) => s.e !== null || s.b !== null);
  card.samples = older.concat(card.samples.filter((s) => !older.length || s.t > older[older.length - 1].t));
  scheduleRender(card);
}

async function loadDrawing(card) {
  if (card.device.kind !== "lineus") return;
  const data = await call("GET", `/devices/${encodeURIComponent(card.device.id)}/drawing`);
  card.preview = data.preview; card.ink = data.ink;
  scheduleRender(card);
}

async function loadDevices() {
  const devices = await call("GET", "/devices");
  if (!devices.length) {
    document.getElementById("devices").replaceChildren(el("p", {class: "empty"},
      "No machines yet: name them in devices.toml, or start with `fabwire serve --demo`."));
  }
  for (const device of devices) {
    const card = ensureCard(device);
    card.device = device; card.state = device.state;
    render(card);
  }
  performance.mark("fabwire-cards");  // first meaningful paint: every machine on the page
  for (const card of cards.values()) {
    loadHistory(card).catch(() => {});
    loadDrawing(card).catch(() => {});
  }
}

async function loadJobs() {
  const jobs = await call("GET", "/jobs?limit=20");
  const names = (id) => (cards.get(id)?.device.name) || id;
  document.querySelector("#jobs tbody").replaceChildren(...jobs.map((job) => el("tr", {"data-job": job.id},
    el("td", {}, names(job.device)), el("td", {}, job.filename || (job.params && job.params.text) || job.type),
    el("td", {class: `job-state ${job.state}`}, job.state), el("td", {}, `${Math.round(job.progress_percent || 0)} %`),
    el("td", {}, job.started ? new Date(job.started).toLocaleTimeString() : ""),
    el("td", {}, job.state === "running" ? el("button", {type: "button", class: "danger",
      onclick: () => cancelJob(cards.get(job.device))}, "Cancel") : job.message || ""))));
}

async function start() {
  try {
    await loadDevices();
    connect();
    loadJobs().catch(() => {});
  } catch (error) {
    document.getElementById("devices").replaceChildren(el("p", {class: "empty"}, error.message));
  }
}

setInterval(() => { for (const card of cards.values()) if (card.device.kind === "xyz") scheduleRender(card); }, 5000);
start();
