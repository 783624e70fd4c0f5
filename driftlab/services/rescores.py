"""A job's rescore as the API and the dashboard see it (POST/GET/DELETE /api/jobs/{id}/rescore): queued in the
database for the runner (driftlab.worker.rescoring), counted against a global episode budget, read back as one
document."""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.robust import rescore_seeds
from driftlab.core.tuning import TuningSpec
from driftlab.db import rescores, storage
from driftlab.db.models import Evaluation, Rescore
from driftlab.db.rescores import RescoreBusy

__all__ = ["RescoreBusy", "RescoreBudget", "cancel", "document", "queue", "status"]


class RescoreBudget(Exception):
    """Rescores waiting or running would hold more episodes than the service allows."""


def document(session: Session, rescore: Rescore | None, job_id: int) -> dict[str, Any]:
    """queued, running (``done`` of ``samples``), finished (``result``), failed (``error``), cancelled, or none."""
    if rescore is None:
        return {"job_id": job_id, "status": "none"}
    stored = session.get(Evaluation, rescore.evaluation_id)
    return {"job_id": job_id, "id": rescore.id, "status": rescore.status, "samples": len(rescore.seeds),
            "done": len(rescore.samples), "theta": rescore.theta, "evaluation_id": rescore.evaluation_id,
            "J_stored": None if stored is None else stored.J,
            "status_stored": None if stored is None else stored.status,
            "result": rescore.result, "error": rescore.error}


def queue(factory: sessionmaker[Session], job_id: int, samples: int, max_outstanding: int) -> dict[str, Any]:
    """Queue the job's best theta on ``samples`` fresh seeds.

    Raises:
        storage.NotFound: no such job, or no evaluation to rescore yet.
        RescoreBusy: the job's last rescore is queued or running.
        RescoreBudget: the episodes of every waiting rescore would pass ``max_outstanding``.
    """
    with storage.transaction(factory) as session:
        job = storage.get_job(session, job_id=job_id)
        best = storage.best_evaluation(session, job_id=job_id)
        if best is None:
            raise storage.NotFound(f"job {job_id} has no evaluation to rescore yet")
        outstanding = rescores.episodes_outstanding(session)
        if outstanding + samples > max_outstanding:
            raise RescoreBudget(f"samples: rescores already wait for {outstanding} episodes and this adds {samples}; "
                                f"the limit is {max_outstanding} (DRIFTLAB_MAX_RESCORE_EPISODES): wait, or cancel one")
        config = TuningSpec.from_dict(job.spec).to_dict()["config"]
        rescore = rescores.queue(session, job_id=job_id, evaluation_id=best.id, theta=dict(best.theta), config=config,
                                 seeds=rescore_seeds(samples))
        return document(session, rescore, job_id)


def status(factory: sessionmaker[Session], job_id: int) -> dict[str, Any]:
    with storage.snapshot(factory) as session:
        storage.get_job(session, job_id=job_id)
        return document(session, rescores.latest(session, job_id=job_id), job_id)


def cancel(factory: sessionmaker[Session], job_id: int) -> dict[str, Any]:
    with storage.transaction(factory) as session:
        storage.get_job(session, job_id=job_id)
        return document(session, rescores.cancel(session, job_id=job_id), job_id)
