"""JSON and CSV representations of stored jobs and evaluations (theta at full precision everywhere)."""

from __future__ import annotations

import csv
import io
from datetime import UTC
from typing import Any

from driftlab.core.config import THETA_KEYS, Theta
from driftlab.db import storage
from driftlab.db.models import Evaluation, Job


def evaluation_dict(e: Evaluation) -> dict[str, Any]:
    return {"id": e.id, "job_id": e.job_id, "index": e.index, "theta": e.theta, "J": e.J, "status": e.status,
            "completed": e.completed, "metrics": e.metrics, "trigger_points": e.trigger_points,
            "wall_ms": e.wall_ms, "seeds": e.seeds, "trajectory_seed": e.trajectory_seed,
            "created_at": e.created_at.replace(tzinfo=UTC).isoformat()}


CSV_FIELDS = ("id", "index", "status", "J", *THETA_KEYS, "n_samples", "n_completed", "seeds", "trajectory_seed",
              "mean_abs_e_m", "max_abs_e_m", "completed_fraction", "wall_ms", "created_at")


def evaluations_csv(rows: list[dict[str, Any]]) -> str:
    """csv writes floats with repr(): the shortest text that reads back as the same double."""
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    writer.writerow(CSV_FIELDS)
    for row in rows:
        metrics, seeds = row["metrics"], row["seeds"] or []
        # a theta stored before the model corrections ran the model as configured: scales 1
        summary = {k: metrics.get(k) for k in ("n_samples", "n_completed", "mean_abs_e_m", "max_abs_e_m",
                                                "completed_fraction")}
        flat = {**row, **Theta().as_dict(), **row["theta"], **summary,
                "seeds": " ".join(str(s["seed"]) for s in seeds)}
        writer.writerow([flat.get(name) for name in CSV_FIELDS])
    return buffer.getvalue()


def job_dict(session, job: Job) -> dict[str, Any]:
    n_done = storage.count_evaluations(session, job_id=job.id)
    iterations = job.spec["iterations"]
    best = storage.best_evaluation(session, job_id=job.id)
    rate = storage.seconds_per_evaluation(session, job_id=job.id) if job.status == "running" else None
    eta = None if rate is None else rate * (iterations - n_done)
    return {"id": job.id, "name": job.name, "status": job.status, "seed": job.seed, "n_done": n_done,
            "iterations": iterations, "progress": n_done / iterations, "eta_s": eta, "error": job.error,
            "best": None if best is None else {"evaluation_id": best.id, "index": best.index, "theta": best.theta,
                                               "J": best.J, "status": best.status, "seeds": best.seeds},
            "runner_id": job.runner_id, "study_id": job.study_id, "spec": job.spec,
            "created_at": job.created_at.replace(tzinfo=UTC).isoformat()}
