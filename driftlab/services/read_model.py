"""The read model: what is stored, in the shapes the view (driftlab.web) and the reports draw: a stored evaluation
with the episode kept as its trajectory, a job's evaluations as they arrive, studies, comparisons, the drift window
of a job's plant; and what the view writes: the config a what-if episode runs with, a theta enqueued from it. The
view draws what this module gives it and imports neither the database nor the physics (tests/test_layers.py)."""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.compiled import episode_kernels_cached
from driftlab.core.config import config_to_dict
from driftlab.core.configure import apply_overrides, config_from_dict
from driftlab.core.drivability import check_drivable, drift_window
from driftlab.core.errors import ConfigError
from driftlab.core.statuses import WorkStatus
from driftlab.db import storage, studies
from driftlab.db.lifecycle import TransitionError
from driftlab.markup import plain
from driftlab.services import studies as study_views
from driftlab.services.enqueue import enqueue_thetas
from driftlab.services.job_documents import spec_diff

NotFound = storage.NotFound
Factory = sessionmaker[Session]  # what the view holds to read through this module (it opens no session itself)


@dataclass(frozen=True)
class StoredEpisode:
    """A stored evaluation and the episode kept as its trajectory (one row per control step, ``columns`` named),
    with that episode's metrics (driftlab.core.metrics.EpisodeMetrics as stored: its laps, its phases)."""

    columns: tuple[str, ...]
    rows: np.ndarray
    trigger_points: tuple[dict[str, float], ...]
    evaluation_id: int
    index: int
    theta: dict[str, float]
    status: str
    J: float
    seed: int
    episode_J: float
    n_seeds: int
    failure_reason: str
    metrics: dict[str, Any]
    job: str  # "job 3 · name"
    plant: str  # the plant it ran on: "commonroad_std, CommonRoad vehicle 2 (BMW 320i)"

    @property
    def column_index(self) -> dict[str, int]:
        return {name: i for i, name in enumerate(self.columns)}

    @property
    def trajectory(self) -> np.ndarray:
        return self.rows

    def column(self, name: str) -> np.ndarray:
        return self.rows[:, self.columns.index(name)]


def stored_episode(factory: Factory, evaluation_id: int) -> StoredEpisode:
    """Raises NotFound (no such evaluation, or its trajectory was not kept)."""
    with storage.snapshot(factory) as session:
        e = storage.get_evaluation(session, evaluation_id=evaluation_id)
        columns, rows = storage.trajectory_array(session, evaluation_id=evaluation_id)
        return StoredEpisode(tuple(columns), rows, tuple(e.trigger_points or ()), evaluation_id=e.id, index=e.index,
                             theta=dict(e.theta), status=e.status, J=float(e.J), seed=e.shown_seed,
                             episode_J=float(e.shown_episode["J"]), n_seeds=max(len(e.seeds or ()), 1),
                             failure_reason=str((e.metrics or {}).get("failure_reason") or ""),
                             metrics=dict(e.metrics or {}), job=f"job {e.job.id} · {e.job.name}",
                             plant=plant_label(e.job.spec))


def plant_label(spec: dict[str, Any]) -> str:
    """The plant a job runs, as a played episode names it: its ``plant.model``, and its car where the plant has
    several (a CommonRoad parameter set)."""
    from driftlab.core.plants import plant_type

    plant = spec.get("config", {}).get("plant", {})
    model = str(plant.get("model", "default"))
    entry = plant_type(model)
    if entry is None or not hasattr(entry, "car_name") or "commonroad_vehicle" not in plant:
        return model
    return f"{model}, {entry.car_name(int(plant['commonroad_vehicle']))}"


@dataclass(frozen=True)
class JobRows:
    """A job as it is now and its evaluations after a position: (id, J, completed, theta) each, in index order."""

    name: str
    status: str
    iterations: int
    spec: dict[str, Any]
    evaluations: list[tuple[int, float, bool, dict[str, float]]]


def job_rows(factory: Factory, job_id: int, after: int) -> JobRows:
    """The job and its evaluations of index > ``after`` (raises NotFound)."""
    with storage.snapshot(factory) as session:
        job = storage.get_job(session, job_id=job_id)
        rows = storage.evaluations(session, job_id=job_id, after=after)
        return JobRows(job.name, job.status, int(job.spec["iterations"]), job.spec,
                       [(e.id, float(e.J), bool(e.completed), dict(e.theta)) for e in rows])


