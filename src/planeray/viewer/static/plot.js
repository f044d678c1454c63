// planeray viewer: a small interactive line plot on a <canvas> (no library, works offline).
// setData({xlabel, ylabel, series: [{name, x, y, color, dash, width, markers, stems}],
//          vlines: [{x, color, label}], spans: [{x0, x1, color}]}); hover shows the nearest point.
"use strict";

function niceTicks(lo, hi, count) {
  if (!(hi > lo)) { hi = lo + 1; }
  const raw = (hi - lo) / Math.max(count, 1);
  const mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const norm = raw / mag;
  const step = (norm < 1.5 ? 1 : norm < 3 ? 2 : norm < 7 ? 5 : 10) * mag;
  const ticks = [];
  for (let t = Math.ceil(lo / step) * step; t <= hi + step * 1e-9; t += step) {
    ticks.push(Math.abs(t) < step * 1e-9 ? 0 : t);
  }
  return ticks;
}

function formatNumber(v) {
  if (v === null || v === undefined || !isFinite(v)) { return "--"; }
  const a = Math.abs(v);
  if (a !== 0 && (a < 1e-3 || a >= 1e5)) { return v.toExponential(3); }
  return Number(v.toPrecision(4)).toString();
}

class LinePlot {
  constructor(canvas, readout) {
    this.canvas = canvas;
    this.readout = readout;
    this.data = null;
    this.hoverPoint = null;
    this.margin = { left: 64, right: 16, top: 12, bottom: 40 };
    canvas.addEventListener("mousemove", (ev) => this.onMove(ev));
    canvas.addEventListener("mouseleave", () => { this.hoverPoint = null; this.draw(); this.showReadout(); });
    window.addEventListener("resize", () => this.draw());
  }

  setData(data) {
    this.data = data;
    this.hoverPoint = null;
    this.computeRange();
    this.draw();
    this.showReadout();
  }

  computeRange() {
    const d = this.data;
    let x0 = Infinity, x1 = -Infinity, y0 = 0, y1 = -Infinity;
    for (const s of d.series) {
      for (let i = 0; i < s.x.length; i++) {
        const y = s.y[i];
        if (y === null || !isFinite(y)) { continue; }
        x0 = Math.min(x0, s.x[i]); x1 = Math.max(x1, s.x[i]);
        y0 = Math.min(y0, y); y1 = Math.max(y1, y);
      }
    }
    if (!isFinite(x0)) { x0 = 0; x1 = 1; }
    if (d.xrange) { x0 = d.xrange[0]; x1 = d.xrange[1]; }
    if (!(y1 > y0)) { y1 = y0 + 1; }
    this.range = { x0, x1: x1 > x0 ? x1 : x0 + 1, y0, y1: y1 + 0.05 * (y1 - y0) };
  }

