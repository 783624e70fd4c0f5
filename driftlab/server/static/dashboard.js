// The researcher's dashboard: jobs (start, pause, resume, extend, clone, delete, rescore, notes) through the REST
// API, and the selected job's convergence and search space, read again every second.
// With a token set, open the page as /dashboard/?token=<DRIFTLAB_TOKEN>: the server keeps it in an HttpOnly cookie,
// takes it out of the address, and every change from this page carries the cookie (never a script's copy).
"use strict";
import { calibrationPanel } from "./calibrate.js";
import { formBody, openForm as fillForm } from "./jobform.js";
import { renderSpace } from "./searchspace.js";
import { freshTrials, keepInAddress, renderTrials, shownTrials, wireTrials } from "./trials.js";
import { el, extent, fmt, frame, line, parallel, points, ramp, RAMPS } from "./svgplot.js";

const POLL_MS = 1000;
const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);

const state = {
  jobs: [], form: null, selected: null, job: null,
  evals: [], // the selected job's evaluations, in index order
  space: null, spaceKey: "", spaceBusy: false,
  axesChosen: false, // until a parameter is chosen, the contour shows the two most important
  rescoring: false,
  trials: freshTrials({ status: params.get("status"), best: Number(params.get("best")) }), picked: null, // the evaluations table's view, and the evaluation selected everywhere
  refreshCalibration: async () => {},
};

// ----- the API ------------------------------------------------------------------------------------------------
async function api(method, path, body) {
  const headers = { "content-type": "application/json" };
  const r = await fetch(path, { method, headers, credentials: "same-origin", body: body === undefined ? undefined : JSON.stringify(body) });
  if (r.status === 204) return null;
  const data = parseJson(await r.text()) ?? { detail: `${r.status} ${r.statusText}` };
  if (!r.ok) {
    const hint = r.status === 401 ? " (open this page as /dashboard/?token=<DRIFTLAB_TOKEN>)" : "";
    const error = new Error(`${method} ${path}: ${r.status} ${data.detail || r.statusText}${hint}`);
    error.status = r.status;
    throw error;
  }
  return data;
}

// Python's json writes NaN and Infinity bare (a failed episode's metrics can hold them): JSON.parse refuses them.
function parseJson(text) {
  try {
    return JSON.parse(text.replace(/([:\[,]\s*)-?(?:NaN|Infinity)(?=\s*[,\]}])/g, "$1null"));
  } catch {
    return null;
  }
}

function say(text, ok = false) {
  const m = $("message");
  m.hidden = !text;
  m.textContent = text || "";
  m.className = ok ? "ok" : "";
}

async function act(fn) {
  try { await fn(); } catch (e) { say(e.message); }
}

// ----- the job list -------------------------------------------------------------------------------------------
function renderJobs() {
  const body = $("job-table").tBodies[0];
  body.replaceChildren();
  for (const j of state.jobs) {
    const tr = document.createElement("tr");
    tr.dataset.jobId = j.id;
    if (j.id === state.selected) tr.className = "selected";
    for (const text of [j.id, j.name, j.status, `${j.n_done} / ${j.iterations}`, j.best ? fmt(j.best.J) : "–"]) {
      const td = document.createElement("td");
      td.textContent = text;
      tr.appendChild(td);
    }
    tr.addEventListener("click", () => select(j.id));
    body.appendChild(tr);
  }
}

function select(jobId) {
  if (state.selected !== jobId) {
    state.selected = jobId;
    state.evals = [];
    state.space = null;
    state.spaceKey = "";
    state.axesChosen = false;
    $("notes").dataset.loaded = "";
    state.trials = freshTrials();
    state.picked = null;
    $("trials-status").value = "";
    $("trials-best").value = "";
    keepInAddress(state);
    $("contour-x").replaceChildren();
    $("contour-y").replaceChildren();
  }
  renderJobs();
  return refreshJob();
}

// ----- the selected job ---------------------------------------------------------------------------------------
async function refreshJob() {
  if (state.selected === null) return;
  const id = state.selected;
  try {
    await refreshSelected(id);
  } catch (e) {
    // Deleted meanwhile (here, between two of this refresh's requests, or elsewhere): the selection goes quietly,
    // the next poll's list has it gone too. A job no longer selected has nothing left to say.
    if (id !== state.selected) return;
    if (e.status !== 404) throw e;
    state.selected = null;
    state.job = null;
    $("job-panel").hidden = true;
  }
}

