// The dashboard's calibration panel: a car calibrated through POST /api/calibrations (as `driftlab calibrate`), its
// progress followed, cancelled; the stored car profiles listed (GET /api/profiles), each a download.
"use strict";
import { parseSets } from "./jobform.js";

const $ = (id) => document.getElementById(id);

function requestBody() {
  const f = $("calibration-form").elements;
  const body = { plant: f.plant.value, config: parseSets(f.sets.value), iterations: Number(f.iterations.value),
    seeds: Number(f.seeds.value), rounds: Number(f.rounds.value) };
  if (f.points.value.trim()) body.points = f.points.value.trim();
  return body;
}

function progressText(c) {
  const p = c.progress;
  if (c.status === "queued") return `calibration ${c.id} queued`;
  if (c.status === "running" && p) {
    return `calibration ${c.id}: ${p.points.join(", ")} (search ${p.group} of ${p.groups}, round ${p.round} of ` +
      `${p.rounds}): ${p.step === "theta" ? "theta" : "weight set"} ${p.tried} of ${p.of}, best score ` +
      `${p.best_score.toFixed(3)}`;
  }
  if (c.status === "running") return `calibration ${c.id} running: ${c.messages[c.messages.length - 1] || ""}`;
  const profiles = c.profile_ids.length ? `, profiles ${c.profile_ids.join(", ")}` : "";
  return `calibration ${c.id} ${c.status}${c.error ? `: ${c.error}` : ""}${profiles}`;
}

function renderCalibration(c) {
  const running = c && (c.status === "queued" || c.status === "running");
  $("calibrate").disabled = running;
  $("cancel-calibration").hidden = !running;
  const bar = $("calibration-progress");
  bar.hidden = !(running && c.progress);
  if (running && c.progress) {
    const p = c.progress;
    const perSearch = p.rounds;
    bar.max = p.groups * perSearch;
    bar.value = (p.group - 1) * perSearch + (p.round - 1) + p.tried / p.of;
  }
  $("calibration-text").textContent = c ? progressText(c) : "";
}

function renderProfiles(profiles) {
  const body = $("profile-table").tBodies[0];
  body.replaceChildren();
  for (const p of profiles.slice().reverse()) {
    for (const point of p.per_point || [{}]) {
      const tr = body.insertRow();
      const link = document.createElement("a");
      link.href = `/api/profiles/${p.id}`;
      link.textContent = String(p.id);
      tr.insertCell().appendChild(link);
      const e = point.mean_abs_e_m;
      for (const text of [`${p.plant_model} ${p.vehicle_id}`, `${point.sideslip_rad}@${point.radius_m}`,
        `${point.completed} / ${point.episodes}`, e === null || e === undefined ? "–" : e.toFixed(2)]) {
        tr.insertCell().textContent = text;
      }
    }
  }
}

// Wires the panel; ``api`` is the page's fetch wrapper, ``act`` runs an action and shows its error.
export function calibrationPanel(api, act, presets) {
  const f = $("calibration-form");
  f.elements.plant.replaceChildren(...presets.map((n) => new Option(n, n)));
  f.elements.plant.value = presets.includes("commonroad_std") ? "commonroad_std" : presets[0];
  let latest = null;
  f.addEventListener("submit", (event) => {
    event.preventDefault();
    act(async () => { latest = await api("POST", "/api/calibrations", requestBody()); renderCalibration(latest); });
  });
  $("cancel-calibration").addEventListener("click", () => act(async () => {
    if (latest) renderCalibration(await api("DELETE", `/api/calibrations/${latest.id}`));
  }));
  // Read again with the page's loop: the newest calibration and the profiles.
  return async function refresh() {
    if (!$("calibration-box").open) return;
    const all = await api("GET", "/api/calibrations");
    latest = all.length ? all[all.length - 1] : null;
    renderCalibration(latest);
    renderProfiles(await api("GET", "/api/profiles"));
  };
}
