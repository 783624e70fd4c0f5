"""Enqueueing hand-picked thetas for a job (driftlab.db.enqueued): the one place the REST API, `driftlab tune
--enqueue` and the 3D view's what-if panel go through."""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import Session

from driftlab.core.tuning import TuningSpec
from driftlab.db import enqueued, lifecycle, storage
from driftlab.db.models import EnqueuedTheta


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
    waiting = len(enqueued.waiting(session, job_id=job_id))
    if waiting + len(picked) > left:
        raise lifecycle.TransitionError(
            f"{field}: job {job_id} has {left} evaluations left and {waiting} thetas waiting: at most "
            f"{max(left - waiting, 0)} more (raise its budget first: PATCH /api/jobs/{job_id} with iterations, or "
            "driftlab tune --iterations N)")
    return enqueued.enqueue(session, job_id=job_id, thetas=picked)


def waiting_document(session: Session, *, job_id: int, added: list[EnqueuedTheta] = ()) -> dict[str, Any]:
    """What the API answers: the ids just enqueued and every theta still waiting, next first."""
    return {"job_id": job_id, "enqueued": [row.id for row in added],
            "waiting": [{"id": row.id, "theta": row.theta} for row in enqueued.waiting(session, job_id=job_id)]}