async function refreshSelected(id) {
  const job = await api("GET", `/api/jobs/${id}`);
  if (id !== state.selected) return;
  state.job = job;
  const after = state.evals.length - 1;
  const fresh = await api("GET", `/api/jobs/${id}/evaluations?after=${after}&limit=1000`);
  if (id !== state.selected) return;
  // Two refreshes may overlap (a poll and an action's own): each appends only the next index, never one twice.
  for (const e of fresh) if (e.index === state.evals.length) state.evals.push(e);
  renderJob();
  if (fresh.length) {
    renderHistoryPlots();
    renderTrials(state);
  }
  maybeFetchSpace();
  if (state.rescoring) await pollRescore();
}

/** A time left as a person says it: "40 s", "12 min", "2.5 h" (not "0.9025 min"). */
function duration(seconds) {
  if (seconds < 90) return `${Math.max(1, Math.round(seconds))} s`;
  if (seconds < 5400) return `${Math.round(seconds / 60)} min`;
  return `${(seconds / 3600).toFixed(1)} h`;
}

function renderJob() {
  const j = state.job;
  $("job-panel").hidden = false;
  $("job-title").textContent = `${j.id} · ${j.name}`;
  const own = j.best ? `best J ${fmt(j.best.J)} (evaluation id ${j.best.id})` : "no completed evaluation yet";
  const told = j.best_told;  // a continuation starts from the best it was told
  const best = told && (!j.best || told.J < j.best.J)
    ? `best J ${fmt(told.J)} (told, from job ${told.from_jobs.join(", ")}); its own: ${own}` : own;
  const eta = j.eta_s !== null && j.eta_s !== undefined ? `, about ${duration(j.eta_s)} left` : "";
  const stopped = j.stop_reason ? ` · stopped by its rule: ${j.stop_reason}` : "";
  $("job-status").textContent = `status: ${j.status}${j.detail ? ` (${j.detail})` : ""} · ${j.n_done} / ` +
    `${j.iterations} evaluations${eta} · ${best}${stopped}`;
  $("pause").disabled = !["queued", "running"].includes(j.status);
  $("resume").disabled = !["paused", "failed"].includes(j.status);
  if (document.activeElement !== $("extend-to")) $("extend-to").value = j.iterations;
  if (!$("notes").dataset.loaded) { $("notes").value = j.notes || ""; $("notes").dataset.loaded = "1"; }
  $("view-link").href = "/viser/";
  renderPhases();
}

const PHASE_NAMES = { left_drift: "left drift", inertia_left_to_right: "flick left → right",
  right_drift: "right drift", inertia_right_to_left: "flick right → left", left_drift_final: "final left drift" };

/** The best evaluation's drift and flicks in numbers (metrics.phases of its shown episode, as the report gives). */
function renderPhases() {
  const j = state.job;
  const best = j.best ? state.evals.find((e) => e.id === j.best.id) : undefined;
  const phases = (best && best.metrics && best.metrics.phases) || [];
  const body = $("phase-table").tBodies[0];
  body.replaceChildren();
  const num = (v, digits) => (v === null || v === undefined ? "–" : Number(v).toFixed(digits));
  for (const p of phases) {
    const flick = "flip_s" in p;
    const cells = [PHASE_NAMES[p.phase] || p.phase, `${num(p.start_s, 2)}–${num(p.end_s, 2)}`,
      `${num(p.mean_abs_e_m, 2)} / ${num(p.max_abs_e_m, 2)}`, num(p.rms_beta_err_rad, 3),
      p.countersteer_share === undefined ? "–" : `${Math.round(100 * p.countersteer_share)}%`,
      flick ? num(p.flip_s, 2) : "", flick ? num(p.settle_s, 2) : "", num(p.speed_loss_mps, 2)];
    const tr = body.insertRow();
    for (const text of cells) tr.insertCell().textContent = text;
  }
  $("phase-caption").textContent = best
    ? `evaluation id ${best.id}, its shown episode (seed ${best.trajectory_seed ?? 0}); a flick runs from its ` +
      "trigger to the sideslip settling on the new side"
    : "no completed evaluation yet";
}

function paramNames() {
  return Object.keys(state.job?.spec?.bounds || {});
}

