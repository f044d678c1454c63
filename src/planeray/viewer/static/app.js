// planeray viewer: the page.  Talks to the server over one WebSocket (protocol: planeray/viewer/server.py),
// paints float32 frames into <canvas> elements through a 4096-entry colour table (planeray/viewer/display.py
// does the same mapping in Python), draws the pixel plots (plot.js).  No library, no network but the server.
"use strict";

const QUERY = new URLSearchParams(location.search);
const TOKEN = QUERY.get("token") || "";
// ?bench=SECONDS[&size=...]: sweep the delay of panel 0 for that long, then report the measured frame rates
// and timings to the server ({"type": "report"}); benchmarks/bench_viewer.py reads them without any
// debugging protocol attached to the browser (which would copy every frame).
const BENCH_S = Number(QUERY.get("bench") || 0);
// &input_hz=N: the sweep moves the slider N times a second on a timer instead of once per displayed frame
// (to measure what the pipeline delivers beyond the display's refresh rate, with vsync off).
const INPUT_HZ = Number(QUERY.get("input_hz") || 0);
const MAX_INFLIGHT = 2;       // render requests in flight per panel (pipelining render, transfer and paint)
const LEVELS = 4095;          // quantization of value / white before the gamma and colour tables
const PALETTE = ["#f0a030", "#6fc3ff", "#9be38f", "#ff7fa8", "#c9a6ff", "#ffe066", "#5fd3c7"];

const app = {
  ws: null, source: null, colormaps: null, version: null, panels: [], nextId: 0,
  plot: null, plotState: null, connected: false, framesPainted: 0, paintLog: [],
  stats: { render: [], encode: [], queue: [], transfer: [], decode: [], paint: [], latency: [], slider: [] },
  sentAt: new Map(), inputAt: new Map(), lastSnapshot: null, lastStack: null, errors: [],
};
window.planeray = app;

function $(sel, root) { return (root || document).querySelector(sel); }
function el(tag, cls, text) {
  const e = document.createElement(tag);
  if (cls) { e.className = cls; }
  if (text !== undefined) { e.textContent = text; }
  return e;
}
function setStatus(text, bad) { const s = $("#status"); s.textContent = text; s.classList.toggle("bad", !!bad); }
function record(name, value) {
  const a = app.stats[name];
  a.push(value);
  if (a.length > 2000) { a.splice(0, a.length - 2000); }
}
app.resetStats = function () {
  for (const k of Object.keys(app.stats)) { app.stats[k] = []; }
  app.framesPainted = 0; app.paintLog = [];
  for (const p of app.panels) { p.painted = 0; }
};

// ------------------------------------------------------------------ connection
function connect() {
  const proto = location.protocol === "https:" ? "wss:" : "ws:";
  const ws = new WebSocket(`${proto}//${location.host}/ws?token=${encodeURIComponent(TOKEN)}`);
  ws.binaryType = "arraybuffer";
  ws.onopen = () => { app.connected = true; setStatus("connected"); };
  ws.onmessage = (ev) => {
    if (typeof ev.data === "string") { onText(JSON.parse(ev.data)); } else { onFrame(ev.data); }
  };
  ws.onclose = (ev) => {
    app.connected = false;
    setStatus(`disconnected${ev.reason ? ": " + ev.reason : ""} (retrying)`, true);
    for (const p of app.panels) { p.inflight = []; }
    setTimeout(connect, 2000);
  };
  app.ws = ws;
}

function send(obj) {
  if (app.ws && app.ws.readyState === WebSocket.OPEN) { app.ws.send(JSON.stringify(obj)); return true; }
  return false;
}

function onText(msg) {
  if (msg.type === "hello") {
    const first = app.source === null;
    app.source = msg.source; app.colormaps = msg.colormaps; app.version = msg.version;
    if (first) { init(); }
    for (const p of app.panels) { requestRender(p); }
  } else if (msg.type === "pixel") {
    app.plotState = { panel: msg.panel, data: msg.data };
    drawPlot();
  } else if (msg.type === "snapshot") {
    app.lastStack = msg.data;
    setStatus(`saved ${msg.data.images} image${msg.data.images === 1 ? "" : "s"}: ${msg.data.path}`);
  } else if (msg.type === "error") {
    app.errors.push(msg);
    const p = msg.panel !== null && msg.panel !== undefined ? app.panels[msg.panel] : null;
    if (p) {
      p.inflight = p.inflight.filter((id) => msg.id === null || id !== msg.id);
      $(".error", p.el).textContent = msg.message;
      pump(p);
    } else {
      setStatus(msg.message, true);
    }
  }
}

