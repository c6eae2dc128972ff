// The localisation as the Darmstadt program's operator's screen showed it (seed 000 §6.6, §8):
// every sensor's raw data, the synchronisation, the position store, main's action queue and the
// messages: the same panels as `tokenring console` (modules/pc/console/state.py), as lines of
// text. Reads the feed's topics only (modules/pc/feed.py); every field may be missing (a ring
// without copro, a feed without a topic), and then the line says so or shows "?".

const SENSORS = [  // [name, channel], in the order the seed's screen listed them
  ["odometry", "motor.data"],
  ["gyro", "gyro.data"],
  ["correlator", "correlator.data"],
  ["compass", "compass.data"],
  ["sonar", "sonar.data"],
  ["battery", "charger.data"],
];
const QUEUE_SHOWN = 12;
const MESSAGES_SHOWN = 200;

export function mount(section, view) {
  section.insertAdjacentHTML(
    "beforeend",
    `<style>
       #panel-localisation .loc-grid { display: grid; grid-template-columns: 1fr 1fr; gap: .5em .8em; }
       #panel-localisation h3 { font-size: .85em; margin: .2em 0; color: #495057; }
       #panel-localisation .loc-lines { font: 12px monospace; white-space: pre; overflow-x: auto;
         background: #f8f9fa; border: 1px solid #e9ecef; padding: .3em .4em; min-height: 3em; }
       #panel-localisation .loc-wide { grid-column: 1 / -1; }
       #loc-messages { max-height: 12em; overflow-y: auto; }
       #loc-messages [data-class="E"], #loc-messages [data-class="F"] { color: #c92a2a; }
       #loc-messages [data-class="W"] { color: #e8590c; }
     </style>
     <div class="loc-grid">
       <div class="loc-wide"><h3>Sensors (raw data)</h3><div id="loc-sensors" class="loc-lines"></div></div>
       <div><h3>Synchronisation</h3><div id="loc-sync" class="loc-lines"></div></div>
       <div><h3>Action queue (main)</h3><div id="loc-queue" class="loc-lines"></div></div>
       <div class="loc-wide"><h3>Position store</h3><div id="loc-positions" class="loc-lines"></div></div>
       <div class="loc-wide"><h3>Messages</h3><div id="loc-messages" class="loc-lines"></div></div>
     </div>`,
  );
  const state = {
    channels: {}, updates: {}, localization: null, truth: null, main: null, navigator: null, answering: null,
  };
  const enums = enumNames(view.config && view.config.enums);
  const $ = (id) => section.querySelector(`#${id}`);

  for (const [, channel] of SENSORS) {
    view.on(`/channel/${channel}`, (data) => {
      state.channels[channel] = data;
      state.updates[channel] = (state.updates[channel] || 0) + 1;
      draw();
    });
  }
  view.on("/robot/localization", (data) => { state.localization = data; draw(); });
  view.on("/robot/pose/true", (data) => { state.truth = truePose(data); draw(); });
  view.on("/robot/main", (data) => { state.main = data; draw(); });
  view.on("/robot/navigator", (data) => { state.navigator = data; draw(); });
  view.on("/robot/messages", (data) => showMessages($("loc-messages"), data));
  view.on("/ring/nodes", (data) => {  // which nodes answer: a silent node's channel is only zeros
    const ids = new Set(Object.keys(object(data?.nodes)));
    state.answering = new Set((view.config?.nodes || []).filter((n) => ids.has(String(n.id))).map((n) => n.name));
    draw();
  });

  let pending = false;
  function draw() {  // at most once a frame, however many topics changed
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => {
      pending = false;
      fill($("loc-sensors"), sensorLines(state, enums));
      fill($("loc-sync"), syncLines(state.localization).map((text) => [text]));
      fill($("loc-positions"), positionLines(state).map(([name, text]) => [text, name]));
      fill($("loc-queue"), queueLines(state).map((text) => [text]));
    });
  }
  draw();
}

/** Replace ``element``'s lines by ``lines`` ([text, name]: each line a div, named by data-line). */
function fill(element, lines) {
  const divs = lines.map(([text, name]) => {
    const div = document.createElement("div");
    div.textContent = text;
    if (name) div.dataset.line = name;
    return div;
  });
  element.replaceChildren(...divs);
}

