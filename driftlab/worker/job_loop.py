"""Runs one tuning job: rebuild the optimizer from stored evaluations, then ask, evaluate, store, tell.

Shared by `driftlab tune` and the server's worker. Every evaluation is committed as it completes; a job
that was interrupted continues from what is stored, with no repeated evaluation and unbroken numbering.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, wait
from dataclasses import dataclass

from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.optimizer import BayesianOptimizer
from driftlab.core.tuning import TuningSpec
from driftlab.db import storage
from driftlab.db.models import utcnow
from driftlab.worker.executor import EpisodeExecutor, EpisodeOutcome


@dataclass
class Progress:
    n_done: int
    iterations: int
    best_J: float | None
    last: EpisodeOutcome | None
    seconds_per_evaluation: float | None

    @property
    def eta_s(self) -> float | None:
        if self.seconds_per_evaluation is None:
            return None
        return (self.iterations - self.n_done) * self.seconds_per_evaluation


def restore_optimizer(spec: TuningSpec, history: list[tuple[dict[str, float], float | None]]) -> BayesianOptimizer:
    """An optimizer in the state it had after telling ``history`` (theta, J or None if failed)."""
    optimizer = BayesianOptimizer(spec.bounds, seed_points=spec.seed_points, active_set=spec.active_set,
                                  seed=spec.seed)
    for theta, value in history:
        optimizer.tell(theta, value)
    return optimizer


def run_job(factory: sessionmaker[Session], job_id: int, executor: EpisodeExecutor, *, workers: int = 1,
            should_stop: Callable[[], bool] = lambda: False,
            on_progress: Callable[[Progress], None] | None = None) -> str:
    """Runs the job until its budget is spent or ``should_stop()``; returns the status it leaves the job in
    ("finished", "paused" or "failed")."""
    with storage.transaction(factory) as session:
        job = storage.get_job(session, job_id=job_id)
        spec = TuningSpec.from_dict(job.spec)
        stored = storage.evaluations(session, job_id=job_id)
        history = [(e.theta, e.J if e.completed else None) for e in stored]
        best = min((e.J for e in stored if e.completed), default=None)
        job.status = "running"
        job.started_at = job.started_at or utcnow()
    optimizer = restore_optimizer(spec, history)
    config_doc = spec.to_dict()["config"]
    n_done = len(history)
    running: dict[Future[EpisodeOutcome], dict[str, float]] = {}
    started = time.perf_counter()
    n_at_start = n_done
    try:
        while n_done < spec.iterations:
            stopping = should_stop()
            while not stopping and len(running) < workers and n_done + len(running) < spec.iterations:
                theta = optimizer.ask()
                running[executor.submit(theta, config_doc)] = theta
            if not running:
                break
            finished, _ = wait(list(running), return_when=FIRST_COMPLETED)
            for future in finished:
                theta = running.pop(future)
                outcome = future.result()
                with storage.transaction(factory) as session:
                    storage.add_evaluation(session, job_id=job_id, theta=theta, J=outcome.J,
                                           status=outcome.status, metrics=outcome.metrics,
                                           trigger_points=outcome.trigger_points, wall_ms=outcome.wall_ms,
                                           columns=outcome.columns, trajectory=outcome.trajectory)
                optimizer.tell(theta, outcome.J if outcome.completed else None)
                n_done += 1
                if outcome.completed:
                    best = outcome.J if best is None else min(best, outcome.J)
                if on_progress is not None:
                    rate = (time.perf_counter() - started) / max(n_done - n_at_start, 1)
                    on_progress(Progress(n_done, spec.iterations, best, outcome, rate))
    except Exception as exc:  # an evaluation crashed the worker process: the job fails, storage stays
        with storage.transaction(factory) as session:
            storage.set_job_status(session, job_id=job_id, status="failed", error=f"{type(exc).__name__}: {exc}")
        return "failed"
    status = "finished" if n_done >= spec.iterations else "paused"
    with storage.transaction(factory) as session:
        storage.set_job_status(session, job_id=job_id, status=status)
    return status