function onFrame(buf) {
  const t0 = performance.now();
  const n = new DataView(buf).getUint32(0, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
  const data = new Float32Array(buf, 4 + n, header.width * header.height);
  header.received_ms = performance.timeOrigin + t0;
  record("decode", performance.now() - t0);
  const p = app.panels[header.panel];
  if (!p) { return; }
  // The server renders only the newest request of a panel: a frame answers every older request too.
  p.inflight = p.inflight.filter((id) => id > header.id);
  p.pending = { header, data };
  $(".error", p.el).textContent = "";
  if (app.source.live) { p.dirty = true; } // a live device: keep asking, frames are shown as they arrive
  pump(p);
  schedulePaint();
}

// ------------------------------------------------------------------ rendering requests
function requestRender(p) { p.dirty = true; pump(p); }

function pump(p) {
  if (!p.dirty || p.hidden || p.inflight.length >= MAX_INFLIGHT) { return; }
  const id = ++app.nextId;
  if (send({ type: "render", panel: p.index, id, settings: p.settings })) {
    p.dirty = false;
    p.inflight.push(id);
    app.sentAt.set(id, performance.now());
    if (app.sentAt.size > 500) { app.sentAt.delete(app.sentAt.keys().next().value); }
  }
}

// ------------------------------------------------------------------ painting
function buildLut(p) {
  const table = app.colormaps[p.display.colormap] || app.colormaps.gray;
  const lut = new Uint32Array(LEVELS + 1);
  const g = p.display.gamma;
  for (let q = 0; q <= LEVELS; q++) {
    const c = table[Math.floor(255 * Math.pow(q / LEVELS, g) + 0.5)];
    // ImageData is RGBA bytes; a little-endian Uint32 view holds them as 0xAABBGGRR.
    lut[q] = (0xff000000 | ((c & 0xff) << 16) | (c & 0xff00) | ((c >> 16) & 0xff)) >>> 0;
  }
  p.lut = lut;
}

function white(p) { return p.refWhite * Math.pow(2, -p.display.stops); }

function mapImage(p) {
  const data = p.image.data, out = p.out32, lut = p.lut;
  const k = LEVELS / white(p);
  for (let i = 0; i < data.length; i++) {
    const x = data[i] * k;
    out[i] = lut[x > 0 ? (x >= LEVELS ? LEVELS : Math.floor(x + 0.5)) : 0];
  }
}

function paint(p, fresh) {
  const t0 = performance.now();
  if (fresh) {
    const { header, data } = p.pending;
    p.pending = null;
    if (p.canvas.width !== header.width || p.canvas.height !== header.height || !p.imageData) {
      p.canvas.width = header.width; p.canvas.height = header.height;
      p.imageData = p.ctx.createImageData(header.width, header.height);
      p.out32 = new Uint32Array(p.imageData.data.buffer);
    }
    if (p.refWhite === null) { p.refWhite = header.auto_white; }
    p.image = { width: header.width, height: header.height, data, header };
  }
  if (!p.image) { return; }
  mapImage(p);
  p.ctx.putImageData(p.imageData, 0, 0);
  const t1 = performance.now();
  p.remap = false;
  if (!fresh) { return; }
  const h = p.image.header;
  p.painted += 1; app.framesPainted += 1; app.paintLog.push(t1); p.paintLog.push(t1);
  record("paint", t1 - t0);
  record("render", h.render_ms); record("encode", h.encode_ms); record("queue", h.queue_ms);
  record("transfer", h.received_ms - h.sent_at_ms);
  const sent = app.sentAt.get(h.id);
  if (sent !== undefined) { record("latency", t1 - sent); }
  const shownDelay = h.delay_us !== undefined ? h.delay_us : (h.settings ? h.settings.delay_us : undefined);
  const moved = app.inputAt.get(shownDelay); // the frame shows this delay: since when was it asked for?
  if (moved !== undefined) { record("slider", t1 - moved); app.inputAt.delete(shownDelay); }
  $(".label", p.el).textContent = h.label + (h.saturated ? `  (${h.saturated} saturated)` : "");
  if (h.camera_fps !== undefined) { $("#camera-fps").textContent = `camera ${h.camera_fps.toFixed(1)} fps`; }
  if (h.pulse !== undefined && p.index === 0) { app.plotState = { panel: p.index, data: { kind: "pulse", pulse: h.pulse } }; drawPlot(); }
  else if (app.plotState && app.plotState.panel === p.index) { drawPlot(); }
}

// Painting happens in animation frames, and only when there is something new: an idle page asks for none.
let paintScheduled = false;
function schedulePaint() {
  if (!paintScheduled) { paintScheduled = true; requestAnimationFrame(tick); }
}
function tick() {
  paintScheduled = false;
  for (const p of app.panels) {
    if (p.pending) { paint(p, true); } else if (p.remap) { paint(p, false); }
  }
}

function fpsOf(log, now) {
  while (log.length && log[0] < now - 1000) { log.shift(); }
  return log.length;
}
setInterval(() => {
  const now = performance.now();
  const fps = fpsOf(app.paintLog, now);
  app.fps = fps;
  $("#fps").textContent = `${fps} fps`;
  for (const p of app.panels) {
    const n = fpsOf(p.paintLog, now);
    $(".panel-fps", p.el).textContent = n ? `${n} fps` : "";
  }
}, 250);

// ------------------------------------------------------------------ panels and controls
function sliderSpecs() {
  const s = app.source;
  return [
    { key: "delay_us", label: "delay t_d (us)", spec: s.delay_us, modes: ["band"], sweep: true },
    { key: "exposure_us", label: "exposure t_e (us)", spec: s.exposure_us, modes: ["band"] },
    { key: "width_rows", label: "band width (rows)", spec: s.width_rows, modes: ["sharpened"] },
    { key: "max_rows", label: "short range up to (rows)", spec: s.max_rows, modes: ["short_range", "long_range"] },
    { key: "row", label: "projector row", spec: s.row, modes: ["relight_row"] },
    { key: "period_rows", label: "pattern period (rows)", spec: { min: 2, max: 256, step: 1 }, modes: ["relight_pattern"], patterns: ["sine", "stripes"] },
    { key: "phase_deg", label: "pattern phase (deg)", spec: { min: 0, max: 360, step: 1 }, modes: ["relight_pattern"], patterns: ["sine", "stripes"] },
  ].filter((x) => x.spec);
}

function nearestIndex(grid, v) {
  let best = 0;
  for (let i = 1; i < grid.length; i++) { if (Math.abs(grid[i] - v) < Math.abs(grid[best] - v)) { best = i; } }
  return best;
}

function makeSlider(p, item) {
  const div = el("div", `ctl ctl-${item.key}`);
  div.appendChild(el("label", null, item.label));
  const range = el("input", `range-${item.key}`); range.type = "range";
  const num = el("input", `num-${item.key}`); num.type = "number";
  const grid = item.spec.grid;
  if (grid) {
    range.min = 0; range.max = grid.length - 1; range.step = 1;
    num.step = "any";
  } else {
    range.min = item.spec.min; range.max = item.spec.max; range.step = item.spec.step;
    num.step = "any";
  }
  const show = (v) => {
    if (grid) { const i = nearestIndex(grid, v); range.value = i; num.value = grid[i]; } else { range.value = v; num.value = v; }
  };
  const set = (v) => {
    p.settings[item.key] = v;
    if (item.key === "delay_us") { app.inputAt.set(v, performance.now()); if (app.inputAt.size > 500) { app.inputAt.delete(app.inputAt.keys().next().value); } }
    requestRender(p);
  };
  range.addEventListener("input", () => {
    const v = grid ? grid[Number(range.value)] : Number(range.value);
    num.value = v; set(v);
  });
  num.addEventListener("change", () => {
    let v = Number(num.value);
    if (num.value === "" || !isFinite(v)) { show(p.settings[item.key]); return; }
    if (item.key === "row") { v = Math.round(v); }
    if (grid) { v = grid[nearestIndex(grid, v)]; }
    show(v); set(v);
  });
  div.appendChild(range); div.appendChild(num);
  if (item.sweep) {
    const b = el("button", "sweep", "sweep"); b.type = "button";
    b.title = "Sweep the delay back and forth (the paper's 'sweeping the band')";
    b.addEventListener("click", () => toggleSweep(p, item, range, b));
    div.appendChild(b);
  }
  show(p.settings[item.key] === null ? Number(item.spec.min) : p.settings[item.key]);
  p.controls[item.key] = { div, range, num, show, item };
  return div;
}

// The sweep button moves the slider as a hand dragging it would: one input event per displayed frame
// (Chromium delivers pointer moves once per frame), back and forth over the slider's range in 6 s.
function toggleSweep(p, item, range, button) {
  if (p.animation) {
    if (p.animation.timer) { clearInterval(p.animation.timer); }
    p.animation = null; button.textContent = "sweep"; return;
  }
  button.textContent = "stop";
  const lo = Number(range.min), hi = Number(range.max), period = 6000, t0 = performance.now();
  const move = () => {
    const phase = ((performance.now() - t0) % period) / period;
    const f = phase < 0.5 ? phase * 2 : 2 - phase * 2;
    const v = lo + f * (hi - lo);
    range.value = item.spec.grid ? Math.round(v) : v;
    range.dispatchEvent(new Event("input"));
  };
  if (INPUT_HZ > 0) { p.animation = { timer: setInterval(move, 1000 / INPUT_HZ) }; return; }
  const step = () => {
    if (p.animation !== step) { return; }
    move();
    requestAnimationFrame(step);
  };
  p.animation = step;
  requestAnimationFrame(step);
}

function updateVisibility(p) {
  const mode = p.settings.mode;
  for (const c of Object.values(p.controls)) {
    let on = c.item.modes.includes(mode);
    if (on && c.item.patterns) { on = c.item.patterns.includes(p.settings.pattern); }
    c.div.classList.toggle("hidden", !on);
  }
  $(".ctl-pattern", p.el).classList.toggle("hidden", mode !== "relight_pattern");
  if (app.source.live && !app.source.transport) { // a live device: the exposure counts in every view, the delay in all but Eq. 7's cycle
    for (const key of ["delay_us", "exposure_us"]) {
      if (p.controls[key]) { p.controls[key].div.classList.toggle("hidden", key === "delay_us" && mode === "composite"); }
    }
  }
  const toggles = app.source.toggles.length > 0 && mode === "band";
  $(".ctl-toggles", p.el).classList.toggle("hidden", !toggles);
}

function makePanel(index, settings) {
  const node = $("#panel-template").content.firstElementChild.cloneNode(true);
  const p = {
    index, el: node, settings: { ...settings }, controls: {}, inflight: [], dirty: false, pending: null,
    image: null, imageData: null, out32: null, lut: null, refWhite: null, remap: false, painted: 0,
    hidden: index > 0, animation: null, paintLog: [],
    display: { stops: 0, gamma: 1, colormap: "gray" },
  };
  p.canvas = $("canvas.image", node);
  p.ctx = p.canvas.getContext("2d", { alpha: false });
  node.classList.toggle("hidden", p.hidden);
  node.dataset.panel = index;
  const src = app.source;
  const mode = $(".mode", node);
  for (const m of src.modes) { const o = el("option", null, m.label); o.value = m.name; mode.appendChild(o); }
  mode.value = p.settings.mode;
  mode.addEventListener("change", () => {
    p.settings.mode = mode.value; p.refWhite = null;
    const preset = (src.mode_defaults || {})[mode.value] || {};
    for (const [k, v] of Object.entries(preset)) { p.settings[k] = v; if (p.controls[k]) { p.controls[k].show(v); } }
    if (app.plotState && app.plotState.data.kind === "pulse") { app.plotState = null; }
    updateVisibility(p); requestRender(p);
  });
  const sliders = $(".sliders", node);
  for (const item of sliderSpecs()) { sliders.appendChild(makeSlider(p, item)); }
  const pattern = $(".pattern", node);
  for (const name of src.patterns) { const o = el("option", null, name); o.value = name; pattern.appendChild(o); }
  pattern.value = p.settings.pattern;
  pattern.addEventListener("change", () => { p.settings.pattern = pattern.value; updateVisibility(p); requestRender(p); });
  for (const key of ["noise", "ambient"]) {
    const box = $(`.${key}`, node);
    box.checked = !!p.settings[key];
    box.addEventListener("change", () => { p.settings[key] = box.checked; requestRender(p); });
  }
  const stops = $(".stops", node), gamma = $(".gamma", node), cmap = $(".colormap", node);
  stops.addEventListener("input", () => { p.display.stops = Number(stops.value); p.remap = true; schedulePaint(); });
  gamma.addEventListener("input", () => {
    p.display.gamma = Number(gamma.value); $(".gamma-value", node).textContent = p.display.gamma.toFixed(2);
    buildLut(p); p.remap = true; schedulePaint();
  });
  for (const name of Object.keys(app.colormaps)) { const o = el("option", null, name); o.value = name; cmap.appendChild(o); }
  cmap.value = p.display.colormap;
  cmap.addEventListener("change", () => { p.display.colormap = cmap.value; buildLut(p); p.remap = true; schedulePaint(); });
  $(".auto", node).addEventListener("click", () => {
    if (p.image) { p.refWhite = p.image.header.auto_white; }
    p.display.stops = 0; stops.value = 0; p.remap = true; schedulePaint();
  });
  p.canvas.addEventListener("mousemove", (ev) => hover(p, ev));
  p.canvas.addEventListener("mouseleave", () => { $(".hover", node).textContent = ""; });
  p.canvas.addEventListener("click", (ev) => clickPixel(p, ev));
  buildLut(p);
  updateVisibility(p);
  $("#panels").appendChild(node);
  return p;
}

function pixelAt(p, ev) {
  if (!p.image) { return null; }
  const r = p.canvas.getBoundingClientRect();
  const col = Math.floor((ev.clientX - r.left) / r.width * p.image.width);
  const row = Math.floor((ev.clientY - r.top) / r.height * p.image.height);
  if (row < 0 || col < 0 || row >= p.image.height || col >= p.image.width) { return null; }
  return { row, col };
}

function hover(p, ev) {
  const px = pixelAt(p, ev);
  $(".hover", p.el).textContent = px ? `(${px.row}, ${px.col}) = ${formatNumber(p.image.data[px.row * p.image.width + px.col])}` : "";
}

function clickPixel(p, ev) {
  const px = pixelAt(p, ev);
  if (!px) { return; }
  selectPixel(p, px.row, px.col);
}

function selectPixel(p, row, col) {
  for (const q of app.panels) { $(".marker", q.el).style.display = "none"; }
  const m = $(".marker", p.el);
  m.style.left = `${(col + 0.5) / p.image.width * 100}%`; m.style.top = `${(row + 0.5) / p.image.height * 100}%`;
  m.style.display = "block";
  send({ type: "pixel", panel: p.index, id: ++app.nextId, row, col, settings: p.settings });
}
app.selectPixel = (panel, row, col) => selectPixel(app.panels[panel], row, col);

// ------------------------------------------------------------------ the pixel plot
function areaNormalize(x, y) {
  let area = 0;
  for (let i = 1; i < x.length; i++) {
    const a = y[i - 1], b = y[i];
    if (a === null || b === null) { continue; }
    area += 0.5 * (Math.max(a, 0) + Math.max(b, 0)) * (x[i] - x[i - 1]);
  }
  return y.map((v) => (v === null ? null : area > 0 ? v / area : 0));
}

function windowRows(s) {
  const v = app.source.lines_per_second * 1e-6;
  if (s.mode === "band") { return [s.delay_us * v - s.exposure_us * v / 2, s.delay_us * v + s.exposure_us * v / 2]; }
  if (s.mode === "sharpened") { return [-s.width_rows / 2, s.width_rows / 2]; }
  if (s.mode === "short_range") { return [-s.max_rows, s.max_rows]; }
  if (s.mode === "epipolar") { const r = app.source.projector_rows / app.source.shape[0] / 2; return [-r, r]; }
  return null;
}

function drawPlot() {
  const st = app.plotState;
  if (!st) { return; }
  const d = st.data, p = app.panels[st.panel];
  const norm = $("#plot-normalize").checked;
  const series = [], spans = [], vlines = [];
  let notes = "";
  if (d.kind === "pulse") {
    const r = d.pulse;
    if (!r) {
      $("#plot-title").textContent = `Pulse: collecting frames (the rate needs 3 s of video, the window is ${app.source.pulse_window_s} s)`;
      app.plot.setData({ series: [], xlabel: "heart rate (bpm)", ylabel: "power", xname: "bpm", yname: "P" });
      $("#plot-notes").textContent = "";
      return;
    }
    const rate = r.rate_bpm === null ? `no pulse found (peak ${formatNumber(r.peak_bpm)} bpm)` : `${r.rate_bpm.toFixed(1)} bpm`;
    $("#plot-title").textContent = `Pulse: ${rate}; SNR ${r.snr_db.toFixed(1)} dB; ${r.frames} frames, ${r.window_s.toFixed(1)} s at ${r.fps.toFixed(1)} fps (skin pulse's analysis)`;
    app.plot.setData({ series: [{ name: "spectrum of the region's signal", x: r.spectrum.bpm, y: r.spectrum.power, color: PALETTE[0], width: 2 }],
      vlines: r.rate_bpm === null ? [] : [{ x: r.rate_bpm, color: "#ffffff" }], xlabel: "heart rate (bpm)",
      ylabel: "power (relative)", xname: "bpm", yname: "P" });
    $("#plot-notes").textContent = `region rows ${r.region[0]}-${r.region[2]}, columns ${r.region[1]}-${r.region[3]}; peak SNR ${r.band_snr_db.toFixed(1)} dB`;
    return;
  }
  if (d.kind === "device") {
    $("#plot-title").textContent = `Pixel (${d.row}, ${d.col}) over the last ${d.t_s.length} frames at t_d ${d.timing[0]} us, t_e ${d.timing[1]} us`;
    app.plot.setData({ series: [{ name: "value", x: d.t_s, y: d.values, color: PALETTE[0], width: 2 }],
      xlabel: "time (s, 0 = newest frame)", ylabel: "value", xname: "t", yname: "I" });
    $("#plot-notes").textContent = "";
    return;
  }
  if (d.kind === "stack") {
    const x = d.delays_us;
    const cur = p.image && p.image.header.delay_us !== undefined ? p.image.header : d.current;
    d.exposures_us.forEach((e, i) => {
      const y = norm ? d.normalized[i] : d.raw[i];
      const current = Math.abs(e - cur.exposure_us) < 1e-6;
      series.push({ name: `t_e ${e} us (measured)`, x, y, color: PALETTE[i % PALETTE.length], markers: true, width: current ? 3 : 1.2 });
    });
    if (d.truth) {
      d.exposures_us.forEach((e, i) => {
        series.push({ name: i === 0 ? "ground truth (dashed)" : "", legend: i === 0, x: d.truth.delays_us,
          y: norm ? d.truth.normalized[i] : d.truth.raw[i], color: PALETTE[i % PALETTE.length], dash: [5, 4], width: 1 });
      });
    }
    vlines.push({ x: cur.delay_us, color: "#ffffff" });
    $("#plot-title").textContent = `Delay profiles of pixel (${d.row}, ${d.col})${norm ? ", area-normalized" : ""}`;
    app.plot.setData({ series, vlines, xlabel: "delay t_d (us)", ylabel: norm ? "normalized intensity (1/ms)" : "intensity",
      xname: "t_d", yname: "I" });
  } else {
    const win = windowRows(p.settings);
    if (win) { spans.push({ x0: win[0], x1: win[1], color: "rgba(240,160,48,0.15)" }); }
    const res = d.epipolar_resolution_rows;
    if (res) { spans.push({ x0: -res, x1: res, color: "rgba(160,160,160,0.18)" }); }
    const add = (curve, name, color, dash, scale) => {
      let y = curve.T.map((v) => v * scale);
      if (norm) { y = areaNormalize(curve.offsets_rows, y); }
      series.push({ name, x: curve.offsets_rows, y, color, dash, width: 2 });
      const far = curve.sparse_offsets_rows.length;
      if (far) {
        notes += `${name}: ${far} far (sparse) entries, e.g. u = ${curve.sparse_offsets_rows.slice(0, 4).join(", ")} rows. `;
      }
    };
    if (d.estimate) { add(d.estimate, "T(u)", PALETTE[0], [], 1); }
    if (d.truth) {
      const scale = d.truth_scale === null ? 1 : d.truth_scale;
      const name = d.kind === "scene" ? "ground truth T(u)" : `ground truth${scale !== 1 ? " x " + formatNumber(scale) : ""}`;
      add(d.truth, name, PALETTE[1], d.kind === "scene" ? [] : [6, 4], scale);
    }
    $("#plot-title").textContent = `T(u) of pixel (${d.row}, ${d.col})${norm ? ", area-normalized" : ""}; shaded: what the mode lets through`;
    app.plot.setData({ series, spans, vlines,
      xlabel: `offset u = v - t (projector rows); delay = u / v_p, 1 row = ${formatNumber(1 / d.rows_per_us)} us`,
      ylabel: norm ? "T(u) / area" : "T(u)", xname: "u", yname: "T" });
  }
  $("#plot-notes").textContent = notes;
}

// ------------------------------------------------------------------ snapshot (PNG with the settings in a tEXt chunk)
const CRC_TABLE = (() => {
  const t = new Uint32Array(256);
  for (let n = 0; n < 256; n++) {
    let c = n;
    for (let k = 0; k < 8; k++) { c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1; }
    t[n] = c >>> 0;
  }
  return t;
})();
function crc32(bytes) {
  let c = 0xffffffff;
  for (let i = 0; i < bytes.length; i++) { c = CRC_TABLE[(c ^ bytes[i]) & 0xff] ^ (c >>> 8); }
  return (c ^ 0xffffffff) >>> 0;
}
function pngWithText(png, keyword, text) {
  const ascii = text.replace(/[\u0080-\uffff]/g, (ch) => "\\u" + ch.charCodeAt(0).toString(16).padStart(4, "0"));
  const body = new TextEncoder().encode(`tEXt${keyword}\0${ascii}`);
  const chunk = new Uint8Array(body.length + 8);
  const dv = new DataView(chunk.buffer);
  dv.setUint32(0, body.length - 4);
  chunk.set(body, 4);
  dv.setUint32(chunk.length - 4, crc32(body));
  const at = 33; // after the signature (8) and IHDR (25)
  const out = new Uint8Array(png.length + chunk.length);
  out.set(png.subarray(0, at)); out.set(chunk, at); out.set(png.subarray(at), at + chunk.length);
  return out;
}

async function snapshot() {
  const shown = app.panels.filter((p) => !p.hidden && p.image);
  if (!shown.length) { return null; }
  const gap = 8;
  const w = shown.reduce((a, p) => a + p.image.width, 0) + gap * (shown.length - 1);
  const h = Math.max(...shown.map((p) => p.image.height));
  const c = document.createElement("canvas"); c.width = w; c.height = h;
  const ctx = c.getContext("2d");
  ctx.fillStyle = "#000"; ctx.fillRect(0, 0, w, h);
  let x = 0;
  for (const p of shown) { ctx.drawImage(p.canvas, x, 0); x += p.image.width + gap; }
  const meta = {
    planeray: app.version, source: { kind: app.source.kind, name: app.source.name, shape: app.source.shape },
    panels: shown.map((p) => ({
      settings: p.image.header.settings, label: p.image.header.label,
      display: { white: white(p), gamma: p.display.gamma, colormap: p.display.colormap },
    })),
    taken: new Date().toISOString(),
  };
  const blob = await new Promise((resolve) => c.toBlob(resolve, "image/png"));
  const bytes = pngWithText(new Uint8Array(await blob.arrayBuffer()), "planeray", JSON.stringify(meta));
  const url = URL.createObjectURL(new Blob([bytes], { type: "image/png" }));
  const a = el("a"); a.href = url;
  const name = String(app.source.name).split(/[\\/]/).filter(Boolean).pop() || "view";
  a.download = `planeray-${name}-${shown.map((p) => p.settings.mode).join("-")}.png`;
  document.body.appendChild(a); a.click(); a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 30000);
  app.lastSnapshot = meta;
  return meta;
}
app.snapshot = snapshot;
app.saveStack = () => { const p = app.panels[0]; return send({ type: "snapshot", panel: 0, id: ++app.nextId, settings: p.settings }); };

