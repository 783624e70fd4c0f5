"""A job's lifecycle in one place: its statuses, the allowed transitions, and the lease that makes exactly one
runner (the server's worker or a `driftlab tune`) run a job at a time.

    queued --claim--> running --release--> finished | paused | failed | queued (server shutdown)
    running --request_pause--> paused (the runner sees it at its next heartbeat and stops)
    paused | failed --requeue--> queued;  finished --extend--> queued;  any but running --delete--> gone

The lease (``runner_id``, ``heartbeat_at``) is driftlab.db.lease's, the same for jobs and robustness studies.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import delete, or_, select, update
from sqlalchemy.orm import Session
from sqlalchemy.orm.util import identity_key

from driftlab.core.statuses import StudyKind
from driftlab.db import lease
from driftlab.db.lease import HEARTBEAT_S, LEASE_TIMEOUT_S, TransitionError, new_runner_id
from driftlab.db.models import EnqueuedTheta, Evaluation, Job, Rescore, Study, Trajectory, WorkStatus, utcnow
from driftlab.db.storage import count_evaluations, get_job, job_for_store

__all__ = ["HEARTBEAT_S", "LEASE_TIMEOUT_S", "WorkStatus", "LeaseHeld", "TransitionError", "claim", "claimable",
           "delete_job", "extend", "heartbeat", "lease_is_live", "new_runner_id", "release", "request_pause",
           "requeue"]


class LeaseHeld(TransitionError):
    """Another live runner holds the job."""


def _study_held_by_another(now: datetime, runner: str | None):
    """SQL: the job belongs to a seeds study that another live runner holds (``driftlab study seeds`` runs its
    jobs one after another and holds the study from the moment it creates it, so no other runner starts one).
    False, not NULL, for a job of no study (NOT NULL would be NULL and filter the job out)."""
    holders = select(Study.id).where(Study.kind == StudyKind.SEEDS, Study.runner_id.is_not(None),
                                     Study.heartbeat_at >= lease.stale_before(now))
    if runner is not None:
        holders = holders.where(Study.runner_id != runner)
    return Job.study_id.is_not(None) & Job.study_id.in_(holders)


def lease_is_live(job: Job, now: datetime | None = None) -> bool:
    return lease.is_live(job, now)


def claim(session: Session, *, job_id: int, runner: str, from_statuses: tuple[WorkStatus, ...] = (WorkStatus.QUEUED,)
          ) -> None:
    """Take the job for ``runner``: from one of ``from_statuses``, or from a dead runner's stale lease. One UPDATE
    when it is free (the job's row is read only to say why it is not: a runner claims every job it runs).

    Raises:
        NotFound: no such job.
        LeaseHeld: another runner's lease is live.
        TransitionError: the job's status allows no claim.
    """
    now = utcnow()
    # started_at: this run's start, so the ETA counts only the time since (pauses excluded)
    if lease.take(session, Job, row_id=job_id, runner=runner, from_statuses=from_statuses, now=now,
                  also=~_study_held_by_another(now, runner), started_at=now, stop_reason=None):
        _reload_if_loaded(session, job_id)
        return
    job = get_job(session, job_id=job_id)
    session.refresh(job)
    if lease_is_live(job, now):
        age = (lease.naive(now) - lease.naive(job.heartbeat_at or now)).total_seconds()
        raise LeaseHeld(f"job {job.name!r} is being run by {job.runner_id} (last heartbeat {age:.1f} s ago); "
                        "pause it first, or wait for it to finish")
    if job.study_id is not None:
        study = session.get(Study, job.study_id)
        if study is not None and session.scalar(select(Job.id).where(Job.id == job_id,
                                                                     _study_held_by_another(now, runner))):
            raise LeaseHeld(f"job {job.name!r} belongs to study {study.name!r} (id {study.id}), which "
                            f"{study.runner_id} is running; pause the study first, or wait for it to finish")
    raise TransitionError(f"job {job.name!r} is {job.status}; it can be run from {', '.join(from_statuses)}")


def heartbeat(session: Session, *, job_id: int, runner: str) -> bool:
    """Renew the lease (and the runner's hold on the job's seeds study, if it holds it); False when the runner
    no longer holds the job (paused, deleted or taken over): stop."""
    now = lease.naive(utcnow())
    held = lease.renew(session, Job, row_id=job_id, runner=runner, now=now)
    study_of_job = select(Job.study_id).where(Job.id == job_id).scalar_subquery()
    session.execute(update(Study)
                    .where(Study.id == study_of_job, Study.kind == StudyKind.SEEDS, Study.runner_id == runner)
                    .values(heartbeat_at=now).execution_options(synchronize_session=False))
    return held


def release(session: Session, *, job_id: int, runner: str, status: WorkStatus, error: str | None = None,
            stop_reason: str | None = None) -> None:
    """The runner stops: the job takes ``status`` unless someone changed it meanwhile (driftlab.db.lease), adds this
    run's wall time to the time it has run in all (``run_s``, what a time budget counts), and keeps the stop rule
    that finished it, if one did. A job the runner would finish goes back to the queue instead when its budget
    was raised after the runner last read it (a PATCH between the runner's last look and this transaction)."""
    session.flush()  # a change the caller made in this session (a new budget) is what the read below sees
    job = job_for_store(session, job_id=job_id)  # not the row's documents: no ORM load
    ran: dict[str, Any] = {}
    if job is not None and job.runner_id == runner and job.started_at is not None:
        ran_s = (lease.naive(utcnow()) - lease.naive(job.started_at)).total_seconds()
        ran = {"run_s": (job.run_s or 0.0) + max(ran_s, 0.0), "stop_reason": stop_reason}
        if status == WorkStatus.FINISHED and stop_reason is None and job.iterations > job.n_evaluations:
            status = WorkStatus.QUEUED
    lease.release(session, Job, row_id=job_id, runner=runner, status=status, error=error, **ran)
    _reload_if_loaded(session, job_id)


def _reload_if_loaded(session: Session, job_id: int) -> None:
    """The caller's loaded copy of the job, if it has one, reads what the UPDATEs wrote when next used."""
    loaded = session.identity_map.get(identity_key(Job, job_id))
    if loaded is not None:
        session.expire(loaded)


def request_pause(session: Session, *, job_id: int) -> Job:
    return lease.pause(get_job(session, job_id=job_id), f"job {job_id}")


def requeue(session: Session, *, job_id: int) -> Job:
    return lease.requeue(get_job(session, job_id=job_id), f"job {job_id}")


def extend(session: Session, *, job_id: int, iterations: int) -> Job:
    """A new budget. Raising a finished job's budget queues it again; a running job takes it on the fly."""
    job = get_job(session, job_id=job_id)
    done = count_evaluations(session, job_id=job_id)
    if iterations < done:
        raise TransitionError(f"iterations must be at least the {done} evaluations already stored, got {iterations}")
    job.spec = {**job.spec, "iterations": iterations}
    if job.status == WorkStatus.FINISHED and iterations > done:
        job.status = WorkStatus.QUEUED
    elif job.status in (WorkStatus.QUEUED, WorkStatus.PAUSED) and iterations == done:
        job.status = WorkStatus.FINISHED
    return job


def delete_job(session: Session, *, job_id: int, with_its_study: bool = False) -> None:
    """The job, its evaluations and trajectories. A seeds study's job goes only with its study
    (``with_its_study``): deleting one alone would silently change the study's band and spread."""
    job = get_job(session, job_id=job_id)
    if job.study_id is not None and not with_its_study:
        study = session.get(Study, job.study_id)
        name = f"{study.name!r} (id {study.id})" if study is not None else f"id {job.study_id}"
        raise TransitionError(f"job {job_id} belongs to seeds study {name}; delete the study "
                              f"(DELETE /api/studies/{job.study_id}) to delete its jobs")
    if lease_is_live(job):
        raise TransitionError(f"job {job_id} is running; pause it first")
    ids = select(Evaluation.id).where(Evaluation.job_id == job_id)
    session.execute(delete(Trajectory).where(Trajectory.evaluation_id.in_(ids)))
    session.execute(delete(Rescore).where(Rescore.job_id == job_id))
    session.execute(delete(EnqueuedTheta).where(EnqueuedTheta.job_id == job_id))
    session.execute(delete(Evaluation).where(Evaluation.job_id == job_id))
    session.execute(delete(Job).where(Job.id == job_id))


def claimable(session: Session, *, limit: int) -> list[int]:
    """The ``limit`` oldest jobs that are queued, or whose runner died (not of a seeds study another runner holds):
    a runner claims what it has room for in one look."""
    now = utcnow()
    stale = (Job.status == WorkStatus.RUNNING) & lease.is_stale(Job, now)
    query = (select(Job.id).where(or_(Job.status == WorkStatus.QUEUED, stale), ~_study_held_by_another(now, None))
             .order_by(Job.id).limit(limit))
    return list(session.scalars(query))