// -- sensors ----------------------------------------------------------------------------------
function sensorLines(state, enums) {
  const lines = [];
  for (const [sensor, channel] of SENSORS) {
    const data = state.channels[channel];
    if (!data) continue;
    const node = channel.split(".")[0];
    let text;
    if (state.answering && !state.answering.has(node)) text = `(no ${node} node answers on this ring)`;
    else try { text = raw(sensor, data, enums); } catch (error) { text = `(${error})`; }
    lines.push([`${sensor.padEnd(10)} ${text}  (${state.updates[channel] || 0})`, sensor]);
  }
  const lops = object(object(state.localization?.sensors).lops);
  if (Object.keys(lops).length) lines.push([`${"lops".padEnd(10)} ${values(lops.values ?? lops)}`, "lops"]);
  return lines.length ? lines : [["(no sensor data yet: is the ring up?)"]];
}

/** A sensor's raw data in a line, its most telling fields first (as the console's). */
function raw(sensor, d, enums) {
  if (sensor === "odometry") {
    return `steps ${d.steps_left} / ${d.steps_right}  x ${num(d.x_mm)} y ${num(d.y_mm)} mm  `
      + `ψ ${num(wireDegrees(d.angle_cdeg), 2)}°  ${enums.name("motor_state", d.state)}  t ${d.stamp_ms}`;
  }
  if (sensor === "gyro") {
    return `rate ${signed((d.rate_urad_s ?? NaN) / 1e6, 6)} rad/s  angle ${signed((d.angle_mrad ?? NaN) / 1000, 3)} rad  `
      + `sample ${d.sample}  t ${d.stamp_ms}`;
  }
  if (sensor === "correlator") {
    return `forward ${num((d.forward_um ?? NaN) / 1000, 1)} mm  sample ${d.sample}  t ${d.stamp_ms}`;
  }
  if (sensor === "compass") {
    return `heading ${num((d.heading_cdeg ?? NaN) / 100, 2)}°  ${enums.name("compass_state", d.state)}  t ${d.stamp_ms}`;
  }
  if (sensor === "battery") {
    return `motors ${num((d.motors_mv ?? NaN) / 1000, 2)} V ${d.motors_pct} %  electronics `
      + `${num((d.electronics_mv ?? NaN) / 1000, 2)} V  ${d.remaining_min} min left`;
  }
  if (sensor === "sonar") {
    const distances = (d.distances || []).map((v) => (v === 255 ? "--" : String(v))).join(" ");
    return `${distances} cm  sweep ${d.sweep}`;
  }
  return values(d);
}

/** A wire angle (1/100 degree, clockwise) as degrees counter-clockwise in (-180, 180]. */
function wireDegrees(cdeg) {
  if (typeof cdeg !== "number") return NaN;
  let deg = -(cdeg / 100) % 360;
  if (deg <= -180) deg += 360;
  if (deg > 180) deg -= 360;
  return deg;
}

// -- synchronisation and the position store ---------------------------------------------------
function syncLines(snapshot) {
  if (!snapshot) return ["(no localisation on this ring, or not yet heard from)"];
  const sync = object(snapshot.sync);
  const rule = sync.mode === "count" ? `every ${sync.count} sample(s)`
    : sync.mode === "rounds" ? `every ${sync.rounds} round(s)` : `every ${sync.period_ms} ms`;
  return [
    `trigger    ${sync.sensor ?? "the token"}, ${rule} (${sync.mode ?? "?"})`,
    `syncs      ${sync.syncs ?? 0}${sync.skipped ? `, ${sync.skipped} grid times skipped` : ""}`,
    `period     last ${num(sync.last_period_ms)} ms, mean ${num(sync.mean_period_ms)} ms`,
  ];
}

function positionLines(state) {
  const snapshot = state.localization;
  const lines = [];
  for (const [name, p] of Object.entries(object(snapshot?.positions))) {
    if (!p || typeof p !== "object") continue;
    lines.push([name, `${name.padEnd(10)} ${placed(p)}  ${validity(p)}`]);
  }
  // the best pose (the filter's, with its σ) and the simulator's truth: named as the console does,
  // apart from the store's own "filter" and "truth" entries above
  const best = object(snapshot?.filter);
  if (typeof best.x_mm === "number") {
    const s = object(best.sigma);
    lines.push(["best", `${"best".padEnd(10)} ${placed(best)}  σ ${num(s.x_mm, 1)}/${num(s.y_mm, 1)} mm `
      + `${num(degrees(s.heading_rad), 2)}°  (${best.source ?? "?"})`]);
  }
  if (state.truth && !("truth" in object(snapshot?.positions))) {
    const [x, y, theta] = state.truth;
    lines.push(["truth", `${"truth".padEnd(10)} x ${num(x).padStart(7)} mm  y ${num(y).padStart(7)} mm  `
      + `ψ ${num(degrees(theta), 2).padStart(7)}°  (the simulator's)`]);
  }
  return lines.length ? lines : [["", "(no positions yet)"]];
}