  resize() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(Math.round(this.canvas.clientWidth * dpr), 10);
    const h = Math.max(Math.round(this.canvas.clientHeight * dpr), 10);
    if (this.canvas.width !== w || this.canvas.height !== h) { this.canvas.width = w; this.canvas.height = h; }
    return dpr;
  }

  sx(x) { const m = this.margin, r = this.range; return m.left + (x - r.x0) / (r.x1 - r.x0) * (this.cssW - m.left - m.right); }
  sy(y) { const m = this.margin, r = this.range; return this.cssH - m.bottom - (y - r.y0) / (r.y1 - r.y0) * (this.cssH - m.top - m.bottom); }

  draw() {
    const dpr = this.resize();
    const ctx = this.canvas.getContext("2d");
    this.cssW = this.canvas.width / dpr; this.cssH = this.canvas.height / dpr;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, this.cssW, this.cssH);
    if (!this.data) { return; }
    const d = this.data, r = this.range, m = this.margin;
    ctx.font = "12px system-ui, sans-serif";
    // spans (band window, unresolved cell)
    for (const sp of d.spans || []) {
      const a = this.sx(Math.max(sp.x0, r.x0)), b = this.sx(Math.min(sp.x1, r.x1));
      if (b > a) { ctx.fillStyle = sp.color; ctx.fillRect(a, m.top, b - a, this.cssH - m.top - m.bottom); }
    }
    // axes and ticks
    ctx.strokeStyle = "#3a3f46"; ctx.fillStyle = "#9aa0a6"; ctx.lineWidth = 1;
    for (const t of niceTicks(r.x0, r.x1, 10)) {
      const x = this.sx(t);
      ctx.beginPath(); ctx.moveTo(x, m.top); ctx.lineTo(x, this.cssH - m.bottom); ctx.stroke();
      ctx.textAlign = "center"; ctx.fillText(formatNumber(t), x, this.cssH - m.bottom + 14);
    }
    for (const t of niceTicks(r.y0, r.y1, 5)) {
      const y = this.sy(t);
      ctx.beginPath(); ctx.moveTo(m.left, y); ctx.lineTo(this.cssW - m.right, y); ctx.stroke();
      ctx.textAlign = "right"; ctx.fillText(formatNumber(t), m.left - 6, y + 4);
    }
    ctx.textAlign = "center"; ctx.fillText(d.xlabel || "", (m.left + this.cssW - m.right) / 2, this.cssH - 6);
    ctx.save(); ctx.translate(14, (m.top + this.cssH - m.bottom) / 2); ctx.rotate(-Math.PI / 2);
    ctx.fillText(d.ylabel || "", 0, 0); ctx.restore();
    ctx.save();
    ctx.beginPath(); ctx.rect(m.left, m.top, this.cssW - m.left - m.right, this.cssH - m.top - m.bottom); ctx.clip();
    for (const v of d.vlines || []) {
      ctx.strokeStyle = v.color; ctx.setLineDash([4, 3]); ctx.beginPath();
      ctx.moveTo(this.sx(v.x), m.top); ctx.lineTo(this.sx(v.x), this.cssH - m.bottom); ctx.stroke(); ctx.setLineDash([]);
    }
    for (const s of d.series) {
      ctx.strokeStyle = s.color; ctx.fillStyle = s.color; ctx.lineWidth = s.width || 1.5;
      ctx.setLineDash(s.dash || []);
      if (s.stems) {
        for (let i = 0; i < s.x.length; i++) {
          ctx.beginPath(); ctx.moveTo(this.sx(s.x[i]), this.sy(0)); ctx.lineTo(this.sx(s.x[i]), this.sy(s.y[i])); ctx.stroke();
          ctx.beginPath(); ctx.arc(this.sx(s.x[i]), this.sy(s.y[i]), 3, 0, 2 * Math.PI); ctx.fill();
        }
        continue;
      }
      ctx.beginPath();
      let pen = false;
      for (let i = 0; i < s.x.length; i++) {
        const y = s.y[i];
        if (y === null || !isFinite(y)) { pen = false; continue; }
        const X = this.sx(s.x[i]), Y = this.sy(y);
        if (pen) { ctx.lineTo(X, Y); } else { ctx.moveTo(X, Y); pen = true; }
      }
      ctx.stroke();
      ctx.setLineDash([]);
      if (s.markers) {
        for (let i = 0; i < s.x.length; i++) {
          const y = s.y[i];
          if (y === null || !isFinite(y)) { continue; }
          ctx.beginPath(); ctx.arc(this.sx(s.x[i]), this.sy(y), 2.5, 0, 2 * Math.PI); ctx.fill();
        }
      }
    }
    if (this.hoverPoint) {
      const p = this.hoverPoint;
      ctx.strokeStyle = "#ffffff"; ctx.lineWidth = 1;
      ctx.beginPath(); ctx.arc(this.sx(p.x), this.sy(p.y), 5, 0, 2 * Math.PI); ctx.stroke();
    }
    ctx.restore();
    // legend
    let lx = m.left + 8, ly = m.top + 14;
    ctx.textAlign = "left";
    for (const s of d.series) {
      if (!s.name || s.legend === false) { continue; }
      ctx.fillStyle = s.color; ctx.fillRect(lx, ly - 8, 14, 3);
      ctx.fillStyle = "#e6e6e6"; ctx.fillText(s.name, lx + 20, ly - 3);
      ly += 16;
    }
  }

  nearest(mx, my) {
    let best = null, bestD = 18 * 18;
    for (const s of this.data.series) {
      for (let i = 0; i < s.x.length; i++) {
        const y = s.y[i];
        if (y === null || !isFinite(y) || s.x[i] < this.range.x0 || s.x[i] > this.range.x1) { continue; }
        const dx = this.sx(s.x[i]) - mx, dy = this.sy(y) - my, dd = dx * dx + dy * dy;
        if (dd < bestD) { bestD = dd; best = { series: s.name, x: s.x[i], y }; }
      }
    }
    return best;
  }

  onMove(ev) {
    if (!this.data) { return; }
    const rect = this.canvas.getBoundingClientRect();
    this.hoverPoint = this.nearest(ev.clientX - rect.left, ev.clientY - rect.top);
    this.draw();
    this.showReadout();
  }

  showReadout() {
    if (!this.readout) { return; }
    const p = this.hoverPoint;
    const d = this.data;
    this.readout.textContent = p ? `${p.series}: ${d.xname || "x"} = ${formatNumber(p.x)}, ${d.yname || "y"} = ${formatNumber(p.y)}` : "";
  }
}

window.LinePlot = LinePlot;
window.formatNumber = formatNumber;