// ------------------------------------------------------------------ start
function init() {
  const s = app.source;
  $("#source-name").textContent = s.name;
  if (s.live) {
    $("#side-by-side").parentElement.classList.add("hidden"); // one camera: one panel
    const save = el("button", null, "save stack"); save.id = "save-stack"; save.type = "button";
    save.title = "Write what is shown (the frame, or Eq. 7's cycle of frames) as a stack in the --snapshots folder";
    save.addEventListener("click", () => { app.saveStack(); });
    $("#snapshot").after(save);
    const cam = el("span", null, "camera -- fps"); cam.id = "camera-fps"; cam.title = "Frames the device captures per second";
    $("#fps").before(cam);
    $("#plot-title").textContent = s.transport
      ? `Live transport of a ${s.transport.images}-image sweep: click a pixel to see its T(u) in the newest transport.`
      : "Click a pixel to see its value over the recent frames; the pulse view plots the spectrum.";
  }
  $("#source-info").textContent = `${s.kind}, ${s.shape[0]}x${s.shape[1]}, ${s.projector_rows} projector rows` +
    (s.kind === "stack" ? `, ${s.n_images} images` : "") + (s.units ? `; values: ${s.units}` : "");
  document.title = `planeray view: ${s.name}`;
  const first = { ...s.defaults };
  const second = { ...s.defaults };
  if (s.kind !== "stack") { second.mode = "sharpened"; }
  app.panels.push(makePanel(0, first));
  app.panels.push(makePanel(1, second));
  app.plot = new LinePlot($("#plot"), $("#plot-readout"));
  const normalize = $("#plot-normalize");
  normalize.checked = s.kind === "stack" || (s.has_truth && s.truth_scale === null);
  normalize.addEventListener("change", drawPlot);
  $("#side-by-side").addEventListener("change", (ev) => {
    const p = app.panels[1];
    p.hidden = !ev.target.checked;
    p.el.classList.toggle("hidden", p.hidden);
    if (!p.hidden) { requestRender(p); }
  });
  $("#snapshot").addEventListener("click", () => { snapshot(); });
  if (BENCH_S > 0) { runBench(BENCH_S); }
}

