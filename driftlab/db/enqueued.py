"""Thetas enqueued for a job (driftlab.db.models.EnqueuedTheta): added by the API or the CLI, taken by the job's
runner before the optimizer's next proposal, removed when their evaluation is stored."""

from __future__ import annotations

from collections.abc import Collection

from sqlalchemy import delete, exists, func, select
from sqlalchemy.orm import Session

from driftlab.db.models import EnqueuedTheta


def enqueue(session: Session, *, job_id: int, thetas: list[dict[str, float]]) -> list[EnqueuedTheta]:
    rows = [EnqueuedTheta(job_id=job_id, theta=dict(theta)) for theta in thetas]
    session.add_all(rows)
    session.flush()
    return rows


def waiting(session: Session, *, job_id: int, taken: Collection[int] = (), after: int = 0,
            limit: int | None = None) -> list[EnqueuedTheta]:
    """The job's enqueued thetas not yet stored as evaluations, oldest first, except the ids ``taken`` (in flight):
    those with an id above ``after``, at most ``limit`` of them (the index on job_id and the id's order: the next
    one is read without the rest)."""
    query = (select(EnqueuedTheta).where(EnqueuedTheta.job_id == job_id, EnqueuedTheta.id > after)
             .order_by(EnqueuedTheta.id).limit(limit))
    if taken:
        query = query.where(EnqueuedTheta.id.not_in(list(taken)))
    return list(session.scalars(query))


def count_waiting(session: Session, *, job_id: int) -> int:
    return session.scalar(select(func.count()).where(EnqueuedTheta.job_id == job_id)) or 0


def any_waiting(session: Session, *, job_id: int) -> bool:
    return bool(session.scalar(select(exists().where(EnqueuedTheta.job_id == job_id))))


def remove(session: Session, *, row_id: int) -> None:
    session.execute(delete(EnqueuedTheta).where(EnqueuedTheta.id == row_id))


def remove_for_job(session: Session, *, job_id: int) -> None:
    session.execute(delete(EnqueuedTheta).where(EnqueuedTheta.job_id == job_id))
