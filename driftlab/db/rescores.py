"""Stored rescores (driftlab.db.models.Rescore): queued by a request, claimed by a runner under the same lease as a
job (driftlab.db.lease), each seed's sample added as it comes back, cancelled by a request."""

from __future__ import annotations

from typing import Any

from sqlalchemy import func, select, update
from sqlalchemy.orm import Session

from driftlab.db import lease
from driftlab.db.models import Rescore, WorkStatus
from driftlab.db.storage import NotFound

ACTIVE = (WorkStatus.QUEUED, WorkStatus.RUNNING)


class RescoreBusy(Exception):
    """A rescore of this job is queued or running already."""


def latest(session: Session, *, job_id: int) -> Rescore | None:
    return session.scalar(select(Rescore).where(Rescore.job_id == job_id).order_by(Rescore.id.desc()).limit(1))


def queue(session: Session, *, job_id: int, evaluation_id: int, theta: dict[str, float], config: dict[str, Any],
          seeds: list[int]) -> Rescore:
    """A new queued rescore of the job (raises RescoreBusy while its last one is queued or running)."""
    last = latest(session, job_id=job_id)
    if last is not None and last.status in ACTIVE:
        raise RescoreBusy(f"job {job_id}: a rescore is {last.status} ({len(last.samples)} / {len(last.seeds)} "
                          f"episodes); cancel it with DELETE /api/jobs/{job_id}/rescore")
    rescore = Rescore(job_id=job_id, evaluation_id=evaluation_id, theta=theta, config=config, seeds=list(seeds),
                      samples=[], status=WorkStatus.QUEUED)
    session.add(rescore)
    session.flush()
    return rescore


def episodes_outstanding(session: Session) -> int:
    """Episodes of every queued or running rescore not back yet (what the global budget counts)."""
    rows = session.execute(select(Rescore.seeds, Rescore.samples).where(Rescore.status.in_(ACTIVE))).all()
    return sum(len(seeds) - len(samples or []) for seeds, samples in rows)


def cancel(session: Session, *, job_id: int) -> Rescore:
    """The job's queued or running rescore stops (its runner sees it at its next heartbeat); raises NotFound."""
    last = latest(session, job_id=job_id)
    if last is None or last.status not in ACTIVE:
        raise NotFound(f"job {job_id} has no queued or running rescore")
    return lease.cancel(last)


def add_sample(session: Session, *, rescore_id: int, runner: str, sample: dict[str, Any]) -> bool:
    """Store one seed's result if ``runner`` still holds the rescore (False: cancelled or taken over; stop)."""
    rescore = session.get(Rescore, rescore_id)
    if rescore is None or rescore.runner_id != runner or rescore.status != WorkStatus.RUNNING:
        return False
    if all(s["seed"] != sample["seed"] for s in rescore.samples):
        rescore.samples = [*rescore.samples, sample]  # a new list: JSON columns track assignment, not mutation
    return True


def finish(session: Session, *, rescore_id: int, runner: str, status: WorkStatus,
           result: dict[str, Any] | None = None, error: str | None = None) -> None:
    session.execute(update(Rescore).where(Rescore.id == rescore_id, Rescore.runner_id == runner,
                                          Rescore.status == WorkStatus.RUNNING)
                    .values(result=result).execution_options(synchronize_session=False))
    lease.release(session, Rescore, row_id=rescore_id, runner=runner, status=status, error=error)


def count_active(session: Session) -> int:
    return session.scalar(select(func.count()).select_from(Rescore).where(Rescore.status.in_(ACTIVE))) or 0