function median(a) { const s = [...a].sort((x, y) => x - y); return s.length ? s[Math.floor(s.length / 2)] : null; }
function percentile(a, q) { const s = [...a].sort((x, y) => x - y); return s.length ? s[Math.min(s.length - 1, Math.floor(q * s.length))] : null; }

function runBench(seconds) {
  const p = app.panels[0];
  const c = p.controls.delay_us;
  let displayHz = null;
  const start = () => {
    if (!p.image) { setTimeout(start, 100); return; }
    if (displayHz === null) { // the display's refresh rate: animation frames in one idle second
      let n = 0; const t = performance.now();
      const count = () => { n += 1; if (performance.now() - t < 1000) { requestAnimationFrame(count); } else { displayHz = n / ((performance.now() - t) / 1000); start(); } };
      requestAnimationFrame(count);
      return;
    }
    toggleSweep(p, c.item, c.range, $("button.sweep", c.div));
    setTimeout(() => {
      app.resetStats();
      const t0 = performance.now();
      setTimeout(() => {
        const secs = (performance.now() - t0) / 1000;
        const stats = { frames: app.framesPainted, seconds: secs, fps: app.framesPainted / secs, display_hz: displayHz,
          width: p.image.width, height: p.image.height };
        for (const k of Object.keys(app.stats)) { stats[`${k}_ms`] = median(app.stats[k]); }
        stats.slider_p90_ms = percentile(app.stats.slider, 0.9); stats.slider_n = app.stats.slider.length;
        app.benchResult = stats;
        send({ type: "report", stats });
      }, seconds * 1000);
    }, 1000);
  };
  start();
}

connect();
