// The robot's panel of the web view: the room's true walls (faint), the map's vectors as they
// are recorded, the sonar beams, the true pose and the estimated one with its uncertainty, the
// LCD's lines and the navigator. Reads the robot's feed topics (modules/pc/feed.py) only.

const COLOURS = {
  walls: "#ced4da",     // faint: what the robot should find
  map: "#1c7ed6",       // strong: what it found (the browser test looks for this blue)
  beam: "rgba(240, 62, 62, 0.55)",
  truth: "#2b8a3e",
  estimate: "#e8590c",
  ellipse: "rgba(232, 89, 12, 0.18)",
};

export function mount(section, view) {
  section.insertAdjacentHTML(
    "beforeend",
    `<div style="display:flex;flex-direction:column;gap:.3em">
       <canvas id="robot-room" width="580" height="440" style="background:#fff;border:1px solid #e9ecef"></canvas>
       <div style="display:flex;gap:1em;flex-wrap:wrap;align-items:flex-start"><div style="max-width:300px">
         <p style="margin:.2em 0">map: <b id="robot-map-count" data-vectors="0">0</b> vectors</p>
         <p style="margin:.2em 0">navigator: <b id="robot-navigator">–</b></p>
         <p style="margin:.2em 0;font-size:.85em">
           <span style="color:${COLOURS.truth}">■</span> true pose
           <span style="color:${COLOURS.estimate}">■</span> estimate (±2σ)
           <span style="color:${COLOURS.map}">■</span> map
           <span style="color:${COLOURS.walls}">■</span> walls
           <span style="color:${COLOURS.beam}">■</span> sonar</p></div>
         <pre id="robot-lcd" style="background:#c3d69b;color:#1d2b0f;padding:.5em;font:14px monospace;
           width:21ch;min-height:8em;margin:0;border:3px solid #5c6b3c"></pre>
       </div>
     </div>`,
  );
  const canvas = section.querySelector("#robot-room");
  const state = { walls: [], map: [], beams: [], truth: null, estimate: null, sigma: null };

  view.on("/robot/walls/vectors", (v) => { state.walls = v.vectors || []; draw(); });
  view.on("/robot/map/vectors", (v) => {
    state.map = v.vectors || [];
    const count = section.querySelector("#robot-map-count");
    count.textContent = state.map.length;
    count.dataset.vectors = state.map.length;
    draw();
  });
  view.on("/robot/sonar/beams", (v) => { state.beams = v.segments_m || []; draw(); });
  view.on("/robot/pose/true", (v) => { state.truth = pose(v); draw(); });
  view.on("/robot/pose/odometry", (v) => { if (!state.filtered) { state.estimate = pose(v); draw(); } });
  view.on("/robot/pose/filtered", (v) => { state.filtered = true; state.estimate = pose(v); draw(); });
  view.on("/robot/uncertainty", (v) => { state.sigma = v; draw(); });
  view.on("/robot/lcd", (v) => { section.querySelector("#robot-lcd").textContent = (v.lines || []).join("\n"); });
  view.on("/robot/navigator", (v) => {
    section.querySelector("#robot-navigator").textContent =
      `${v.state} (explore ${v.explore_mode}, ${v.steps_done} steps, last ${v.abort_reason})`;
  });

  let pending = false;
  function draw() {  // at most once a frame, however many topics changed
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; paint(canvas, state); });
  }
}

/** A foxglove.PoseInFrame as [x m, y m, heading rad]. */
function pose(message) {
  const p = message.pose.position, q = message.pose.orientation;
  return [p.x, p.y, 2 * Math.atan2(q.z, q.w)];
}

function paint(canvas, state) {
  const g = canvas.getContext("2d");
  g.clearRect(0, 0, canvas.width, canvas.height);
  const mm = [...state.walls, ...state.map];  // x1, y1, x2, y2 in mm
  const xs = [], ys = [];
  for (const [x1, y1, x2, y2] of mm) { xs.push(x1 / 1000, x2 / 1000); ys.push(y1 / 1000, y2 / 1000); }
  for (const p of [state.truth, state.estimate]) if (p) { xs.push(p[0]); ys.push(p[1]); }
  if (!xs.length) {
    g.fillStyle = "#adb5bd"; g.font = "14px sans-serif";
    g.fillText("waiting for the robot's room…", 20, 30);
    return;
  }
  const pad = 0.3;
  const x0 = Math.min(...xs) - pad, x1 = Math.max(...xs) + pad;
  const y0 = Math.min(...ys) - pad, y1 = Math.max(...ys) + pad;
  const scale = Math.min(canvas.width / (x1 - x0), canvas.height / (y1 - y0));
  const ox = (canvas.width - (x1 - x0) * scale) / 2, oy = (canvas.height - (y1 - y0) * scale) / 2;
  const X = (x) => ox + (x - x0) * scale;
  const Y = (y) => canvas.height - oy - (y - y0) * scale;  // y up, as in the room

  const segments = (list, colour, width, unit) => {
    g.strokeStyle = colour; g.lineWidth = width; g.lineCap = "round"; g.beginPath();
    for (const [ax, ay, bx, by] of list) {
      g.moveTo(X(ax / unit), Y(ay / unit)); g.lineTo(X(bx / unit), Y(by / unit));
    }
    g.stroke();
  };
  segments(state.walls, COLOURS.walls, 2, 1000);
  segments(state.beams, COLOURS.beam, 1, 1);
  segments(state.map, COLOURS.map, 3, 1000);

  if (state.estimate && state.sigma) {  // 2-sigma ellipse, axis-aligned in the room
    const [x, y] = state.estimate;
    g.fillStyle = COLOURS.ellipse; g.beginPath();
    g.ellipse(X(x), Y(y), Math.max(2, 2 * state.sigma.sigma_x_m * scale),
      Math.max(2, 2 * state.sigma.sigma_y_m * scale), 0, 0, 2 * Math.PI);
    g.fill();
  }
  robot(g, state.truth, COLOURS.truth, X, Y, scale);
  robot(g, state.estimate, COLOURS.estimate, X, Y, scale);
}

function robot(g, p, colour, X, Y, scale) {
  if (!p) return;
  const [x, y, a] = p;
  const r = Math.max(6, 0.2 * scale);  // the robot is about 40 cm across
  g.strokeStyle = colour; g.lineWidth = 2;
  g.beginPath(); g.arc(X(x), Y(y), r, 0, 2 * Math.PI); g.stroke();
  g.beginPath(); g.moveTo(X(x), Y(y));
  g.lineTo(X(x) + r * 1.4 * Math.cos(a), Y(y) - r * 1.4 * Math.sin(a)); g.stroke();
}
