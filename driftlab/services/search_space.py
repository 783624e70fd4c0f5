"""A job's search space as the dashboard shows it (GET /api/jobs/{id}/search-space): the GP mean and uncertainty
of J over two theta coordinates, the learned probability of failure, and the parameters' importance, from the
models of :mod:`driftlab.core.search_space` fitted to the job's stored evaluations.

Fitted models are kept per (job, evaluations stored): a stored evaluation never changes and a job's id is never
reused, so tabs that poll a job refit only when an evaluation lands, once for all of them.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from concurrent.futures import Future
from typing import TYPE_CHECKING, Any

import numpy as np
from sqlalchemy.orm import Session, sessionmaker

from driftlab.db import storage

if TYPE_CHECKING:
    from driftlab.core.search_space import SearchSpaceModels

_CACHE_SIZE = 16


class SearchSpaceCache:
    """Fitted models by (job, evaluations stored), bounded; a fit in progress is shared (single flight): every tab
    that asks for the same job while its models are being fitted waits for that one fit."""

    def __init__(self, size: int = _CACHE_SIZE) -> None:
        self.size = size
        self._models: OrderedDict[tuple[int, int], SearchSpaceModels] = OrderedDict()
        self._fitting: dict[tuple[int, int], Future[SearchSpaceModels]] = {}
        self._lock = threading.Lock()

    def models(self, factory: sessionmaker[Session], job_id: int) -> tuple[SearchSpaceModels, int]:
        """The models of a job's stored evaluations, and how many evaluations they were fitted to."""
        with storage.snapshot(factory) as session:
            storage.get_job(session, job_id=job_id)  # NotFound -> 404
            n = storage.count_evaluations(session, job_id=job_id)
        key = (job_id, n)
        with self._lock:
            if key in self._models:
                self._models.move_to_end(key)
                return self._models[key], n
            pending = self._fitting.get(key)
            owner = pending is None
            if owner:
                pending = self._fitting[key] = Future()
        if not owner:
            return pending.result(), n  # the fit another request started (its error too)
        try:
            models = self._fit(factory, job_id, n)  # outside the lock: another job's tab need not wait
        except BaseException as exc:
            with self._lock:
                del self._fitting[key]
            pending.set_exception(exc)
            raise
        with self._lock:
            del self._fitting[key]
            self._models[key] = models
            while len(self._models) > self.size:
                self._models.popitem(last=False)
        pending.set_result(models)
        return models, n

    @staticmethod
    def _fit(factory: sessionmaker[Session], job_id: int, n: int) -> SearchSpaceModels:
        with storage.snapshot(factory) as session:
            job = storage.get_job(session, job_id=job_id)
            rows = storage.evaluations(session, job_id=job_id, limit=n)  # those counted: the key's
            bounds = job.spec.get("bounds") or {}
            history = ([dict(e.theta) for e in rows], [float(e.J) for e in rows], [bool(e.completed) for e in rows])
        from driftlab.core.search_space import fit_models  # scikit-learn (1.4 s) on first use, not at start

        return fit_models(bounds, *history)


def _grid(values: np.ndarray | None) -> list[list[float]] | None:
    return None if values is None else [[float(v) for v in row] for row in values]


def search_space(cache: SearchSpaceCache, factory: sessionmaker[Session], *, job_id: int, x: str | None = None,
                 y: str | None = None, grid: int = 30) -> dict[str, Any]:
    """The surface over (x, y) (default: the two most important parameters, or the first two) and the importance.

    Raises:
        storage.NotFound: no such job.
        ConfigError: x or y not a parameter of the job, or grid out of range (naming the field).
    """
    models, n = cache.models(factory, job_id)
    importance = models.importance()
    ranked = sorted(models.names, key=lambda k: -(importance or {}).get(k, 0.0)) if importance else list(models.names)
    x_key = x or next(k for k in ranked if k != y)
    y_key = y or next(k for k in ranked if k != x_key)
    from driftlab.core.search_space import surface

    s = surface(models, x_key, y_key, grid)
    return {
        "job_id": job_id, "n_evaluations": n, "parameters": list(models.names),
        "bounds": {k: [float(a), float(b)] for k, a, b in zip(models.names, models.lo, models.hi, strict=True)},
        "importance": importance, "length_scales": models.length_scales(),
        "importance_method": "ARD relevance 1/l^2 of the GP's length scales on the unit cube, normalized to sum 1",
        "best_theta": models.best_theta,
        "x": x_key, "y": y_key, "x_values": [float(v) for v in s.x_values], "y_values": [float(v) for v in s.y_values],
        "held": s.held, "mean_J": _grid(s.mean_J), "std_J": _grid(s.std_J), "p_failure": _grid(s.p_failure),
    }