def job_list(factory: Factory) -> list[tuple[int, str, str]]:
    """(id, name, status) of every job, oldest first."""
    with storage.snapshot(factory) as session:
        return [(j.id, j.name, j.status) for j in storage.list_jobs(session)]


def compiling(status: str) -> bool:
    """Whether a job with this status waits for the simulation's first compile (numba, once after an install)."""
    return status == WorkStatus.RUNNING and episode_kernels_cached() is False


def study_list(factory: Factory) -> list[tuple[int, str, str, str]]:
    """(id, name, kind, status) of every study, oldest first."""
    with storage.snapshot(factory) as session:
        return [(s.id, s.name, s.kind, studies.study_status(session, s)) for s in studies.list_studies(session)]


def study(factory: Factory, study_id: int) -> dict[str, Any]:
    """A study as GET /api/studies/{id} shows it (raises NotFound)."""
    with storage.snapshot(factory) as session:
        return study_views.study_summary(session, studies.get_study(session, study_id=study_id))


def compare(factory: Factory, job_ids: list[int]) -> list[dict[str, Any]]:
    """Each job's best, n_done and convergence, as GET /api/compare shows them (raises NotFound)."""
    with storage.snapshot(factory) as session:
        return study_views.compare_jobs(session, job_ids=job_ids)


def config_diff(factory: Factory, job_ids: list[int]) -> dict[str, Any]:
    """The settings that differ between the jobs, as GET /api/compare/config shows them (raises NotFound)."""
    with storage.snapshot(factory) as session:
        jobs = [storage.get_job(session, job_id=i) for i in job_ids]
        return {"jobs": [{"id": j.id, "name": j.name} for j in jobs], "differences": spec_diff([j.spec for j in jobs])}


def enqueue_theta(factory: Factory, job_id: int, theta: dict[str, float]) -> str:
    """Enqueue a what-if theta for the job (driftlab.services.enqueue); what happened, in words."""
    try:
        with storage.transaction(factory) as session:
            row, = enqueue_thetas(session, job_id=job_id, thetas=[theta], field="theta")
    except (ConfigError, TransitionError, NotFound) as exc:
        return f"not added: {exc}"
    return f"added to job {job_id} (queue entry {row.id}): it is evaluated next"


def what_if_config(config_doc: dict[str, Any], plant_overrides: dict[str, float]) -> dict[str, Any]:
    """The config document a what-if episode runs with: a job's config with the plant settings the panel changed
    (raises ConfigError naming the setting, or the reason the car cannot drift it)."""
    config = apply_overrides(config_from_dict(config_doc), plant_overrides)
    check_drivable(config)
    return config_to_dict(config)


def plant_settings(spec: dict[str, Any]) -> dict[str, Any]:
    """A job's plant settings, every key filled (a job stored by an earlier release may lack newer ones)."""
    return config_to_dict(config_from_dict(spec.get("config", {})))["plant"]


def drift_window_text(spec: dict[str, Any]) -> str:
    """The job's plant's drift window at each radius of its 8 (what ``driftlab equilibrium --window`` prints and
    the drivability check decides), as a line for the view. Seconds for a CommonRoad car: call it off the GUI."""
    return _drift_window_text(json.dumps(spec.get("config", {}), sort_keys=True))


@functools.lru_cache(maxsize=64)
def _drift_window_text(config_json: str) -> str:
    try:
        config = config_from_dict(json.loads(config_json))
    except ConfigError as exc:
        return f"**Drift window**: none to show ({plain(exc)})."
    scenario = config.scenario
    radii = dict.fromkeys((scenario.left_radius_m, scenario.right_radius_m))
    parts = []
    for radius_m in radii:
        runs = drift_window(config, radius_m).ranges_rad
        where = ", ".join(f"{low:.2f}-{high:.2f}" for low, high in runs) or "none"
        inside = any(low - 1e-9 <= scenario.sideslip_rad <= high + 1e-9 for low, high in runs)
        parts.append(f"R {radius_m:.4g} m: {where} rad ({scenario.sideslip_rad:.4g} "
                     f"{'inside' if inside else 'outside'})")
    return ("**Drift window** of this plant, the sideslips that drift each circle: " + "; ".join(parts) + ".")
