// Small SVG plots for the dashboard page: axes with ticks, points, lines, heatmaps, parallel coordinates.
// Numbers are printed to 4 significant digits; the API and the downloads keep full precision.
"use strict";

const SVG_NS = "http://www.w3.org/2000/svg";

export function fmt(v) {
  if (v === null || v === undefined || Number.isNaN(v)) return "–";
  if (!Number.isFinite(v)) return String(v);
  return String(Number.parseFloat(Number(v).toPrecision(4)));
}

export function el(tag, attrs = {}, parent = null, text = null) {
  const node = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  if (text !== null) node.textContent = text;
  if (parent) parent.appendChild(node);
  return node;
}

function niceTicks(lo, hi, count = 5) {
  if (!(hi > lo)) return [lo];
  const raw = (hi - lo) / count;
  const mag = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * mag).find((s) => s >= raw) || raw;
  const ticks = [];
  for (let t = Math.ceil(lo / step) * step; t <= hi + 1e-9 * step; t += step) ticks.push(Math.abs(t) < 1e-12 * step ? 0 : t);
  return ticks;
}

export function extent(values, pad = 0.06) {
  const finite = values.filter((v) => Number.isFinite(v));
  if (!finite.length) return [0, 1];
  let lo = Math.min(...finite), hi = Math.max(...finite);
  if (hi - lo < 1e-12) { lo -= 0.5 * Math.max(Math.abs(lo), 1e-3); hi += 0.5 * Math.max(Math.abs(hi), 1e-3); }
  const d = (hi - lo) * pad;
  return [lo - d, hi + d];
}

// An empty plot in `svg` (cleared): returns scales and the group to draw into.
export function frame(svg, { width, height, x, y, xlabel = "", ylabel = "", title = "", margin = {} }) {
  svg.replaceChildren();
  svg.setAttribute("viewBox", `0 0 ${width} ${height}`);
  svg.setAttribute("width", width);
  svg.setAttribute("height", height);
  const m = { l: 52, r: 10, t: title ? 20 : 8, b: 34, ...margin };
  const sx = (v) => m.l + ((v - x[0]) / (x[1] - x[0])) * (width - m.l - m.r);
  const sy = (v) => height - m.b - ((v - y[0]) / (y[1] - y[0])) * (height - m.t - m.b);
  if (title) el("text", { x: m.l, y: 13, class: "plot-title" }, svg, title);
  const axes = el("g", { class: "axes" }, svg);
  el("rect", { x: m.l, y: m.t, width: width - m.l - m.r, height: height - m.t - m.b, class: "plot-area" }, axes);
  for (const t of niceTicks(x[0], x[1], Math.max(2, Math.floor((width - m.l - m.r) / 70)))) {
    el("line", { x1: sx(t), x2: sx(t), y1: height - m.b, y2: height - m.b + 4 }, axes);
    el("text", { x: sx(t), y: height - m.b + 15, "text-anchor": "middle" }, axes, fmt(t));
  }
  for (const t of niceTicks(y[0], y[1], Math.max(2, Math.floor((height - m.t - m.b) / 35)))) {
    el("line", { x1: m.l - 4, x2: m.l, y1: sy(t), y2: sy(t) }, axes);
    el("text", { x: m.l - 6, y: sy(t) + 4, "text-anchor": "end" }, axes, fmt(t));
  }
  if (xlabel) el("text", { x: (m.l + width - m.r) / 2, y: height - 4, "text-anchor": "middle", class: "axis-label" }, axes, xlabel);
  if (ylabel) el("text", { x: 12, y: (m.t + height - m.b) / 2, "text-anchor": "middle", class: "axis-label",
                          transform: `rotate(-90 12 ${(m.t + height - m.b) / 2})` }, axes, ylabel);
  const g = el("g", {}, svg);
  return { sx, sy, g, m, width, height };
}

// ``ids``: an evaluation id per point (data-eval-id: a click selects it) and ``titles``: what hovering shows.
export function points(f, xs, ys, { color = "#2a6fdb", r = 3, shape = "circle", cls = "", ids, titles } = {}) {
  for (let i = 0; i < xs.length; i++) {
    if (!Number.isFinite(xs[i]) || !Number.isFinite(ys[i])) continue;
    const x = f.sx(xs[i]), y = f.sy(ys[i]);
    let mark;
    if (shape === "x") {
      mark = el("path", { d: `M${x - r},${y - r}L${x + r},${y + r}M${x - r},${y + r}L${x + r},${y - r}`,
                          stroke: color, "stroke-width": 1.6, class: cls }, f.g);
    } else if (shape === "star") {
      mark = el("path", { d: starPath(x, y, r), fill: color, stroke: "#222", "stroke-width": 0.8, class: cls }, f.g);
    } else if (shape === "ring") {
      mark = el("circle", { cx: x, cy: y, r, fill: "none", stroke: color, "stroke-width": 2, class: cls }, f.g);
    } else {
      mark = el("circle", { cx: x, cy: y, r, fill: color, class: cls }, f.g);
    }
    if (ids) { mark.setAttribute("data-eval-id", ids[i]); mark.style.cursor = "pointer"; }
    if (titles) el("title", {}, mark).textContent = titles[i];
  }
}

