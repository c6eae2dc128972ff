// The ring's page: builds itself from /api/config, follows /ws (coalesced topics, <= 10/s),
// and injects faults / runs actions / sends keys through the server's POST endpoints. Plain ES
// modules, no build step, nothing from the network but this server.

const $ = (id) => document.getElementById(id);
const listeners = new Map();   // topic -> [callback]
const latest = new Map();      // topic -> last value
let config = null;

/** What a panel module gets in mount(element, view). */
const view = {
  on(topic, callback) {
    if (!listeners.has(topic)) listeners.set(topic, []);
    listeners.get(topic).push(callback);
    if (latest.has(topic)) callback(latest.get(topic), topic);
  },
  latest: (topic) => latest.get(topic),
  action: (name) => post(`/api/action/${encodeURIComponent(name)}`, {}),
  post,
  get config() { return config; },
};

async function post(url, body) {
  const response = await fetch(url, {
    method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body),
  });
  let answer;
  try { answer = await response.json(); } catch { answer = { ok: false, error: response.statusText }; }
  return answer;
}

function deliver(topic, value) {
  latest.set(topic, value);
  for (const callback of listeners.get(topic) || []) {
    try { callback(value, topic); } catch (error) { console.error(topic, error); }
  }
}

function connect() {
  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  const link = $("link");
  ws.onopen = () => { link.dataset.state = "open"; link.textContent = "live"; };
  ws.onmessage = (event) => {
    const update = JSON.parse(event.data);
    for (const [topic, value] of Object.entries(update.topics)) deliver(topic, value);
  };
  ws.onclose = () => {
    link.dataset.state = "closed"; link.textContent = "disconnected, retrying…";
    setTimeout(connect, 1000);
  };
}

// -- the token -------------------------------------------------------------------------------
const passes = [];  // [ms, frames] of the last seconds: the pass rate
function showToken(token) {
  $("token-frames").textContent = token.frames;
  $("token-frames").dataset.frames = token.frames;
  $("token-counter").textContent = token.counter ?? "–";
  $("token-holder").dataset.holder = token.holder ?? "";
  $("token-holder").textContent = nodeName(token.holder);
  const now = performance.now();
  passes.push([now, token.frames]);
  while (passes.length > 2 && now - passes[0][0] > 2000) passes.shift();
  if (passes.length > 1) {
    const [t0, f0] = passes[0];
    if (now > t0) $("token-rate").textContent = Math.round(((token.frames - f0) * 1000) / (now - t0));
  }
  for (const row of document.querySelectorAll("#nodes tbody tr")) {
    row.classList.toggle("holder", row.dataset.nodeId === String(token.holder));
  }
  drawRing();
}

function nodeName(id) {
  const node = config && config.nodes.find((n) => n.id === id);
  return node ? `${node.name} (${id})` : id == null ? "–" : String(id);
}

// -- round trips -----------------------------------------------------------------------------
function showRoundtrip(rt) {
  const values = rt.samples.map((s) => s[1]);
  $("rt-last").textContent = rt.ms.toFixed(2);
  $("rt-last").dataset.ms = rt.ms;
  const sorted = [...values].sort((a, b) => a - b);
  $("rt-median").textContent = sorted.length ? sorted[sorted.length >> 1].toFixed(2) : "–";
  $("rt-count").textContent = values.length;
  const canvas = $("rt-spark");
  const g = canvas.getContext("2d");
  g.clearRect(0, 0, canvas.width, canvas.height);
  if (values.length < 2) return;
  const top = Math.max(...values) * 1.1 || 1;
  const dx = canvas.width / (values.length - 1);
  g.strokeStyle = "#1971c2"; g.lineWidth = 1.5; g.beginPath();
  values.forEach((v, i) => {
    const y = canvas.height - (v / top) * (canvas.height - 4) - 2;
    i ? g.lineTo(i * dx, y) : g.moveTo(0, y);
  });
  g.stroke();
  g.fillStyle = "#7a8490"; g.font = "10px sans-serif";
  g.fillText(`${top.toFixed(1)} ms`, 2, 10);
}

