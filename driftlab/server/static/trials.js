// The selected job's evaluations as a table: sorted by any column, filtered by status and by the theta ranges
// brushed on the parallel coordinates, a page at a time (a 10k-evaluation job stays quick); a row or a plotted point
// selects an evaluation everywhere, "open in 3D view" plays its stored episode; and the form that enqueues a theta.
"use strict";
import { fmt } from "./svgplot.js";

const $ = (id) => document.getElementById(id);
const PAGE_ROWS = 50;

/** The table's view; ``from``: the status and best-K filters the page's address gives (?status=...&best=K). */
export function freshTrials(from = {}) {
  return { sort: { key: "index", dir: 1 }, status: from.status || "", best: from.best || 0, brushes: {}, page: 0 };
}

/** The filters in the page's address, so that a reload or a shared link shows the same (?job=&status=&best=). */
export function keepInAddress(state) {
  const params = new URLSearchParams(location.search);
  const set = (key, value) => (value ? params.set(key, value) : params.delete(key));
  set("job", state.selected || "");
  set("status", state.trials.status);
  set("best", state.trials.best || "");
  history.replaceState(null, "", `${location.pathname}${params.size ? `?${params}` : ""}`);
}

function columns(state) {
  return ["index", "id", "status", "J", ...Object.keys(state.job?.spec?.bounds || {}), "mean |e| m"];
}

function value(e, key) {
  if (key === "mean |e| m") return e.metrics?.mean_abs_e_m ?? NaN;
  if (key in e.theta) return e.theta[key];
  return e[key];
}

function matches(t, e) {
  if (t.status === "completed" && !e.completed) return false;
  if (t.status === "failed" && e.completed) return false;
  if (t.status === "refused" && e.status !== "refused") return false;
  if (t.status === "invalid" && e.status !== "invalid") return false;
  if (t.status === "enqueued" && !e.enqueued) return false;
  for (const [key, [lo, hi]] of Object.entries(t.brushes)) {
    const v = key === "J" ? (e.completed ? e.J : NaN) : e.theta[key];
    if (!(v >= lo && v <= hi)) return false;
  }
  return true;
}

/** The evaluations the table shows, in its order (every page). */
export function shownTrials(state) {
  const t = state.trials;
  let rows = state.evals.filter((e) => matches(t, e));
  if (t.best > 0) { // the K lowest J of the completed evaluations, then the other filters
    const best = new Set(state.evals.filter((e) => e.completed).sort((a, b) => a.J - b.J).slice(0, t.best)
      .map((e) => e.id));
    rows = rows.filter((e) => best.has(e.id));
  }
  const { key, dir } = t.sort;
  const num = (e) => { const v = value(e, key); return typeof v === "number" && Number.isFinite(v) ? v : Infinity; };
  return rows.sort((a, b) => (key === "status" ? dir * a.status.localeCompare(b.status) : dir * (num(a) - num(b)))
    || a.index - b.index);
}

export function renderTrials(state) {
  const t = state.trials;
  const rows = shownTrials(state);
  const pages = Math.max(1, Math.ceil(rows.length / PAGE_ROWS));
  t.page = Math.min(t.page, pages - 1);
  const head = $("trials-table").tHead.rows[0];
  head.replaceChildren();
  for (const key of columns(state)) {
    const th = document.createElement("th");
    th.textContent = key + (t.sort.key === key ? (t.sort.dir > 0 ? " ▲" : " ▼") : "");
    th.dataset.key = key;
    head.appendChild(th);
  }
  const body = $("trials-table").tBodies[0];
  body.replaceChildren();
  for (const e of rows.slice(t.page * PAGE_ROWS, (t.page + 1) * PAGE_ROWS)) {
    const tr = body.insertRow();
    tr.dataset.evalId = e.id;
    if (e.id === state.picked) tr.classList.add("picked");
    for (const key of columns(state)) {
      const v = value(e, key);
      let text = typeof v === "number" ? (key === "index" || key === "id" ? String(v) : fmt(v)) : String(v ?? "–");
      if (key === "status" && e.enqueued) text += " (enqueued)";
      tr.insertCell().textContent = text;
    }
  }
  $("trials-page").textContent = `${rows.length} of ${state.evals.length} evaluations · page ${t.page + 1} of ${pages}`;
  const filters = Object.entries(t.brushes).map(([k, [lo, hi]]) => `${k} ${fmt(lo)}…${fmt(hi)}`);
  $("trials-filter").textContent = filters.length ? `brushed: ${filters.join(", ")}` : "";
  $("trials-clear").hidden = !filters.length;
  renderPicked(state);
}

