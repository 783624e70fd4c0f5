"""Where the view's data comes from: stored evaluations (by job) and episodes the worker just ran."""

from __future__ import annotations

import functools
import json
import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.config import ConfigError, config_from_dict
from driftlab.core.convergence import best_position, best_so_far
from driftlab.core.drivability import drift_window
from driftlab.core.track import FigureEight
from driftlab.db import storage, studies
from driftlab.db.models import Evaluation
from driftlab.markup import plain
from driftlab.services import studies as study_views
from driftlab.services.job_documents import spec_diff
from driftlab.web.frames import EpisodeFrames


def frames_of_evaluation(factory: sessionmaker[Session], evaluation_id: int) -> EpisodeFrames:
    """A stored evaluation with its trajectory (raises storage.NotFound)."""
    with storage.snapshot(factory) as session:
        e = storage.get_evaluation(session, evaluation_id=evaluation_id)
        columns, rows = storage.trajectory_array(session, evaluation_id=evaluation_id)
        seeds = list(e.seeds or ())
        seed = e.trajectory_seed if e.trajectory_seed is not None else (seeds[0]["seed"] if seeds else 0)
        episode_j = next((float(s["J"]) for s in seeds if s["seed"] == seed), float(e.J))
        return EpisodeFrames(tuple(columns), rows, tuple(e.trigger_points or ()), evaluation_id=e.id,
                             index=e.index, theta=dict(e.theta), status=e.status, J=float(e.J), seed=int(seed),
                             episode_J=episode_j, n_seeds=max(len(seeds), 1),
                             failure_reason=str((e.metrics or {}).get("failure_reason") or ""))


def frames_of_outcome(outcome: Any, plant: dict[str, float] | None = None) -> EpisodeFrames:
    """An episode the worker ran (an ``EpisodeOutcome``), not stored; ``plant``: the settings it changed."""
    return EpisodeFrames(tuple(outcome.columns), np.asarray(outcome.trajectory), tuple(outcome.trigger_points),
                         theta=dict(outcome.theta), status=outcome.status, J=float(outcome.J),
                         seed=int(outcome.seed), episode_J=float(outcome.J), plant=dict(plant or {}),
                         failure_reason=str((outcome.metrics or {}).get("failure_reason") or ""))


def car_geometry_of_spec(spec: dict[str, Any]) -> tuple[float, float]:
    """(CG to front axle, CG to rear axle) [m] of a job's car: the geometry its config's vehicle has (a CommonRoad
    plant's model carries the car's own)."""
    vehicle = spec.get("config", {}).get("vehicle", {})
    return float(vehicle.get("cg_to_front_m", 1.39)), float(vehicle.get("cg_to_rear_m", 1.0008))


def track_of_spec(spec: dict[str, Any]) -> FigureEight:
    return FigureEight.of_scenario(spec.get("config", {}).get("scenario", {}))


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


@dataclass
class JobHistory:
    """The evaluations of one job as columns, grown by :meth:`refresh` (only new rows are read)."""

    job_id: int
    name: str = ""
    status: str = ""
    iterations: int = 0
    spec: dict[str, Any] = field(default_factory=dict)
    ids: list[int] = field(default_factory=list)
    values: list[float] = field(default_factory=list)
    completed: list[bool] = field(default_factory=list)
    thetas: list[dict[str, float]] = field(default_factory=list)
    # The poller grows the lists while tabs read them: readers must never see them at different lengths.
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def refresh(self, factory: sessionmaker[Session]) -> bool:
        """Read job status and evaluations newer than the last one held; True if anything changed."""
        with self._lock, storage.snapshot(factory) as session:
            job = storage.get_job(session, job_id=self.job_id)
            rows: list[Evaluation] = storage.evaluations(session, job_id=self.job_id, after=len(self.ids) - 1)
            changed = bool(rows) or job.status != self.status
            self.name, self.status, self.iterations, self.spec = job.name, job.status, job.spec["iterations"], job.spec
            for e in rows:
                self.ids.append(e.id)
                self.values.append(float(e.J))
                self.completed.append(bool(e.completed))
                self.thetas.append(dict(e.theta))
        return changed

    @property
    def n_done(self) -> int:
        return len(self.ids)

    def best_position(self) -> int | None:
        """Position (= evaluation index) of the lowest J among completed evaluations."""
        with self._lock:
            return best_position(self.values, self.completed)

    def convergence(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(index, J of completed or NaN, best-so-far J or NaN, failed marker or NaN).

        Failed evaluations store a penalty, not a drift cost; they are marked at the top edge of the completed
        values so they do not squash the scale.
        """
        with self._lock:
            values = np.array(self.values, dtype=float)
            ok = np.array(self.completed, dtype=bool)
        index = np.arange(len(values), dtype=float)
        j_done = np.where(ok, values, np.nan)
        best = np.array([np.nan if b is None else b for b in best_so_far(values, ok)], dtype=float)
        top = np.nanmax(j_done) if ok.any() else 0.0
        failed = np.where(ok, np.nan, top)
        return index, j_done, best, failed


def read_studies(factory: sessionmaker[Session]) -> list[tuple[int, str, str, str]]:
    """(id, name, kind, status) of every study, oldest first."""
    with storage.snapshot(factory) as session:
        return [(s.id, s.name, s.kind, studies.study_status(session, s)) for s in studies.list_studies(session)]


def read_study(factory: sessionmaker[Session], study_id: int) -> dict[str, Any]:
    """A study as GET /api/studies/{id} shows it (raises storage.NotFound)."""
    with storage.snapshot(factory) as session:
        return study_views.study_summary(session, studies.get_study(session, study_id=study_id))


def read_compare(factory: sessionmaker[Session], job_ids: list[int]) -> list[dict[str, Any]]:
    """Each job's best, n_done and convergence, as GET /api/compare shows them (raises storage.NotFound)."""
    with storage.snapshot(factory) as session:
        return study_views.compare_jobs(session, job_ids=job_ids)


def read_config_diff(factory: sessionmaker[Session], job_ids: list[int]) -> dict[str, Any]:
    """The settings that differ between the jobs, as GET /api/compare/config shows them (raises storage.NotFound)."""
    with storage.snapshot(factory) as session:
        jobs = [storage.get_job(session, job_id=i) for i in job_ids]
        return {"jobs": [{"id": j.id, "name": j.name} for j in jobs], "differences": spec_diff([j.spec for j in jobs])}


def enqueue_theta(factory: sessionmaker[Session], job_id: int, theta: dict[str, float]) -> str:
    """Enqueue a what-if theta for the job (driftlab.services.enqueue); what happened, in words."""
    from driftlab.core.errors import ConfigError
    from driftlab.db.lifecycle import TransitionError
    from driftlab.services.enqueue import enqueue_thetas

    try:
        with storage.transaction(factory) as session:
            row, = enqueue_thetas(session, job_id=job_id, thetas=[theta], field="theta")
    except (ConfigError, TransitionError, storage.NotFound) as exc:
        return f"not added: {exc}"
    return f"added to job {job_id} (queue entry {row.id}): it is evaluated next"
