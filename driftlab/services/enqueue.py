"""Enqueueing hand-picked thetas for a job (driftlab.db.enqueued): the one place the REST API, `driftlab tune
--enqueue` and the 3D view's what-if panel go through."""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import Session

from driftlab.core.tuning import TuningSpec
from driftlab.db import enqueued, lifecycle, storage
from driftlab.db.models import EnqueuedTheta

# Thetas a job may have waiting at once, whatever its budget: a queue nobody reads to its end is a mistake, and each
# waiting row is read by the dashboard and the API. Ten requests of the most one may enqueue (schemas.MAX_ENQUEUED).
MAX_WAITING = 1000
WAITING_PAGE = 100  # waiting thetas a response lists (GET .../enqueue?after=ID pages through the rest)


def enqueue_thetas(session: Session, *, job_id: int, thetas: list[Any], field: str = "thetas"
                   ) -> list[EnqueuedTheta]:
    """The thetas, validated against the job's box (``TuningSpec.picked_theta``), enqueued in order.

    Raises:
        NotFound: no such job. TransitionError: it is finished (raise its budget first). ConfigError: a theta's key
        or value, named as ``<field>.<n>.<key>``.
    """
    job = storage.get_job(session, job_id=job_id)
    if job.status == lifecycle.WorkStatus.FINISHED:
        raise lifecycle.TransitionError(f"job {job_id} is finished; raise its budget first (PATCH /api/jobs/{job_id} "
                                        "with iterations, or driftlab tune --iterations N)")
    spec = TuningSpec.from_dict(job.spec)
    picked = [spec.picked_theta(theta, f"{field}.{n}") for n, theta in enumerate(thetas)]
    # The queue is bounded by what the job will evaluate: a theta beyond its budget would wait for ever.
    left = spec.iterations - storage.count_evaluations(session, job_id=job_id)
    waiting = enqueued.count_waiting(session, job_id=job_id)
    if waiting + len(picked) > MAX_WAITING:
        raise lifecycle.TransitionError(
            f"{field}: job {job_id} has {waiting} thetas waiting, and a job holds at most {MAX_WAITING} waiting: at "
            f"most {MAX_WAITING - waiting} more until some are evaluated")
    if waiting + len(picked) > left:
        raise lifecycle.TransitionError(
            f"{field}: job {job_id} has {left} evaluations left and {waiting} thetas waiting: at most "
            f"{max(left - waiting, 0)} more (raise its budget first: PATCH /api/jobs/{job_id} with iterations, or "
            "driftlab tune --iterations N)")
    return enqueued.enqueue(session, job_id=job_id, thetas=picked)


def waiting_document(session: Session, *, job_id: int, added: list[EnqueuedTheta] = (), after: int = 0,
                     limit: int = WAITING_PAGE) -> dict[str, Any]:
    """What the API answers: the ids just enqueued, how many thetas wait in all (``n_waiting``), and a page of them,
    next first: at most ``limit`` with an id above ``after``."""
    page = enqueued.waiting(session, job_id=job_id, after=after, limit=limit)
    return {"job_id": job_id, "enqueued": [row.id for row in added],
            "n_waiting": enqueued.count_waiting(session, job_id=job_id),
            "waiting": [{"id": row.id, "theta": row.theta} for row in page]}