function renderPicked(state) {
  const e = state.evals.find((x) => x.id === state.picked);
  const link = $("trial-3d");
  if (!e) {
    link.hidden = true;
    return;
  }
  const reason = e.metrics?.failure_reason ? ` — ${e.metrics.failure_reason}` : "";
  $("trial-picked").textContent = `evaluation id ${e.id} (index ${e.index}${e.enqueued ? ", enqueued" : ""}): ` +
    `${e.status}, J ${fmt(e.J)}, theta ${Object.entries(e.theta).map(([k, v]) => `${k} ${fmt(v)}`).join(", ")}` +
    reason;
  link.hidden = false;
  // The replay page names what it plays (job, evaluation, J, theta, plant, seed) beside the state plots.
  link.href = `/api/evaluations/${e.id}/replay.html`;
}

/** Select an evaluation everywhere: its table page and row, its ring in the plots (``redraw``). */
export function pick(state, id, redraw) {
  state.picked = id;
  const at = shownTrials(state).findIndex((e) => e.id === id);
  if (at < 0) {
    state.trials = { ...state.trials, status: "", brushes: {} }; // a filtered-out point clears the filters
    $("trials-status").value = "";
  }
  const index = shownTrials(state).findIndex((e) => e.id === id);
  state.trials.page = Math.max(0, Math.floor(index / PAGE_ROWS));
  renderTrials(state);
  redraw();
  document.querySelector("#trials-table tr.picked")?.scrollIntoView({ block: "nearest" });
}

/** "k=0.06, dV=0.1" as a theta. */
function parseTheta(text) {
  const theta = {};
  for (const part of text.split(",").map((s) => s.trim()).filter(Boolean)) {
    const at = part.indexOf("=");
    const number = Number(part.slice(at + 1));
    if (at < 1 || part.slice(at + 1).trim() === "" || !Number.isFinite(number)) {
      throw new Error(`enqueue: expected key=number pairs separated by commas, got ${JSON.stringify(part)}`);
    }
    theta[part.slice(0, at).trim()] = number;
  }
  return theta;
}

export function wireTrials(state, { api, act, say, redraw }) {
  $("trials-status").onchange = () => { state.trials.status = $("trials-status").value; state.trials.page = 0;
                                         keepInAddress(state); renderTrials(state); redraw(); };
  $("trials-best").onchange = () => { state.trials.best = Number($("trials-best").value) || 0; state.trials.page = 0;
                                       keepInAddress(state); renderTrials(state); redraw(); };
  $("trials-status").value = state.trials.status;
  $("trials-best").value = String(state.trials.best || "");
  $("trials-clear").onclick = () => { state.trials.brushes = {}; renderTrials(state); redraw(); };
  $("trials-prev").onclick = () => { state.trials.page = Math.max(0, state.trials.page - 1); renderTrials(state); };
  $("trials-next").onclick = () => { state.trials.page += 1; renderTrials(state); };
  $("trials-table").tHead.onclick = (ev) => {
    const key = ev.target.closest("th")?.dataset.key;
    if (!key) return;
    const { sort } = state.trials;
    state.trials.sort = { key, dir: sort.key === key ? -sort.dir : 1 };
    renderTrials(state);
  };
  $("trials-table").tBodies[0].onclick = (ev) => {
    const id = ev.target.closest("tr")?.dataset.evalId;
    if (id) pick(state, Number(id), redraw);
  };
  $("job-panel").addEventListener("click", (ev) => {
    const id = ev.target.closest?.("[data-eval-id]")?.getAttribute("data-eval-id");
    if (id) pick(state, Number(id), redraw);
  });
  $("enqueue-form").onsubmit = (ev) => {
    ev.preventDefault();
    act(async () => {
      const theta = parseTheta($("enqueue-form").elements.theta.value);
      const out = await api("POST", `/api/jobs/${state.selected}/enqueue`, { thetas: [theta] });
      $("enqueue-text").textContent = `enqueued (${out.n_waiting} waiting); it is evaluated next`;
      say(`job ${state.selected}: theta enqueued`, true);
    });
  };
}