function placed(p) {
  return `x ${num(p.x_mm).padStart(7)} mm  y ${num(p.y_mm).padStart(7)} mm  ψ ${num(degrees(p.heading_rad), 2).padStart(7)}°`;
}

/** Table B.7's validity bits: X, Y, P(si), "-" where not valid. */
function validity(p) {
  return [["X", p.x_valid], ["Y", p.y_valid], ["P", p.heading_valid]].map(([c, v]) => (v ? c : "-")).join("");
}

function truePose(message) {
  const p = message?.pose?.position, q = message?.pose?.orientation;
  if (!p || !q) return null;
  return [p.x * 1000, p.y * 1000, 2 * Math.atan2(q.z, q.w)];
}

// -- main's action queue ----------------------------------------------------------------------
function queueLines(state) {
  const main = state.main;
  if (!main) {
    const nav = state.navigator;
    const head = nav ? `navigator ${nav.state}, last abort ${nav.abort_reason}` : "(no word from main yet)";
    return [head, "  (the queue: waiting for main's state)"];
  }
  if (main.error) return [`(main: ${main.error})`];
  const queue = Array.isArray(main.queue) ? main.queue : [];
  const lines = [`navigator ${main.navigator ?? "?"}, last abort ${main.abort_reason ?? "?"}`];
  queue.slice(0, QUEUE_SHOWN).forEach((text, i) => lines.push(`${i === 0 ? "▶" : " "} ${text}`));
  if (queue.length > QUEUE_SHOWN) lines.push(`  … ${queue.length - QUEUE_SHOWN} more`);
  if (!queue.length) lines.push("  (queue empty)");
  return lines;
}

// -- messages ---------------------------------------------------------------------------------
function showMessages(element, data) {
  const messages = Array.isArray(data?.messages) ? data.messages.slice(-MESSAGES_SHOWN) : [];
  const atEnd = element.scrollTop + element.clientHeight >= element.scrollHeight - 4;
  const divs = messages.map((m) => {
    const div = document.createElement("div");
    const cls = String(m?.class ?? "?").slice(0, 1);
    div.dataset.class = cls;
    div.textContent = `${cls} ${String(Math.trunc(Number(m?.stamp_ms) || 0)).padStart(9)} ${m?.text ?? ""}`;
    return div;
  });
  if (!divs.length) divs.push(Object.assign(document.createElement("div"), { textContent: "(no messages yet)" }));
  element.replaceChildren(...divs);
  if (atEnd) element.scrollTop = element.scrollHeight;  // follow the newest unless scrolled back
}

// -- helpers ----------------------------------------------------------------------------------
/** protocol.yaml's enums (from /api/config) by value: the name in lower case, else the number. */
function enumNames(enums) {
  const byValue = {};
  for (const [name, members] of Object.entries(enums || {})) {
    byValue[name] = new Map(Object.entries(members || {}).map(([k, v]) => [v, k.toLowerCase()]));
  }
  return { name: (enumName, value) => byValue[enumName]?.get(value) ?? String(value) };
}

function object(value) {
  return value && typeof value === "object" && !Array.isArray(value) ? value : {};
}

function values(data) {
  if (!data || typeof data !== "object") return String(data);
  return Object.entries(data).filter(([, v]) => v === null || typeof v !== "object")
    .map(([k, v]) => `${k} ${v}`).join("  ");
}

function degrees(rad) {
  return typeof rad === "number" ? (rad * 180) / Math.PI : NaN;
}

function num(value, digits = 0) {
  return typeof value === "number" && Number.isFinite(value) ? value.toFixed(digits) : "?";
}

function signed(value, digits) {
  return typeof value === "number" && Number.isFinite(value) ? (value >= 0 ? "+" : "") + value.toFixed(digits) : "?";
}
