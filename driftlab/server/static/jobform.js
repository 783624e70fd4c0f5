// The dashboard's new-job form, also "clone with changes": filled from the defaults (GET /api/config/job-form) or
// from a job's settings (its config as the `--set` keys that differ from the default), read back as the document
// POST /api/jobs takes.
"use strict";

const $ = (id) => document.getElementById(id);

// The search box shown: the default, the chosen plant preset's own box on top (a CommonRoad car's), then the job's.
function boundsRows(jobForm, bounds, modelCorrection) {
  const table = $("bounds-table");
  table.replaceChildren();
  const plant = jobForm.plant_bounds[$("job-form").elements.plant_preset.value] || {};
  const all = { ...jobForm.default_bounds, ...plant, ...(modelCorrection ? jobForm.model_bounds : {}), ...bounds };
  for (const [name, [lo, hi]] of Object.entries(all)) {
    if (!modelCorrection && name in jobForm.model_bounds) continue;
    const tr = table.insertRow();
    tr.insertCell().textContent = name;
    for (const [side, v] of [["lo", lo], ["hi", hi]]) {
      const input = document.createElement("input");
      Object.assign(input, { type: "number", step: "any", value: v, name: `bound-${name}-${side}` });
      tr.insertCell().appendChild(input);
    }
  }
}

function differingSets(jobForm, spec) {
  const dotted = {};
  for (const [section, values] of Object.entries(spec.config || {})) {
    for (const [k, v] of Object.entries(values)) dotted[`${section}.${k}`] = v;
  }
  return Object.entries(dotted).filter(([k, v]) => JSON.stringify(jobForm.default_config[k]) !== JSON.stringify(v))
    .map(([k, v]) => `${k}=${typeof v === "string" ? v : JSON.stringify(v)}`).join("\n");
}

export function openForm(jobForm, job) {
  const f = $("job-form");
  f.hidden = false;
  const spec = job ? job.spec : jobForm.defaults;
  $("form-title").textContent = job ? `Clone job ${job.id} (${job.name}) with changes` : "New job";
  f.elements.name.value = job ? `${job.name}-clone` : "";
  for (const k of ["iterations", "seed_points", "robust_samples", "confirm_samples", "seed"]) {
    f.elements[k].value = k === "iterations" && !job ? 60 : spec[k];
  }
  f.elements.model_correction.checked = spec.model_correction;
  f.elements.deterministic.checked = spec.deterministic;
  f.elements.sets.value = job ? differingSets(jobForm, job.spec) : "";
  const stop = spec.stop || {};
  f.elements.time_budget_s.value = stop.time_budget_s ?? "";
  f.elements.no_improvement_evaluations.value = stop.no_improvement_evaluations ?? "";
  f.elements.no_improvement_by.value = stop.no_improvement_by ?? 0;
  const sources = (job && job.spec.warm_start && job.spec.warm_start.from_jobs) || [];
  f.elements.warm_start_from.value = sources.map((s) => s.job_id).join(", ");
  f.elements.plant_preset.value = "default";
  boundsRows(jobForm, job ? job.spec.bounds : {}, spec.model_correction);
  f.elements.model_correction.onchange = () => boundsRows(jobForm, {}, f.elements.model_correction.checked);
  f.elements.plant_preset.onchange = () => boundsRows(jobForm, {}, f.elements.model_correction.checked);
  f.elements.name.focus();
}

// `key=value` lines (the --set syntax) as a config document; a value that is not JSON is text.
export function parseSets(text) {
  const out = {};
  text.split("\n").map((l) => l.trim()).filter(Boolean).forEach((lineText, i) => {
    const at = lineText.indexOf("=");
    if (at < 1) throw new Error(`sets, line ${i + 1}: expected key=value, got ${JSON.stringify(lineText)}`);
    const raw = lineText.slice(at + 1).trim();
    let value;
    try { value = JSON.parse(raw); } catch { value = raw; } // text values (plant.model=commonroad_std)
    out[lineText.slice(0, at).trim()] = value;
  });
  return out;
}

// The POST /api/jobs document the form describes: the preset's config keys, then the typed ones on top.
export function formBody(jobForm) {
  const f = $("job-form").elements;
  const body = { iterations: Number(f.iterations.value), seed_points: Number(f.seed_points.value),
    robust_samples: Number(f.robust_samples.value), confirm_samples: Number(f.confirm_samples.value),
    seed: Number(f.seed.value), model_correction: f.model_correction.checked, deterministic: f.deterministic.checked,
    config: { ...jobForm.plant_presets[f.plant_preset.value], ...parseSets(f.sets.value) }, bounds: {} };
  if (f.name.value.trim()) body.name = f.name.value.trim();
  const stop = {};
  if (f.time_budget_s.value !== "") stop.time_budget_s = Number(f.time_budget_s.value);
  if (f.no_improvement_evaluations.value !== "") {
    stop.no_improvement_evaluations = Number(f.no_improvement_evaluations.value);
    stop.no_improvement_by = Number(f.no_improvement_by.value || 0);
  }
  if (Object.keys(stop).length) body.stop = stop;
  const sources = f.warm_start_from.value.split(",").map((t) => t.trim()).filter(Boolean);
  if (sources.length) body.warm_start_from = sources.map(Number);
  for (const input of $("bounds-table").querySelectorAll("input")) {
    const [, name, side] = input.name.match(/^bound-(.+)-(lo|hi)$/);
    body.bounds[name] = body.bounds[name] || [0, 0];
    body.bounds[name][side === "lo" ? 0 : 1] = Number(input.value);
  }
  return body;
}
