// The dashboard's search-space panel: the GP's mean and standard deviation of J and the failure probability over
// two parameters (GET /api/jobs/{id}/search-space) with the evaluations on top, and the parameters' importance.
"use strict";
import { colorbar, el, fmt, frame, heatmap, points, RAMPS } from "./svgplot.js";

const $ = (id) => document.getElementById(id);

function fillSelect(select, names, value) {
  if (select.options.length !== names.length) {
    select.replaceChildren(...names.map((n) => new Option(n, n)));
  }
  select.value = value;
}

export function renderSpace(s, ev) {
  fillSelect($("contour-x"), s.parameters, s.x);
  fillSelect($("contour-y"), s.parameters, s.y);
  $("search-space").dataset.nEvaluations = s.n_evaluations;
  $("search-space-status").textContent = `(models fitted to ${s.n_evaluations} evaluations)`;
  $("held-text").textContent = Object.keys(s.held).length
    ? `others held at the best theta: ${Object.entries(s.held).map(([k, v]) => `${k} ${fmt(v)}`).join(", ")}` : "";
  renderImportance(s);
  const box = { width: 315, height: 270, x: s.bounds[s.x], y: s.bounds[s.y], xlabel: s.x, ylabel: s.y,
                margin: { r: 64, l: 46 } };
  const overlay = (f) => {
    points(f, ev.map((e) => e.theta[s.x]), ev.map((e) => (e.completed ? e.theta[s.y] : NaN)),
      { color: "#111", r: 2 });
    points(f, ev.map((e) => e.theta[s.x]), ev.map((e) => (e.completed ? NaN : e.theta[s.y])),
      { color: "#c92a2a", shape: "x", r: 3 });
    if (s.best_theta) points(f, [s.best_theta[s.x]], [s.best_theta[s.y]], { color: "#ffd43b", shape: "star", r: 7 });
  };
  const panels = [["contour-mean", "mean_J", "GP mean of J", RAMPS.viridis, true],
    ["contour-std", "std_J", "GP std of J", RAMPS.greys, false],
    ["contour-fail", "p_failure", "P(failure)", RAMPS.reds, false]];
  for (const [id, field, title, stops, reverse] of panels) {
    const f = frame($(id), { ...box, title });
    if (s[field]) {
      const range = field === "p_failure" ? [0, 1] : null;
      const [lo, hi] = heatmap(f, s.x_values, s.y_values, s[field], { stops, reverse, range });
      colorbar(f, lo, hi, { stops, reverse });
    } else {
      el("text", { x: f.m.l + 10, y: f.m.t + 20 }, f.g,
        field === "p_failure" ? "no failure model: no failed (or no completed) evaluation" : "needs 2 completed evaluations");
    }
    overlay(f);
  }
}

function renderImportance(s) {
  const names = s.parameters;
  const imp = s.importance || {};
  const f = frame($("importance"), { width: 330, height: 30 + 26 * names.length, x: [0, 1], y: [0, names.length],
    title: "Importance (GP ARD relevance)", margin: { l: 110, b: 22 } });
  f.g.parentNode.querySelectorAll(".axes text").forEach((t) => {
    if (Number(t.getAttribute("x")) < f.m.l) t.remove(); // no numeric y ticks: the rows are parameters
  });
  names.forEach((n, i) => {
    const y = f.sy(names.length - i - 0.5);
    el("text", { x: f.m.l - 6, y: y + 4, "text-anchor": "end" }, f.g, n);
    const v = imp[n] ?? 0;
    el("rect", { x: f.sx(0), y: y - 8, width: f.sx(v) - f.sx(0), height: 16, fill: "#2a6fdb" }, f.g);
    el("text", { x: f.sx(v) + 4, y: y + 4 }, f.g, s.importance ? `${fmt(100 * v)} %` : "–");
  });
  $("importance-caption").textContent = `Parameter importance: ${s.importance_method}. Length scales: ` +
    (s.length_scales ? Object.entries(s.length_scales).map(([k, v]) => `${k} ${fmt(v)}`).join(", ") : "none yet");
}