// -- nodes, counters, faults -----------------------------------------------------------------
let ringNodes = { nodes: {}, faults: {} };
const COUNTERS = [
  (s) => s.stats.visits,
  (s) => s.stats.tokens_regenerated,
  (s) => s.stats.pass_retries,
  (s) => s.stats.rejected_crc,
  (s) => s.stats.inbox_full,
];

function buildTable() {
  const body = document.querySelector("#nodes tbody");
  body.textContent = "";
  for (const node of config.nodes) {
    const row = document.createElement("tr");
    row.dataset.nodeId = node.id;
    row.id = `node-${node.id}`;
    const cells = [node.id, node.name, "–", ...COUNTERS.map(() => "–"), ""];
    for (const text of cells) {
      const cell = document.createElement("td");
      cell.textContent = text;
      row.append(cell);
    }
    row.cells[row.cells.length - 1].className = "faults";
    row.cells[row.cells.length - 1].dataset.faults = "";
    const clear = document.createElement("button");
    clear.textContent = "clear";
    clear.className = "clear-fault";
    clear.dataset.node = node.id;
    clear.title = `clear every fault on ${node.name}`;
    clear.onclick = () => injectFault({ node: node.id, kind: "clear" });
    const last = document.createElement("td");
    last.append(clear);
    row.append(last);
    body.append(row);
  }
}

function showNodes(value) {
  ringNodes = value;
  for (const node of config.nodes) {
    const row = $(`node-${node.id}`);
    if (!row) continue;
    const stats = value.nodes[String(node.id)];
    row.classList.toggle("silent", !stats);
    row.cells[2].textContent = stats ? stats.successor ?? "–" : "–";
    COUNTERS.forEach((get, i) => { row.cells[3 + i].textContent = stats ? get(stats) : "–"; });
    const faults = value.faults[String(node.id)];
    const names = faults ? Object.entries(faults).map(([kind, spec]) => describeFault(kind, spec)) : [];
    const cell = row.querySelector("td.faults");
    cell.textContent = names.join(", ") || (stats ? "" : "no answer");
    cell.dataset.faults = faults ? Object.keys(faults).sort().join(",") : "";
  }
  $("chain").textContent = chain(value.nodes);
  drawRing();
}

function describeFault(kind, spec) {
  const options = Object.entries(spec).filter(([k]) => !["kind", "since"].includes(k));
  return options.length ? `${kind} (${options.map(([k, v]) => `${k}=${v}`).join(", ")})` : kind;
}

function chain(nodes) {
  const ids = Object.keys(nodes).map(Number).sort((a, b) => a - b);
  if (!ids.length) return "–";
  const seen = new Set();
  const out = [];
  let at = ids[0];
  while (at != null && !seen.has(at) && nodes[String(at)]) {
    seen.add(at); out.push(at);
    at = nodes[String(at)].successor;
  }
  if (at != null) out.push(at);
  return out.map((id) => nodeName(id).split(" ")[0]).join(" → ");
}

