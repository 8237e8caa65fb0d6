// The file library, the print queues and application-key requests: a section of the dashboard of its own.
// Uses app.js's helpers (el, call, toast, duration); fed by /api/v1/devices/ID/library and /api/v1/appkeys.
"use strict";

const LIBRARY_REFRESH_MS = 2000;
const previews = new Map();          // "device/name/uploaded" -> object URL of the preview image

function librarySection() {
  let section = document.getElementById("library-section");
  if (!section) {
    section = el("section", {id: "library-section"}, el("div", {id: "key-requests"}), el("h2", {}, "Library"),
      el("div", {id: "library"}, el("p", {class: "empty"}, "Loading files…")));
    document.getElementById("jobs-section").before(section);
  }
  return section;
}

function megabytes(bytes) {
  return bytes >= 1e6 ? `${(bytes / 1e6).toFixed(1)} MB` : `${Math.max(1, Math.round(bytes / 1e3))} kB`;
}

async function previewImage(device, entry) {
  if (!entry.thumbnails.length) return el("div", {class: "preview none"}, "no preview");
  const key = `${device}/${entry.name}/${entry.uploaded}`;
  if (!previews.has(key)) {
    const headers = token ? {Authorization: `Bearer ${token}`} : {};
    const path = `${API}/devices/${encodeURIComponent(device)}/library/${entry.name.split("/")
      .map(encodeURIComponent).join("/")}/thumbnail`;
    const response = await fetch(path, {headers});
    previews.set(key, response.ok ? URL.createObjectURL(await response.blob()) : "");
  }
  const url = previews.get(key);
  return url ? el("img", {class: "preview", src: url, alt: `preview of ${entry.name}`})
    : el("div", {class: "preview none"}, "no preview");
}

async function libraryDo(what, method, path, body) {
  try {
    await call(method, path, body);
    toast(what);
  } catch (error) {
    toast(error.message, true);
  }
  refreshLibrary();
}

function libraryPath(device, name) {
  return `/devices/${encodeURIComponent(device)}/library/${name.split("/").map(encodeURIComponent).join("/")}`;
}

// What each kind of machine does with a file, the figures its library shows, and where its files come from, in
// its own words. Each column: its heading and what it shows of an entry's `meta` ("–" where a file does not say).
const WORK = {
  lineus: {verb: "Draw", doing: "drawing", things: "drawings",
    columns: [["Drawing time", (meta) => duration(meta.print_time_s)],
      ["Pen down", (meta) => meta.pen_down_mm ? `${Math.round(meta.pen_down_mm)} mm` : null],
      ["Strokes", (meta) => meta.strokes]],
    empty: (address) => `No drawings yet: send an SVG or Line-us G-code to this machine's print-host address, ${address}.`},
  xyz: {verb: "Print", doing: "printing", things: "prints",
    columns: [["Print time", (meta) => duration(meta.print_time_s)],
      ["Filament", (meta) => meta.filament_mm ? `${(meta.filament_mm / 1000).toFixed(2)} m` : null],
      ["Layers", (meta) => meta.layers], ["Slicer", (meta) => meta.slicer]],
    empty: (address) => `No files yet: send one from your slicer to this machine's print-host address, ${address}.`},
};

