"""Rescoring from the server (POST /api/jobs/{id}/rescore): a job's best theta, exactly as stored, under fresh seeds
(the same episodes as ``driftlab rescore``), on a worker process of its own so that it never waits behind a job's
evaluations and a job never waits behind it. Progress and the result are kept while the server runs.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.robust import rescore_seeds, summarize
from driftlab.core.tuning import TuningSpec
from driftlab.db import storage
from driftlab.worker.executors import EpisodeExecutor, LocalProcessExecutor


class RescoreBusy(Exception):
    """A rescore of this job is already running."""


class RescoreRunner:
    def __init__(self, factory: sessionmaker[Session],
                 open_executor: Callable[[], EpisodeExecutor] = lambda: LocalProcessExecutor(1)) -> None:
        self.factory = factory
        self._open_executor = open_executor
        self._executor: EpisodeExecutor | None = None
        self._lock = threading.Lock()
        self._state: dict[int, dict[str, Any]] = {}

    def start(self, job_id: int, samples: int) -> dict[str, Any]:
        """Submit the best theta's episodes; returns the state at once.

        Raises:
            storage.NotFound: no such job, or no completed evaluation to rescore.
            RescoreBusy: one is running for this job.
        """
        with storage.snapshot(self.factory) as session:
            job = storage.get_job(session, job_id=job_id)
            best = storage.best_evaluation(session, job_id=job_id)
            if best is None:
                raise storage.NotFound(f"job {job_id} has no evaluation to rescore yet")
            theta, config = dict(best.theta), TuningSpec.from_dict(job.spec).to_dict()["config"]
            stored = {"evaluation_id": best.id, "J_stored": best.J, "status_stored": best.status}
        seeds = rescore_seeds(samples)
        with self._lock:
            if self._state.get(job_id, {}).get("status") == "running":
                raise RescoreBusy(f"job {job_id}: a rescore is running ({self._state[job_id]['done']} / "
                                  f"{self._state[job_id]['samples']} episodes)")
            if self._executor is None:
                self._executor = self._open_executor()
            state = {"job_id": job_id, "status": "running", "samples": samples, "done": 0, "theta": theta, **stored,
                     "result": None, "error": None}
            self._state[job_id] = state
            futures = [self._executor.submit(theta, config, seed) for seed in seeds]
        for future in futures:
            future.add_done_callback(lambda f, s=state, fs=futures: self._one_done(s, fs))
        return self.status(job_id)

    def _one_done(self, state: dict[str, Any], futures: list[Future]) -> None:
        with self._lock:
            state["done"] += 1
            if state["done"] < len(futures):
                return
        try:
            result = summarize([f.result().sample() for f in futures])
            with self._lock:
                state.update(status="finished", result={**result, "seeds": [f.result().seed for f in futures]})
        except Exception as exc:  # a dead worker: the rescore failed, the server goes on
            with self._lock:
                state.update(status="failed", error=f"{type(exc).__name__}: {exc}")

    def status(self, job_id: int) -> dict[str, Any]:
        """The job's rescore: running (with ``done`` of ``samples``), finished (with ``result``), failed, or none."""
        with self._lock:
            state = self._state.get(job_id)
            return {"job_id": job_id, "status": "none"} if state is None else dict(state)

    def stop(self) -> None:
        with self._lock:
            executor, self._executor = self._executor, None
        if executor is not None:
            executor.shutdown()
