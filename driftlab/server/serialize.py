"""JSON and CSV representations of stored jobs and evaluations (theta at full precision everywhere)."""

from __future__ import annotations

import csv
import io
from datetime import UTC
from typing import Any

from driftlab.core.config import THETA_KEYS, Theta
from driftlab.core.errors import ConfigError
from driftlab.core.warm_start import WarmStart
from driftlab.db import storage
from driftlab.db.models import Evaluation, Job, WorkStatus
from driftlab.services.read_model import compiling


def evaluation_dict(e: Evaluation) -> dict[str, Any]:
    return {"id": e.id, "job_id": e.job_id, "index": e.index, "theta": e.theta, "J": e.J, "status": e.status,
            "completed": e.completed, "metrics": e.metrics, "trigger_points": e.trigger_points,
            "wall_ms": e.wall_ms, "seeds": e.seeds, "trajectory_seed": e.trajectory_seed, "enqueued": e.enqueued,
            "created_at": e.created_at.replace(tzinfo=UTC).isoformat()}


CSV_FIELDS = ("id", "index", "status", "J", *THETA_KEYS, "n_samples", "n_completed", "seeds", "trajectory_seed",
              "mean_abs_e_m", "max_abs_e_m", "completed_fraction", "wall_ms", "created_at", "enqueued")


def evaluations_csv(rows: list[dict[str, Any]]) -> str:
    """csv writes floats with repr(): the shortest text that reads back as the same double."""
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    writer.writerow(CSV_FIELDS)
    for row in rows:
        metrics, seeds = row["metrics"], row["seeds"] or []
        summary = {k: metrics.get(k) for k in ("n_samples", "n_completed", "mean_abs_e_m", "max_abs_e_m",
                                                "completed_fraction")}
        flat = {**row, **Theta.filled(row["theta"]), **summary,
                "seeds": " ".join(str(s["seed"]) for s in seeds)}
        writer.writerow([flat.get(name) for name in CSV_FIELDS])
    return buffer.getvalue()


def job_dict(session, job: Job) -> dict[str, Any]:
    n_done, best = storage.count_and_best(session, job_id=job.id)
    iterations = job.spec["iterations"]
    running = job.status == WorkStatus.RUNNING
    rate = storage.seconds_per_evaluation(session, job_id=job.id, since=job.started_at) if running else None
    eta = None if rate is None else rate * (iterations - n_done)
    return {"id": job.id, "name": job.name, "status": job.status, "detail": job_detail(job.status, rate),
            "seed": job.seed, "n_done": n_done,
            "iterations": iterations, "progress": n_done / iterations, "eta_s": eta, "error": job.error,
            "best": storage.best_summary(best), "best_told": best_told(job.spec),
            "runner_id": job.runner_id, "study_id": job.study_id, "profile_id": job.profile_id, "spec": job.spec,
            "run_s": job.run_s or 0.0, "stop_reason": job.stop_reason,
            "notes": job.notes or "",
            "created_at": job.created_at.replace(tzinfo=UTC).isoformat()}


def best_told(spec: dict[str, Any]) -> dict[str, Any] | None:
    """The best evaluation a warm start told the job from jobs of its own config (driftlab.core.warm_start)."""
    warm = spec.get("warm_start")
    if not warm:
        return None
    try:
        return WarmStart.from_dict(warm).best_told()
    except ConfigError:  # a document no release wrote: nothing to show
        return None


COMPILING = "compiling the simulation (numba, once after an install; no evaluation until it is done)"


def job_detail(status: str, seconds_per_evaluation: float | None) -> str | None:
    """What a running job does when its status alone does not say: compiling before its run's first evaluation."""
    if seconds_per_evaluation is None and compiling(status):
        return COMPILING
    return None


def trajectory_metadata(e: Evaluation, job: Job) -> dict[str, Any]:
    """What a downloaded trajectory is: the evaluation, its job, theta, the drawn episode's seed and J (the worst
    of the evaluation's seeds), the evaluation's J over all its seeds, that episode's phases in numbers
    (driftlab.core.metrics.phase_segments), and the config to re-run it with."""
    episode = e.shown_episode
    return {"evaluation_id": e.id, "job_id": job.id, "job_name": job.name, "index": e.index,
            "theta": Theta.filled(e.theta), "seed": e.shown_seed, "J_episode": episode["J"],
            "episode_status": episode["status"], "J": e.J, "status": e.status, "n_seeds": max(len(e.seeds or ()), 1),
            "phases": (e.metrics or {}).get("phases", []), "config": job.spec.get("config", {})}