async function machineLibrary(device, listing) {
  const base = `/devices/${encodeURIComponent(device.id)}`;
  const work = WORK[device.kind] || WORK.xyz;
  const rows = await Promise.all(listing.files.map(async (entry) => {
    const meta = entry.meta;
    return el("tr", {"data-file": entry.name},
      el("td", {}, await previewImage(device.id, entry)),
      el("td", {class: "file-name"}, entry.name, listing.selected === entry.name ? el("span", {class: "kind"}, " selected") : null),
      ...work.columns.map(([, shown]) => el("td", {}, shown(meta) || "–")), el("td", {}, megabytes(entry.size)),
      el("td", {}, `${entry.prints.success} ✓ ${entry.prints.failure} ✗`),
      el("td", {class: "buttons"},
        el("button", {type: "button", onclick: () => libraryDo(`${work.doing} ${entry.name}`, "POST",
          `${libraryPath(device.id, entry.name)}/print`), disabled: !listing.ready, title: listing.refusal || ""},
          work.verb),
        el("button", {type: "button", onclick: () => libraryDo(`${entry.name} queued`, "POST", `${base}/queue`,
          {name: entry.name})}, "Queue"),
        el("button", {type: "button", class: "danger", onclick: () => window.confirm(`Delete ${entry.name}?`)
          && libraryDo(`${entry.name} deleted`, "DELETE", libraryPath(device.id, entry.name))}, "Delete")));
  }));
  const queue = listing.queue;
  const move = (index, by) => {
    const order = [...queue];
    const [name] = order.splice(index, 1);
    if (by !== null) order.splice(index + by, 0, name);
    return order;
  };
  const queueItems = queue.map((name, index) => el("li", {"data-queued": name}, name, " ",
    el("button", {type: "button", title: "earlier", disabled: index === 0,
      onclick: () => libraryDo("queue reordered", "PUT", `${base}/queue`, {order: move(index, -1)})}, "↑"),
    el("button", {type: "button", title: "later", disabled: index === queue.length - 1,
      onclick: () => libraryDo("queue reordered", "PUT", `${base}/queue`, {order: move(index, 1)})}, "↓"),
    el("button", {type: "button", title: "remove from the queue",
      onclick: () => libraryDo(`${name} left the queue`, "PUT", `${base}/queue`, {order: move(index, null)})}, "✕")));
  return el("div", {class: "library-machine", "data-device": device.id},
    el("h3", {}, device.name, " ", listing.ready ? el("span", {class: "kind"}, "ready")
      : el("span", {class: "refusal"}, listing.refusal || "")),
    listing.files.length ? el("table", {class: "library"}, el("thead", {}, el("tr", {},
      ...["Preview", "File", ...work.columns.map(([heading]) => heading), "Size", `${work.verb}s`, ""]
        .map((h) => el("th", {}, h)))),
      el("tbody", {}, rows)) : el("p", {class: "empty"},
        work.empty(`${location.origin}/printers/${encodeURIComponent(device.name)}`)),
    el("div", {class: "queue"},
      el("label", {}, el("input", {type: "checkbox", checked: listing.queue_enabled, onchange: (event) =>
        libraryDo(event.target.checked ? "queue on" : "queue off", "PUT", `${base}/queue`,
          {enabled: event.target.checked})}), ` Queue ${work.things} sent while busy`),
      queue.length ? el("ol", {class: "queue-list"}, queueItems) : el("span", {class: "empty"}, " (queue empty)"),
      el("button", {type: "button", disabled: !queue.length || !listing.ready,
        onclick: () => libraryDo("starting the next file", "POST", `${base}/queue/next`)}, "Start next")));
}

async function keyRequests() {
  const pending = await call("GET", "/appkeys");
  document.getElementById("key-requests").replaceChildren(...pending.map((request) => el("div",
    {class: "error-box key-request", "data-request": request.id},
    `${request.app}${request.user ? ` (${request.user})` : ""} from ${request.remote} asks for this agent's key. `,
    el("button", {type: "button", onclick: () => libraryDo(`${request.app} may use the agent`, "POST",
      `/appkeys/${encodeURIComponent(request.id)}/approve`)}, "Approve"), " ",
    el("button", {type: "button", class: "danger", onclick: () => libraryDo(`${request.app} refused`, "POST",
      `/appkeys/${encodeURIComponent(request.id)}/deny`)}, "Deny"))));
}

let libraryBusy = false;
async function refreshLibrary() {
  if (libraryBusy) return;
  libraryBusy = true;
  try {
    librarySection();
    await keyRequests();
    const devices = (await call("GET", "/devices")).filter((d) => d.kind !== "mmu");
    const parts = await Promise.all(devices.map(async (device) =>
      machineLibrary(device, await call("GET", `/devices/${encodeURIComponent(device.id)}/library`))));
    document.getElementById("library").replaceChildren(...parts);
  } catch (error) {
    document.getElementById("library").replaceChildren(el("p", {class: "empty"}, error.message));
  } finally {
    libraryBusy = false;
  }
}

setInterval(refreshLibrary, LIBRARY_REFRESH_MS);
refreshLibrary();