function renderHistoryPlots() {
  const ev = state.evals;
  const names = paramNames();
  const J = ev.map((e) => (e.completed ? e.J : NaN));
  const idx = ev.map((e) => e.index);
  const best = [];
  let b = Infinity;
  for (const v of J) { if (Number.isFinite(v) && v < b) b = v; best.push(Number.isFinite(b) ? b : NaN); }
  const yr = extent(J);
  const failedTop = ev.map((e) => (e.completed ? NaN : yr[1]));
  const ids = ev.map((e) => e.id);
  const titles = ev.map((e) => `evaluation id ${e.id} (index ${e.index})${e.enqueued ? ", enqueued" : ""}: ` +
    `${e.status}, J ${fmt(e.J)}; ${Object.entries(e.theta).map(([k, v]) => `${k} ${fmt(v)}`).join(", ")}`);
  const marks = { ids, titles };
  // The table's filters (status, best K, brushes) apply to every plot: the evaluations outside them grey.
  const shown = new Set(shownTrials(state).map((e) => e.id));
  const inView = (values, yes) => values.map((v, i) => (shown.has(ev[i].id) === yes ? v : NaN));
  const conv = frame($("convergence"), { width: 460, height: 260, x: [0, Math.max(state.job.iterations - 1, 1)],
    y: yr, xlabel: "evaluation", ylabel: "J", title: "Convergence" });
  line(conv, idx, best, { color: "#e8590c" });
  points(conv, idx, inView(J, false), { color: "#d0d0d0", cls: "outside", ...marks });
  points(conv, idx, inView(failedTop, false), { color: "#d0d0d0", shape: "x", r: 3.5, cls: "outside", ...marks });
  points(conv, idx, inView(J, true), { color: "#2a6fdb", ...marks });
  points(conv, idx, inView(failedTop, true), { color: "#c92a2a", shape: "x", r: 3.5, ...marks });
  // enqueued evaluations in green; the selected one ringed
  points(conv, idx, ev.map((e, i) => (e.enqueued ? (e.completed ? J[i] : yr[1]) : NaN)),
         { color: "#2b8a3e", r: 4, ...marks });
  points(conv, idx, ev.map((e, i) => (e.id === state.picked ? (e.completed ? J[i] : yr[1]) : NaN)),
         { color: "#111", shape: "ring", r: 7 });
  $("convergence").dataset.n = ev.length;

  const slices = $("slices");
  slices.replaceChildren();
  const thetaIter = $("theta-iteration");
  thetaIter.replaceChildren();
  const bounds = state.job.spec.bounds;
  for (const name of names) {
    const xs = ev.map((e) => e.theta[name]);
    const s = frame(el("svg", { class: "slice" }, slices), { width: 250, height: 190, x: bounds[name], y: yr,
      xlabel: name, ylabel: "J", title: `J against ${name}` });
    points(s, xs, inView(J, false), { color: "#d0d0d0", r: 2.6, cls: "outside", ...marks });
    points(s, xs, inView(failedTop, false), { color: "#d0d0d0", shape: "x", r: 3, cls: "outside", ...marks });
    points(s, xs, inView(J, true), { color: "#2a6fdb", r: 2.6, ...marks });
    points(s, xs, inView(failedTop, true), { color: "#c92a2a", shape: "x", r: 3, ...marks });
    const t = frame(el("svg", {}, thetaIter), { width: 250, height: 170, x: [0, Math.max(state.job.iterations - 1, 1)],
      y: bounds[name], xlabel: "evaluation", ylabel: name, title: name });
    points(t, idx, ev.map((e) => (e.completed ? e.theta[name] : NaN)), { color: "#2a6fdb", r: 2.4, ...marks });
    points(t, idx, ev.map((e) => (e.completed ? NaN : e.theta[name])),
           { color: "#c92a2a", shape: "x", r: 3, ...marks });
  }
  slices.dataset.n = ev.length;
  renderRank(ev, names, bounds);

  const bestIndex = state.job.best ? ev.findIndex((e) => e.id === state.job.best.id) : -1;
  const rows = ev.map((e, i) => ({ ...e.theta, J: e.completed ? e.J : NaN, completed: e.completed,
                                   best: i === bestIndex, id: e.id }));
  const axes = [...names.map((n) => ({ key: n, label: n, range: bounds[n] })), { key: "J", label: "J", range: yr }];
  rows.sort((a, c) => Number(a.best) - Number(c.best) || Number(a.completed) - Number(c.completed) || c.J - a.J);
  parallel($("parallel"), rows, axes, { width: 860, height: 252, color: (r) => (r.completed
    ? ramp(1 - (r.J - yr[0]) / (yr[1] - yr[0] || 1), RAMPS.viridis) : "rgba(201,42,42,0.6)"),
  inside: (r) => shown.has(r.id),
  brushes: state.trials.brushes, onBrush: (key, range) => {
    if (range) state.trials.brushes[key] = range; else delete state.trials.brushes[key];
    state.trials.page = 0;
    renderTrials(state);
    renderHistoryPlots();
  } });
  $("parallel").dataset.n = ev.length;
}

