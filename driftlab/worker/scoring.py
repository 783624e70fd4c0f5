"""Scoring thetas outside a tuning job: rescoring a job's best under fresh seeds, and a report's baselines.

Every episode runs on the executor (worker processes), never in the caller, and is a pure function of
(theta, config, seed): a rescore is itself reproducible.
"""

from __future__ import annotations

from typing import Any

from driftlab.core.robust import SampleResult, rescore_seeds, summarize
from driftlab.core.tuning import TuningSpec
from driftlab.db import storage
from driftlab.worker.executors import EpisodeExecutor, open_executor


def score_thetas(executor: EpisodeExecutor, thetas: list[dict[str, float]], config_doc: dict[str, Any],
                 seeds: list[int]) -> list[list[SampleResult]]:
    """Each theta run once per seed; all episodes submitted at once so that every worker stays busy."""
    futures = [[executor.submit(theta, config_doc, seed) for seed in seeds] for theta in thetas]
    return [[f.result().sample for f in row] for row in futures]


def rescore_job(*, db_url: str, name: str, samples: int = 30, workers: int | None = 2,
                dask_address: str | None = None) -> dict[str, Any]:
    """The job's best theta, exactly as stored, under ``samples`` seeds no tuning job uses."""
    factory = storage.open_database(db_url)
    with storage.transaction(factory) as session:
        job = storage.get_job_by_name(session, name=name)
        spec = TuningSpec.from_dict(job.spec)
        best = storage.best_evaluation(session, job_id=job.id)
        if best is None:
            raise storage.NotFound(f"job {name!r} has no evaluations yet")
        theta, stored_j, stored_status = dict(best.theta), best.J, best.status
    executor, _ = open_executor(workers or (None if dask_address else 2), dask_address)
    try:
        [results] = score_thetas(executor, [theta], spec.to_dict()["config"], rescore_seeds(samples))
    finally:
        executor.shutdown()
    return {"job": name, "theta": theta, **summarize(results), "J_stored": stored_j, "status_stored": stored_status,
            "robust_samples": spec.robust_samples, "seeds": [r.seed for r in results]}