function starPath(x, y, r) {
  let d = "";
  for (let k = 0; k < 10; k++) {
    const a = -Math.PI / 2 + (k * Math.PI) / 5, rr = k % 2 ? r * 0.45 : r;
    d += `${k ? "L" : "M"}${x + rr * Math.cos(a)},${y + rr * Math.sin(a)}`;
  }
  return d + "Z";
}

export function line(f, xs, ys, { color = "#e8590c", width = 2 } = {}) {
  let d = "";
  let pen = false;
  for (let i = 0; i < xs.length; i++) {
    if (!Number.isFinite(ys[i])) { pen = false; continue; }
    d += `${pen ? "L" : "M"}${f.sx(xs[i])},${f.sy(ys[i])}`;
    pen = true;
  }
  if (d) el("path", { d, fill: "none", stroke: color, "stroke-width": width }, f.g);
}

// Colour ramps: t in [0, 1].
const VIRIDIS = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
const REDS = [[255, 255, 255], [252, 187, 161], [251, 106, 74], [203, 24, 29], [103, 0, 13]];
export function ramp(t, stops = VIRIDIS) {
  const u = Math.min(Math.max(Number.isFinite(t) ? t : 0, 0), 1) * (stops.length - 1);
  const i = Math.min(Math.floor(u), stops.length - 2), w = u - i;
  const c = stops[i].map((a, k) => Math.round(a + w * (stops[i + 1][k] - a)));
  return `rgb(${c[0]},${c[1]},${c[2]})`;
}
export const RAMPS = { viridis: VIRIDIS, reds: REDS, greys: [[250, 250, 250], [120, 120, 120], [20, 20, 20]] };

// A filled contour: the grid's values in `levels` bands (rows follow ys, columns xs), with a colour bar.
export function heatmap(f, xs, ys, grid, { levels = 10, stops = VIRIDIS, reverse = false, range = null } = {}) {
  const flat = grid.flat().filter(Number.isFinite);
  const [lo, hi] = range || [Math.min(...flat), Math.max(...flat)];
  const span = hi - lo || 1;
  const dx = (xs[xs.length - 1] - xs[0]) / Math.max(xs.length - 1, 1);
  const dy = (ys[ys.length - 1] - ys[0]) / Math.max(ys.length - 1, 1);
  const clip = (v, a) => Math.min(Math.max(v, a[0]), a[a.length - 1]);
  for (let r = 0; r < ys.length; r++) {
    for (let c = 0; c < xs.length; c++) {
      let t = Math.min(Math.floor(((grid[r][c] - lo) / span) * levels), levels - 1) / (levels - 1);
      if (reverse) t = 1 - t;
      const x0 = f.sx(clip(xs[c] - dx / 2, xs)), x1 = f.sx(clip(xs[c] + dx / 2, xs));
      const y0 = f.sy(clip(ys[r] + dy / 2, ys)), y1 = f.sy(clip(ys[r] - dy / 2, ys));
      el("rect", { x: x0, y: y0, width: x1 - x0 + 0.6, height: y1 - y0 + 0.6, fill: ramp(t, stops) }, f.g);
    }
  }
  return [lo, hi];
}

export function colorbar(f, lo, hi, { stops = VIRIDIS, reverse = false, label = "" } = {}) {
  const x = f.width - f.m.r + 8, top = f.m.t, h = f.height - f.m.t - f.m.b;
  for (let k = 0; k < 20; k++) {
    const t = k / 19;
    el("rect", { x, y: top + (1 - (k + 1) / 20) * h, width: 10, height: h / 20 + 0.5,
                 fill: ramp(reverse ? 1 - t : t, stops) }, f.g);
  }
  el("text", { x: x + 13, y: top + 8, class: "small" }, f.g, fmt(hi));
  el("text", { x: x + 13, y: top + h, class: "small" }, f.g, fmt(lo));
  if (label) el("text", { x: x + 13, y: top + h / 2, class: "small" }, f.g, label);
}