function drawRing() {
  const canvas = $("ring-canvas");
  if (!config) return;
  const g = canvas.getContext("2d");
  const w = canvas.width, h = canvas.height, r = Math.min(w, h) / 2 - 48;
  g.clearRect(0, 0, w, h);
  const token = latest.get("/web/token") || {};
  const place = new Map();
  config.nodes.forEach((node, i) => {
    const a = -Math.PI / 2 + (2 * Math.PI * i) / config.nodes.length;
    place.set(node.id, [w / 2 + r * Math.cos(a), h / 2 + r * Math.sin(a)]);
  });
  g.strokeStyle = "#adb5bd"; g.lineWidth = 1.5;
  for (const node of config.nodes) {  // successor arrows
    const stats = ringNodes.nodes[String(node.id)];
    if (!stats || !place.has(stats.successor)) continue;
    const [x0, y0] = place.get(node.id), [x1, y1] = place.get(stats.successor);
    const a = Math.atan2(y1 - y0, x1 - x0), len = Math.hypot(x1 - x0, y1 - y0) - 18;
    const xe = x0 + Math.cos(a) * len, ye = y0 + Math.sin(a) * len;
    g.beginPath(); g.moveTo(x0 + Math.cos(a) * 18, y0 + Math.sin(a) * 18); g.lineTo(xe, ye); g.stroke();
    g.beginPath(); g.moveTo(xe, ye);
    g.lineTo(xe - 7 * Math.cos(a - 0.4), ye - 7 * Math.sin(a - 0.4));
    g.lineTo(xe - 7 * Math.cos(a + 0.4), ye - 7 * Math.sin(a + 0.4)); g.closePath(); g.fill();
  }
  for (const node of config.nodes) {
    const [x, y] = place.get(node.id);
    const alive = Boolean(ringNodes.nodes[String(node.id)]);
    const faulted = Object.keys(ringNodes.faults[String(node.id)] || {}).length > 0;
    g.beginPath(); g.arc(x, y, 16, 0, 2 * Math.PI);
    g.fillStyle = token.holder === node.id ? "#e8590c" : alive ? "#e7f5ff" : "#f1f3f5";
    g.fill();
    g.lineWidth = faulted ? 3 : 1.5;
    g.strokeStyle = faulted ? "#c92a2a" : alive ? "#1971c2" : "#adb5bd";
    g.stroke();
    g.fillStyle = token.holder === node.id ? "#fff" : "#1d232b";
    g.font = "11px sans-serif"; g.textAlign = "center"; g.textBaseline = "middle";
    g.fillText(String(node.id), x, y);
    g.fillStyle = "#495057";
    const out = 1 + 30 / r;
    g.fillText(node.name, w / 2 + (x - w / 2) * out, h / 2 + (y - h / 2) * out);
  }
  g.fillStyle = "#1d232b"; g.font = "bold 13px sans-serif";
  g.fillText(`round ${token.counter ?? "–"}`, w / 2, h / 2);
}

// -- the fault form --------------------------------------------------------------------------
async function injectFault(body) {
  const answer = await post("/api/fault", body).catch((e) => ({ ok: false, error: String(e) }));
  const out = $("fault-answer");
  out.dataset.ok = String(Boolean(answer.ok));
  if (!answer.ok) { out.textContent = answer.error; return answer; }
  out.textContent = answer.results
    .map((r) => r.error || `${r.node} (${r.id}): ${body.kind} → active faults: ${Object.keys(r.faults || {}).join(", ") || "none"}`)
    .join("; ");
  return answer;
}

function buildForm() {
  const nodeSelect = $("fault-node"), kindSelect = $("fault-kind"), value = $("fault-value");
  for (const node of config.nodes) nodeSelect.add(new Option(`${node.name} (${node.id})`, node.id));
  for (const kind of config.fault_kinds) kindSelect.add(new Option(kind, kind));
  const hint = () => {
    const need = config.needs_value[kindSelect.value];
    value.disabled = !need; value.placeholder = need || "";
  };
  kindSelect.onchange = hint; hint();
  $("fault-form").onsubmit = (event) => {
    event.preventDefault();
    const body = { node: nodeSelect.value === "all" ? "all" : Number(nodeSelect.value), kind: kindSelect.value };
    if (!value.disabled) body.value = value.value;
    injectFault(body);
  };
}

function buildActions() {
  if (!config.actions.length) return;
  $("actions").hidden = false;
  for (const action of config.actions) {
    const button = document.createElement("button");
    button.textContent = action.label;
    button.dataset.action = action.name;
    button.onclick = async () => {
      const answer = await view.action(action.name).catch((e) => ({ ok: false, error: String(e) }));
      const out = $("action-answer");
      out.dataset.ok = String(Boolean(answer.ok));
      out.textContent = answer.ok ? `${action.label}: ${answer.result.summary ?? "done"}` : answer.error;
    };
    $("action-buttons").append(button);
  }
}

// -- the keyboard: keys the page has focus for go to the application's key handler, in order --
const IGNORED_KEYS = new Set([
  "Shift", "Control", "Alt", "AltGraph", "Meta", "OS", "Hyper", "Super", "CapsLock", "NumLock",
  "ScrollLock", "Fn", "FnLock", "Tab", "ContextMenu", "Dead", "Unidentified", "Process", "Compose",
]);
const keyLabels = new Map();   // KeyboardEvent.key -> how the page shows it
let keyChain = Promise.resolve();
let keyCount = 0;