/** Each parameter against the rank of J among the completed evaluations the table shows (status, best K, brushes):
 * the ordering, not the values, so that a few very good or very bad J do not flatten the rest (Optuna's rank plot). */
function renderRank(ev, names, bounds) {
  const rank = $("rank");
  rank.replaceChildren();
  const shown = new Set(shownTrials(state).map((e) => e.id));
  const done = ev.filter((e) => e.completed && shown.has(e.id)).sort((a, b) => a.J - b.J);
  const place = new Map(done.map((e, i) => [e.id, done.length > 1 ? i / (done.length - 1) : 0]));
  for (const name of names) {
    const f = frame(el("svg", { class: "rank" }, rank), { width: 250, height: 190, x: bounds[name], y: [0, 1],
      xlabel: name, ylabel: "rank of J", title: `${name} against the rank of J` });
    for (const e of done) {
      points(f, [e.theta[name]], [place.get(e.id)], { color: ramp(1 - place.get(e.id), RAMPS.viridis), r: 2.6,
        ids: [e.id], titles: [`evaluation id ${e.id} (index ${e.index}): J ${fmt(e.J)}, rank ${done.indexOf(e) + 1}`] });
    }
  }
  rank.dataset.n = done.length;
}

// ----- the search space (the models, from GET /api/jobs/{id}/search-space) -------------------------------------
async function maybeFetchSpace() {
  const x = state.axesChosen ? $("contour-x").value : "", y = state.axesChosen ? $("contour-y").value : "";
  const key = `${state.selected}:${state.evals.length}:${x}:${y}`;
  if (state.spaceBusy || key === state.spaceKey) return;
  state.spaceBusy = true;
  const id = state.selected;
  try {
    const query = x && y && x !== y ? `?x=${x}&y=${y}&grid=30` : "?grid=30";
    const space = await api("GET", `/api/jobs/${id}/search-space${query}`);
    if (id === state.selected) {
      state.space = space;
      state.spaceKey = key;
      renderSpace(state.space, state.evals);
    }
  } catch (e) {
    if (id === state.selected) say(e.message); // a job deleted meanwhile has nothing left to say
  } finally {
    state.spaceBusy = false;
  }
}

// ----- actions ------------------------------------------------------------------------------------------------
function confirmDelete(job) {
  return new Promise((resolve) => {
    const d = $("confirm");
    $("confirm-text").textContent = `Delete job ${job.id} (${job.name}) and its ${job.n_done} evaluations? ` +
      "This cannot be undone.";
    d.addEventListener("close", () => resolve(d.returnValue === "ok"), { once: true });
    d.returnValue = "";
    d.showModal();
  });
}

function wireActions() {
  $("pause").onclick = () => act(async () => {
    await api("POST", `/api/jobs/${state.selected}/pause`);
    say(`job ${state.selected}: pause requested (it stops after the evaluations in flight)`, true);
    await poll();
  });
  $("resume").onclick = () => act(async () => {
    await api("POST", `/api/jobs/${state.selected}/resume`);
    say(`job ${state.selected}: queued again`, true);
    await poll();
  });
  $("extend").onclick = () => act(async () => {
    const iterations = Number($("extend-to").value);
    await api("PATCH", `/api/jobs/${state.selected}`, { iterations });
    say(`job ${state.selected}: budget ${iterations} evaluations`, true);
    await poll();
  });
  $("delete").onclick = () => act(async () => {
    const job = state.job;
    if (!(await confirmDelete(job))) return;
    await api("DELETE", `/api/jobs/${job.id}`);
    say(`job ${job.id} (${job.name}) deleted`, true);
    state.selected = null;
    state.job = null;
    $("job-panel").hidden = true;
    await poll();
  });
  $("save-notes").onclick = () => act(async () => {
    await api("PATCH", `/api/jobs/${state.selected}`, { notes: $("notes").value });
    $("notes-saved").textContent = "saved";
  });
  $("rescore").onclick = () => act(async () => {
    await api("POST", `/api/jobs/${state.selected}/rescore`, { samples: Number($("rescore-samples").value) });
    state.rescoring = true;
    await pollRescore();
  });
  $("clone").onclick = () => fillForm(state.form, state.job);
  $("new-job").onclick = () => fillForm(state.form, null);
  $("cancel-form").onclick = () => { $("job-form").hidden = true; };
  $("job-form").onsubmit = (event) => { event.preventDefault(); act(submitForm); };
  for (const id of ["contour-x", "contour-y"]) {
    $(id).onchange = () => { state.axesChosen = true; act(maybeFetchSpace); };
  }
}