// Parallel coordinates: one axis per key, each row a polyline; `color(row)` picks its colour.
// ``brushes``: axis key -> [lo, hi] drawn on its axis; ``onBrush(key, range or null)``: a drag along an axis
// brushes that range (a click without a drag clears the axis's brush). ``inside(row)``: false draws the row greyed
// under the others (outside the brushes and filters). A row whose value on an axis is not a number (a failed
// evaluation's J) ends in a "failed" band above that axis, dashed: a failure is not a value at the axis's top.
export function parallel(svg, rows, axes, { width, height, color, brushes = {}, onBrush = null,
                                            inside = () => true }) {
  svg.replaceChildren();
  svg.setAttribute("viewBox", `0 0 ${width} ${height}`);
  svg.setAttribute("width", width);
  svg.setAttribute("height", height);
  const m = { l: 30, r: 44, t: 40, b: 22 };
  const failedY = 24; // the band a non-number ends in, above the axes' tops
  const ax = (i) => m.l + (i * (width - m.l - m.r)) / Math.max(axes.length - 1, 1);
  const ay = (a, v) => height - m.b - ((v - a.range[0]) / (a.range[1] - a.range[0] || 1)) * (height - m.t - m.b);
  const g = el("g", {}, svg);
  const ordered = [...rows.filter((r) => !inside(r)), ...rows.filter((r) => inside(r))]; // the brushed on top
  for (const row of ordered) {
    let d = "";
    let failed = false;
    axes.forEach((a, i) => {
      const value = row[a.key];
      const y = Number.isFinite(value) ? ay(a, Math.min(Math.max(value, a.range[0]), a.range[1])) : failedY;
      failed = failed || !Number.isFinite(value);
      d += `${i ? "L" : "M"}${ax(i)},${y}`;
    });
    const shown = inside(row);
    el("path", { d, fill: "none", stroke: shown ? color(row) : "#bbb", "stroke-width": row.best ? 3 : 1.2,
                 "stroke-opacity": !shown ? 0.25 : row.best ? 1 : 0.7, "stroke-dasharray": failed ? "4 3" : "none",
                 "data-in": shown ? "1" : "0", "data-failed": failed ? "1" : "0" }, g);
  }
  if (rows.some((r) => axes.some((a) => !Number.isFinite(r[a.key])))) {
    el("text", { x: width - m.r + 5, y: failedY + 3, class: "small" }, svg, "failed");
  }
  axes.forEach((a, i) => {
    el("line", { x1: ax(i), x2: ax(i), y1: m.t, y2: height - m.b, class: "pc-axis" }, svg);
    el("text", { x: ax(i), y: 10, "text-anchor": "middle", class: "axis-label" }, svg, a.label);
    el("text", { x: ax(i), y: m.t - 3, "text-anchor": "middle", class: "small" }, svg, fmt(a.range[1]));
    el("text", { x: ax(i), y: height - 6, "text-anchor": "middle", class: "small" }, svg, fmt(a.range[0]));
    const brushed = brushes[a.key];
    if (brushed) {
      const [top, bottom] = [ay(a, brushed[1]), ay(a, brushed[0])];
      el("rect", { x: ax(i) - 7, y: top, width: 14, height: Math.max(bottom - top, 1), class: "pc-brush" }, svg);
    }
    if (onBrush) brushable(svg, a, ax(i), m.t, height - m.b, (y) => a.range[0] + ((height - m.b - y)
      / (height - m.t - m.b)) * (a.range[1] - a.range[0]), onBrush);
  });
}

function brushable(svg, axis, x, top, bottom, valueAt, onBrush) {
  const hit = el("rect", { x: x - 10, y: top, width: 20, height: bottom - top, fill: "transparent",
                           class: "pc-hit", "data-axis": axis.key }, svg);
  hit.style.cursor = "ns-resize";
  const svgY = (ev) => {
    const box = svg.getBoundingClientRect();
    const scale = svg.viewBox.baseVal.height / box.height;
    return Math.min(Math.max((ev.clientY - box.top) * scale, top), bottom);
  };
  hit.addEventListener("pointerdown", (down) => {
    down.preventDefault();
    const y0 = svgY(down);
    const up = (ev) => {
      window.removeEventListener("pointerup", up);
      const y1 = svgY(ev);
      onBrush(axis.key, Math.abs(y1 - y0) < 3 ? null : [valueAt(Math.max(y0, y1)), valueAt(Math.min(y0, y1))]);
    };
    window.addEventListener("pointerup", up);
  });
}