function typing(target) {
  return target instanceof Element
    && (target.isContentEditable || ["INPUT", "TEXTAREA", "SELECT"].includes(target.tagName));
}

/** Whether this keydown/keyup is the keyboard's (not a shortcut, not typing, not the browser's). */
function forKeys(event) {
  if (event.ctrlKey || event.altKey || event.metaKey || typing(event.target)) return false;
  if (IGNORED_KEYS.has(event.key) || /^F\d+$/.test(event.key)) return false;
  // Enter on a button or link presses that, not the application's key
  return !(event.key === "Enter" && event.target instanceof Element && event.target.closest("button, a"));
}

function buildKeys() {
  if (!config.keys) return;
  $("keys").hidden = false;
  const help = $("key-help");
  for (const key of config.keys.keys) {
    for (const value of key.values) keyLabels.set(value, key.label);
    const item = document.createElement("span");
    const kbd = document.createElement("kbd");
    kbd.textContent = key.label;
    item.append(kbd, ` ${key.meaning}`);
    help.append(item, " ");
  }
  $("key-note").textContent = config.keys.note || "";
  document.addEventListener("keydown", (event) => {
    if (!forKeys(event)) return;
    if (keyLabels.has(event.key)) event.preventDefault();  // the arrows and space scroll no page
    if (!event.repeat) sendKey(event.key);  // a held key counts once
  });
  document.addEventListener("keyup", (event) => {  // space on a focused button presses no button
    if (forKeys(event) && keyLabels.has(event.key)) event.preventDefault();
  });
  const focus = () => {
    const has = document.hasFocus();
    $("key-focus").dataset.focus = String(has);
    $("key-focus").textContent = has ? "(the page has the keyboard)" : "(click the page to give it the keyboard)";
  };
  window.addEventListener("focus", focus);
  window.addEventListener("blur", focus);
  focus();
}

function sendKey(key) {
  const shown = key.length === 1 && key !== " " ? key : keyLabels.get(key) ?? (key === " " ? "space" : key);
  const status = $("key-status");
  status.dataset.ok = "";
  status.textContent = `${shown} …`;
  // one after another: the server carries keys out in the order they arrive
  keyChain = keyChain.then(async () => {
    const answer = await post("/api/key", { key }).catch((e) => ({ ok: false, error: String(e) }));
    showKey(shown, answer.text ?? answer.error ?? "no answer", Boolean(answer.ok));
  });
}

function showKey(shown, text, ok) {
  keyCount += 1;
  const status = $("key-status");
  status.textContent = `${shown}: ${text}`;
  status.dataset.ok = String(ok);
  status.dataset.count = String(keyCount);
  const item = document.createElement("li");
  item.textContent = `${new Date().toLocaleTimeString()} ${shown}: ${text}`;
  item.dataset.ok = String(ok);
  $("key-log").prepend(item);
  while ($("key-log").children.length > 30) $("key-log").lastChild.remove();
}

function showEvent(event) {
  const item = document.createElement("li");
  item.textContent = `${new Date().toLocaleTimeString()} ${event.kind} node ${event.node} (by ${event.by}, epoch ${event.epoch})`;
  $("events").prepend(item);
  while ($("events").children.length > 50) $("events").lastChild.remove();
}

async function mountPanels() {
  for (const panel of config.panels) {
    const section = document.createElement("section");
    section.className = "card panel";
    section.id = `panel-${panel.name}`;
    const title = document.createElement("h2");
    title.textContent = panel.title;
    section.append(title);
    $("panels").append(section);
    try {
      const module = await import(panel.url);
      module.mount(section, view);
    } catch (error) {
      section.append(`this panel failed to load: ${error}`);
    }
  }
}

async function start() {
  config = await (await fetch("/api/config")).json();
  $("ring-name").textContent = config.ring;
  document.title = `tokenring ${config.ring}`;
  buildTable(); buildForm(); buildActions(); buildKeys();
  view.on("/web/token", showToken);
  view.on("/ring/roundtrip", showRoundtrip);
  view.on("/ring/nodes", showNodes);
  view.on("/ring/event", showEvent);
  await mountPanels();
  drawRing();
  connect();
  document.body.dataset.ready = "true";
}

start();