// A finished rescore's mean |e|, then the drifts' and the flicks' (a result stored before by_phase shows the mean
// alone): the episode's mean hides a drift far off its circle after a flick.
function rescoreErrors(res) {
  const groups = Object.entries(res.by_phase || {})
    .map(([group, g]) => `${group} ${fmt(g.mean_abs_e_m)} (max ${fmt(g.max_abs_e_m)})`);
  return `mean |e| ${fmt(res.mean_abs_e_m)} m` + (groups.length ? `; ${groups.join(", ")} m` : "");
}

async function pollRescore() {
  const r = await api("GET", `/api/jobs/${state.selected}/rescore`);
  const bar = $("rescore-progress");
  bar.hidden = r.status === "none";
  bar.max = r.samples || 1;
  bar.value = r.done || 0;
  if (r.status === "running" || r.status === "queued") {
    $("rescore-text").textContent = `rescore ${r.status}: ${r.done} / ${r.samples} episodes`;
  } else if (r.status === "finished") {
    const res = r.result;
    const invalid = (res.statuses || {}).invalid ? ` (${res.statuses.invalid} outside the plant's model: invalid)` : "";
    $("rescore-text").textContent = `rescore: ${res.completed} / ${res.samples} completed${invalid}, ` +
      `J mean ${fmt(res.J_mean)} ± ${fmt(res.J_std)}, worst ${fmt(res.J_worst)} (stored J ${fmt(r.J_stored)}); ` +
      rescoreErrors(res);
    state.rescoring = false;
  } else if (r.status === "failed" || r.status === "cancelled") {
    $("rescore-text").textContent = `rescore ${r.status}${r.error ? `: ${r.error}` : ""} (${r.done} / ${r.samples} ` +
      "episodes back)";
    state.rescoring = false;
  }
}

// ----- the new-job form (also "clone with changes", driftlab/server/static/jobform.js) --------------------------
async function submitForm() {
  const job = await api("POST", "/api/jobs", formBody(state.form));
  $("job-form").hidden = true;
  say(`job ${job.id} (${job.name}) queued`, true);
  await poll();
  await select(job.id);
}

// The API pages its job list (100 a page): follow the pages.
async function allJobs() {
  const jobs = [];
  for (;;) {
    const page = await api("GET", `/api/jobs?after=${jobs.length ? jobs[jobs.length - 1].id : 0}&limit=1000`);
    jobs.push(...page);
    if (page.length < 1000) return jobs;
  }
}

// ----- the loop -----------------------------------------------------------------------------------------------
async function poll() {
  state.jobs = await allJobs();
  if (state.selected !== null && !state.jobs.some((j) => j.id === state.selected)) {
    state.selected = null;
    $("job-panel").hidden = true;
  }
  renderJobs();
  if (state.selected === null && state.jobs.length) await select(state.jobs[state.jobs.length - 1].id);
  else await refreshJob();
}

async function loop() {
  try { await poll(); await state.refreshCalibration(); } catch (e) { say(e.message); }
  setTimeout(loop, POLL_MS);
}

async function start() {
  state.form = await api("GET", "/api/config/job-form");
  $("job-form").elements.plant_preset.replaceChildren(
    ...Object.keys(state.form.plant_presets).map((n) => new Option(n, n)));
  wireActions();
  wireTrials(state, { api, act, say, redraw: renderHistoryPlots });
  state.refreshCalibration = calibrationPanel(api, act, Object.keys(state.form.plant_presets));
  $("calibration-box").addEventListener("toggle", () => act(state.refreshCalibration));
  $("new-job").disabled = false; // enabled once the form can be filled
  const wanted = Number(params.get("job"));
  if (wanted) state.selected = wanted;
  loop();
}

start().catch((e) => say(e.message));
