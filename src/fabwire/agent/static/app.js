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

async function act(card, action, params = {}, confirmText = null, destructive = true) {
  // confirmText: asked first; destructive actions also tell the agent so ("confirm": true), as the CLI's --yes
  if (confirmText && !window.confirm(confirmText)) return null;
  try {
    const body = confirmText && destructive ? {...params, confirm: true} : params;
    const result = await call("POST", `/devices/${encodeURIComponent(card.device.id)}/actions/${action}`, body);
    if (result && result.started) toast(`${card.device.name}: ${action.replaceAll("_", " ")} started`);
    return result;
  } catch (error) {
    toast(`${card.device.name}: ${error.message}`, true);
    return null;
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

const LABELS = {pause: "Pause", resume: "Resume", cancel: "Cancel", acknowledge: "Acknowledge",
  home: "Home", unload_filament: "Unload filament", retry: "Retry", continue: "Continue", stop: "Stop",
  unload: "Unload", pen_up: "Pen up", pen_down: "Pen down", reset: "Restart MMU"};
const CONFIRM = {reset: "Restart the MMU? A running command is lost."};
const OWN_UI = ["jog", "move", "text", "load", "eject", "cut", "tool_change", "confirm", "stop_flow", "zoffset",
  "zoffset_step", "pen_height", "list_drawings", "delete_drawing", "load_filament", "unload_filament", "clean_nozzle",
  "calibrate", "home"];

function actionButtons(card, applicable) {
  const out = [];
  for (const action of applicable) {
    if (OWN_UI.includes(action) && !(action === "home" && card.device.kind !== "xyz")) continue;  // own tools
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
  const width = 320, height = 120, left = 28, bottom = 14, topPad = 10;
  const svg = el("svg:svg", {class: "chart", viewBox: `0 0 ${width} ${height}`, preserveAspectRatio: "none",
    role: "img", "aria-label": "temperatures against targets, last ten minutes"});
  const recent = samples.filter((s) => now - s.t <= CHART_WINDOW_S);
  // the window grows with the history it has, from two minutes to ten, so a fresh curve is not squashed
  const span = Math.min(CHART_WINDOW_S, Math.max(120, recent.length ? now - recent[0].t : 0));
  const values = recent.flatMap((s) => [s.e, s.et, s.b, s.bt]).filter((v) => v !== null && v !== undefined);
  const top = Math.max(40, Math.ceil((Math.max(0, ...values) + 10) / 40) * 40);
  const x = (t) => left + (width - left - 2) * (1 - (now - t) / span);
  const y = (v) => topPad + (height - bottom - topPad) * (1 - v / top);
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

function legend() {
  return el("div", {class: "legend", "aria-label": "chart legend"},
    el("span", {class: "key extruder"}, "Extruder"), el("span", {class: "key bed"}, "Bed"),
    el("span", {class: "key target"}, "dashed: target"));
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
    parts.push(chart(card.samples, Date.now() / 1000), legend());
    const cal = card.state.status && card.state.status.calibration;
    if (Array.isArray(cal) && cal.length === 9 && cal.every((v) => typeof v === "number")) parts.push(calibrationMap(cal));
  }
  if (kind === "mmu") {
    if (card.slot === undefined) card.slot = s.active_slot ?? 0;
    parts.push(el("div", {class: "slots", role: "group", "aria-label": "filament slots: choose one"},
      [0, 1, 2, 3, 4].map((i) => el("button", {type: "button",
        class: `slot${s.active_slot === i ? " active" : ""}${s.selector_slot === i ? " selector" : ""}`
          + `${card.slot === i ? " chosen" : ""}`,
        "data-slot": i, "aria-pressed": card.slot === i ? "true" : "false",
        title: s.active_slot === i ? "loaded" : "", onclick: () => chooseSlot(card, i)}, `${i}`))));
    parts.push(el("div", {class: "facts"}, `Filament: ${s.filament_position || "–"} · FINDA ${s.finda ? "on" : "off"}`
      + (s.active_slot !== null ? ` · slot ${s.active_slot} loaded` : "")));
  }
  if (kind === "lineus") parts.push(drawingView(card));
  return parts;
}

function progressSection(card, s) {
  const job = card.state.job;
  const percent = job ? job.progress_percent : s.progress_percent;
  // a flow (loading filament, calibrating) reports no progress worth a bar: its words are in the state line
  if (!(job || ["printing", "paused", "drawing"].includes(s.state)) || percent === null || percent === undefined) {
    return null;
  }
  const left = job && job.time_left_s !== null ? job.time_left_s : s.time_left_s;
  return el("div", {class: "progress-block"},
    el("div", {class: "progress", role: "progressbar", "aria-valuenow": Math.round(percent), "aria-valuemin": 0,
      "aria-valuemax": 100}, el("div", {style: `width:${Math.min(100, percent)}%`})),
    el("div", {class: "progress-text"}, `${Math.round(percent)} %`, left ? ` · ${duration(left)} left` : "",
      job && job.message ? ` · ${job.message}` : ""),
    job ? notesList(job) : null);
}

function notesList(job) {
  // what the planner left out or changed, as `fabwire lineus draw` prints it
  return job.notes && job.notes.length ? el("ul", {class: "job-notes"}, job.notes.map((n) => el("li", {}, n))) : null;
}

const PROMPT_BUTTONS = [  // the printer's prompts (fabwire.xyz.maintenance) → what the owner has just done
  ["Lower the calibration detector", "Detector lowered"],
  ["Raise the calibration detector", "Detector raised"],
  ["Filament is feeding", "Filament comes out"],
  ["The nozzle is hot", "Nozzle is clean"],
];
const HEATS = "The nozzle heats up to about 200 °C.";
const FLOWS = [  // xyz maintenance: action, label, what is asked first (physical steps ask, as the CLI does)
  ["load_filament", "Load filament", `Load filament? ${HEATS} Have the filament ready at the feeder.`],
  ["unload_filament", "Unload filament", `Unload the filament? ${HEATS}`],
  ["clean_nozzle", "Clean nozzle", `Heat the nozzle for cleaning? ${HEATS}`],
  ["calibrate", "Calibrate bed", "Calibrate the bed? You will be asked to lower and raise the detector."],
  ["home", "Home", "Home all axes? The print head and bed move."],
];

function promptBox(card, s) {
  const label = (PROMPT_BUTTONS.find(([start]) => s.prompt.startsWith(start)) || [null, "Done"])[1];
  return el("div", {class: "prompt", role: "alertdialog", "aria-label": "the printer waits for you"},
    el("p", {}, s.prompt),
    el("div", {class: "buttons"},
      el("button", {type: "button", class: "primary", "data-action": "confirm", onclick: () => act(card, "confirm")},
        label),
      el("button", {type: "button", class: "danger", "data-action": "stop_flow",
        onclick: () => act(card, "stop_flow", {}, `Stop this step on ${card.device.name}? The printer cancels it.`,
          false)}, "Stop")));
}

function calibrationMap(values) {
  const mean = values.reduce((a, b) => a + b, 0) / values.length;
  const spread = Math.max(1, ...values.map((v) => Math.abs(v - mean)));
  return el("figure", {class: "calmap"},
    el("div", {class: "grid9", role: "table", "aria-label": "bed calibration: nine readings, back row first"},
      values.map((v, i) => el("span", {class: "cell", role: "cell", "data-index": i,
        style: `--dev:${((v - mean) / spread).toFixed(2)}`, title: `reading ${i + 1}: ${v}`}, `${v}`))),
    el("figcaption", {}, `Bed calibration: nine readings (spread ${Math.max(...values) - Math.min(...values)})`));
}

function xyzTools(card, s) {
  const out = [];
  const idle = s.actions.includes("calibrate");
  if (!idle) return out;
  out.push(el("div", {class: "buttons tools"}, FLOWS.map(([action, label, ask]) => el("button", {type: "button",
    "data-action": action, onclick: () => act(card, action, {}, ask, false)}, label))));
  const step = el("select", {"aria-label": "jog step", class: "jog-step"},
    ["0.1", "1", "10"].map((v) => el("option", {value: v, selected: v === "1"}, `${v} mm`)));
  const jog = (axis, sign) => el("button", {type: "button", "data-action": "jog", "data-axis": axis,
    "data-sign": sign > 0 ? "+" : "-", onclick: () => act(card, "jog", {axis, distance_mm: sign * Number(step.value)})},
    `${axis.toUpperCase()}${sign > 0 ? "+" : "−"}`);
  out.push(el("div", {class: "jogpad", role: "group", "aria-label": "jog"},
    el("span"), jog("y", 1), el("span"), jog("z", 1),
    jog("x", -1), el("span", {class: "jog-label"}, "XY"), jog("x", 1), el("span", {class: "jog-label"}, "Z"),
    el("span"), jog("y", -1), el("span"), jog("z", -1), step));
  const current = card.state.status ? card.state.status.zoffset_mm : null;
  const field = el("input", {type: "number", step: "0.01", min: -20, max: 20, "aria-label": "Z offset in mm",
    class: "zoffset-input", value: current ?? ""});
  out.push(el("div", {class: "zoffset", role: "group", "aria-label": "Z offset"},
    el("span", {}, "Z offset ", el("b", {class: "zoffset-value"}, current === null || current === undefined ? "–"
      : `${current.toFixed(2)} mm`)),
    el("button", {type: "button", "data-action": "zoffset_step", "data-direction": "up",
      onclick: () => act(card, "zoffset_step", {direction: "up"})}, "▲ 0.01"),
    el("button", {type: "button", "data-action": "zoffset_step", "data-direction": "down",
      onclick: () => act(card, "zoffset_step", {direction: "down"})}, "▼ 0.01"),
    field, el("button", {type: "button", "data-action": "zoffset", onclick: () => field.value !== "" &&
      act(card, "zoffset", {mm: Number(field.value)}, `Set the Z offset of ${card.device.name} to `
        + `${Number(field.value).toFixed(2)} mm?`, false)}, "Set")));
  return out;
}

const SLOT_ACTIONS = [  // MMU, per chosen slot: action, label, what is asked first
  ["tool_change", "Tool change", null],
  ["load", "Load", null],
  ["eject", "Eject", "Eject the filament of slot {slot}? It is pushed out of the MMU."],
  ["cut", "Cut", "Cut the filament of slot {slot}? This cannot be undone."],
];

function chooseSlot(card, slot) {
  card.slot = slot;
  card.controlsKey = "";
  render(card);
}

function mmuTools(card, s) {
  if (!s.actions.includes("tool_change")) return [];
  const slot = card.slot ?? 0;
  return [el("div", {class: "buttons slot-actions", role: "group", "aria-label": `slot ${slot}`},
    el("span", {class: "facts"}, `Slot ${slot}:`),
    SLOT_ACTIONS.map(([action, label, ask]) => el("button", {type: "button", "data-action": action, "data-slot": slot,
      class: ask ? "danger" : null, onclick: () => act(card, action, {slot}, ask && ask.replace("{slot}", slot),
        false)}, label)))];
}

function lineusTools(card, s) {
  if (!s.actions.includes("pen_height")) return [];
  const z = s.position ? Math.round(s.position.z) : 1000;
  const height = el("input", {type: "range", min: 0, max: 1000, step: 50, value: z, "aria-label": "pen height",
    class: "pen-height"});
  const shown = el("b", {class: "pen-height-value"}, `${z}`);
  height.addEventListener("input", () => { shown.textContent = height.value; });
  const list = el("div", {class: "stored"});
  return [
    el("div", {class: "pen-row", role: "group", "aria-label": "pen height"}, el("span", {}, "Pen height ", shown),
      height, el("button", {type: "button", "data-action": "pen_height",
        onclick: () => act(card, "pen_height", {z: Number(height.value)})}, "Set")),
    el("div", {class: "buttons"}, el("button", {type: "button", "data-action": "list_drawings",
      onclick: () => storedDrawings(card, list)}, "Stored drawings")),
    list,
  ];
}

async function storedDrawings(card, box) {
  const result = await act(card, "list_drawings");
  if (!result) return;
  box.replaceChildren(result.drawings.length ? el("table", {class: "drawings"},
    el("tbody", {}, result.drawings.map((d) => el("tr", {"data-slot": d.slot}, el("td", {}, `#${d.slot}`),
      el("td", {}, `${d.size_bytes} bytes`), el("td", {}, el("button", {type: "button", class: "danger",
        "data-action": "delete_drawing", "data-slot": d.slot, onclick: async () => {
          if (await act(card, "delete_drawing", {slot: d.slot}, `Delete stored drawing ${d.slot} from `
            + `${card.device.name}?`)) storedDrawings(card, box);
        }}, "Delete")))))) : el("p", {class: "facts"}, "No stored drawings."));
}

function controls(card, s) {
  const kind = card.device.kind;
  const out = [];
  if (s.prompt) out.push(promptBox(card, s));
  out.push(el("div", {class: "buttons"}, actionButtons(card, s.actions)));
  if (kind === "xyz") out.push(...xyzTools(card, s));
  if (kind === "mmu") out.push(...mmuTools(card, s));
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
  if (kind === "lineus") out.push(...lineusTools(card, s));
  return out;
}

function render(card) {
  const {device, state} = card;
  const s = state.summary;
  const stateClass = !state.online ? "offline" : s.state === "error" ? "error" : "";
  const said = Boolean(s.error && state.online && (s.state_text || "").includes(s.error));
  const live = [
    el("header", {},
      el("h3", {}, device.name), el("span", {class: "kind"}, {xyz: "da Vinci", lineus: "Line-us", mmu: "MMU3"}[device.kind]),
      el("span", {class: state.online ? "online" : "offline"}, state.online ? "online" : "offline"),
      el("div", {class: "ident"}, [device.model, device.serial && `serial ${device.serial}`,
        device.firmware && `firmware ${device.firmware}`].filter(Boolean).join(" · "))),
    // the header already says "offline": the state line gives the reason alone; a state line that already
    // names the error (the MMU's explained fault) is the alert itself, so the error is not said twice
    el("div", {class: `state ${stateClass}${said ? " error-box" : ""}`, "data-state": s.state, ...(said ? {role: "alert"} : {})},
      !state.online && s.state_text ? s.state_text.replace(/^offline: /, "") : s.state_text || s.state),
    s.error && !said ? el("div", {class: "error-box", role: "alert"}, s.error) : null,
    progressSection(card, s),
    ...(state.online ? kindSection(card, s) : []),
  ];
  card.live.replaceChildren(...live.filter(Boolean));
  // the controls hold a chosen file or typed text: rebuild them only when what applies has changed
  const key = JSON.stringify([state.online, s.actions, s.busy, Boolean(state.job), s.prompt, card.slot,
    state.status && state.status.zoffset_mm]);
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
    if (!previousJob && event.state.job) { card.preview = []; card.ink = []; loadJobs(); }
    scheduleRender(card);
  } else if (event.type === "online") {
    card.device = {...card.device, ...event.info};
  } else if (event.type === "job") {
    if (event.preview) { card.preview = event.preview; card.ink = []; }
    card.state = {...card.state, job: ["done", "failed", "cancelled"].includes(event.job.state) ? null : event.job};
    if (event.stroke) addInk(card, event.stroke);
    if (event.preview || !event.stroke) scheduleRender(card);
    if (!event.stroke && event.job.state !== "running") loadJobs();
    const cell = document.querySelector(`#jobs tr[data-job="${event.job.id}"] td[data-label="Progress"]`);
    if (cell) cell.textContent = `${Math.round(event.job.progress_percent || 0)} %`;  // the list keeps up
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
    el("td", {"data-label": "Machine"}, names(job.device)),
    el("td", {"data-label": "File", class: "file"}, job.filename || (job.params && job.params.text) || job.type,
      notesList(job)),
    el("td", {"data-label": "State", class: `job-state ${job.state}`}, job.state),
    el("td", {"data-label": "Progress"}, `${Math.round(job.progress_percent || 0)} %`),
    el("td", {"data-label": "Started"}, job.started ? new Date(job.started).toLocaleTimeString() : ""),
    el("td", {"data-label": "", class: "message"}, job.state === "running" ? el("button", {type: "button",
      class: "danger", onclick: () => cancelJob(cards.get(job.device))}, "Cancel") : job.message || ""))));
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
