"""Where the view's data comes from: stored evaluations (by job, through driftlab.services.read_model) and episodes
the worker just ran."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from driftlab.core.convergence import best_position, best_so_far
from driftlab.core.track import FigureEight
from driftlab.services import read_model
from driftlab.web.frames import EpisodeFrames


def frames_of_evaluation(factory: read_model.Factory, evaluation_id: int) -> EpisodeFrames:
    """A stored evaluation with its trajectory (raises read_model.NotFound)."""
    e = read_model.stored_episode(factory, evaluation_id)
    return EpisodeFrames(e.columns, e.rows, e.trigger_points, evaluation_id=e.evaluation_id, index=e.index,
                         theta=e.theta, status=e.status, J=e.J, seed=e.seed, episode_J=e.episode_J,
                         n_seeds=e.n_seeds, failure_reason=e.failure_reason, job=e.job, car=e.plant)


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

    def refresh(self, factory: read_model.Factory) -> bool:
        """Read job status and evaluations newer than the last one held; True if anything changed."""
        with self._lock:
            job = read_model.job_rows(factory, self.job_id, after=len(self.ids) - 1)
            changed = bool(job.evaluations) or job.status != self.status
            self.name, self.status, self.iterations, self.spec = job.name, job.status, job.iterations, job.spec
            for evaluation_id, value, completed, theta in job.evaluations:
                self.ids.append(evaluation_id)
                self.values.append(value)
                self.completed.append(completed)
                self.thetas.append(theta)
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
