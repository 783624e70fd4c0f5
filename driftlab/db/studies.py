"""Studies in storage (keyword-only, no HTTP): create, read, and their lifecycle.

A seeds study is a set of ordinary jobs carrying its id; its status is theirs (see :func:`study_status`), and
pause, resume and delete apply to each of them through the jobs' own lifecycle.

A robustness study owns its cells and is run like a job: queued -> running (one runner holds a lease: runner id
and heartbeat, as jobs do, see driftlab.db.lifecycle) -> finished | paused | failed; paused | failed -> queued.
Each cell is stored as soon as its episodes are back.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import delete, or_, select, update
from sqlalchemy.orm import Session

from driftlab.core.statuses import StudyKind
from driftlab.db import lease, lifecycle, storage
from driftlab.db.lifecycle import TransitionError, WorkStatus
from driftlab.db.models import Job, Study, StudyCell, utcnow

PENDING = "pending"
NOT_DRIVABLE = "not_drivable"  # a cell whose plant has no drift at the scenario's radius: not run


def create_study(session: Session, *, name: str, kind: str, spec: dict[str, Any], status: str = WorkStatus.QUEUED
                 ) -> Study:
    study = Study(name=name, kind=kind, spec=spec, status=status)
    session.add(study)
    session.flush()
    return study


def add_cells(session: Session, *, study_id: int, cells: list[dict[str, Any]]) -> None:
    session.add_all(StudyCell(study_id=study_id, index=i, settings=s, status=PENDING) for i, s in enumerate(cells))
    session.flush()


def get_study(session: Session, *, study_id: int) -> Study:
    return storage.get_row(session, Study, study_id, "study with id")


def find_study(session: Session, *, name: str) -> Study | None:
    return storage.find_named(session, Study, name)


def get_study_by_name(session: Session, *, name: str) -> Study:
    return storage.find_named(session, Study, name, "study")


def unique_study_name(session: Session, base: str) -> str:
    return storage.unique_name(session, Study, base)


def list_studies(session: Session) -> list[Study]:
    return list(session.scalars(select(Study).order_by(Study.id)))


def study_jobs(session: Session, *, study_id: int) -> list[Job]:
    return list(session.scalars(select(Job).where(Job.study_id == study_id).order_by(Job.id)))


def cells(session: Session, *, study_id: int) -> list[StudyCell]:
    return list(session.scalars(select(StudyCell).where(StudyCell.study_id == study_id).order_by(StudyCell.index)))


def store_cell(session: Session, *, cell_id: int, status: str, J: float | None, n_completed: int,
               seeds: list[dict[str, Any]], wall_ms: float) -> StudyCell:
    cell = session.get_one(StudyCell, cell_id)
    cell.status, cell.J, cell.n_completed, cell.seeds, cell.wall_ms = status, J, n_completed, seeds, wall_ms
    cell.completed_at = utcnow()
    return cell


def study_status(session: Session, study: Study) -> str:
    """A robustness study's own status; a seeds study's from its jobs: running if any runs, else queued if
    any waits, else paused, failed, or finished when all are."""
    if study.kind != StudyKind.SEEDS:
        return study.status
    statuses = set(session.scalars(select(Job.status).where(Job.study_id == study.id).distinct()))
    for status in (WorkStatus.RUNNING, WorkStatus.QUEUED, WorkStatus.PAUSED, WorkStatus.FAILED):
        if status in statuses:
            return str(status)
    return str(WorkStatus.FINISHED)


# -- lifecycle ---------------------------------------------------------------------------------------------
def next_claimable_study(session: Session) -> int | None:
    """The oldest queued robustness study, or one whose runner died."""
    return lease.next_claimable(session, Study, also=Study.kind == StudyKind.ROBUSTNESS)


def claim_study(session: Session, *, study_id: int, runner: str) -> bool:
    """Take the study's lease (from queued, or from a dead runner); False if another runner was quicker."""
    return lease.claim(session, Study, row_id=study_id, runner=runner, also=Study.kind == StudyKind.ROBUSTNESS)


def heartbeat_study(session: Session, *, study_id: int, runner: str) -> bool:
    """Renew the lease; False when the runner no longer holds it (paused, deleted or taken over): stop."""
    return lease.renew(session, Study, row_id=study_id, runner=runner)


def release_study(session: Session, *, study_id: int, runner: str, status: str, error: str | None = None) -> None:
    """The runner stops: the study takes ``status`` unless a pause request changed it meanwhile."""
    lease.release(session, Study, row_id=study_id, runner=runner, status=status, error=error)


def hold_seeds_study(session: Session, *, study_id: int, runner: str) -> None:
    """``runner`` runs this seeds study's jobs one after another: no other runner claims them while it holds it
    (renewed with each job's heartbeat, see lifecycle.heartbeat; free again LEASE_TIMEOUT_S after the holder
    died). Taken in the transaction that creates the study, so no server can start a job first.

    Raises:
        LeaseHeld: another live runner holds the study.
    """
    now = utcnow()
    free = or_(Study.runner_id.is_(None), Study.runner_id == runner, lease.is_stale(Study, now))
    taken = lease.rows_updated(session, update(Study).where(Study.id == study_id, Study.kind == StudyKind.SEEDS, free)
                               .values(runner_id=runner, heartbeat_at=now.replace(tzinfo=None))
                               .execution_options(synchronize_session=False))
    if taken != 1:
        study = get_study(session, study_id=study_id)
        raise lifecycle.LeaseHeld(f"study {study.name!r} (id {study_id}) is being run by {study.runner_id}; "
                                  "pause it first, or wait for it to finish")


def let_go_seeds_study(session: Session, *, study_id: int, runner: str) -> None:
    session.execute(update(Study).where(Study.id == study_id, Study.runner_id == runner)
                    .values(runner_id=None, heartbeat_at=None).execution_options(synchronize_session=False))


def pause_study(session: Session, *, study_id: int) -> Study:
    """Pauses a robustness study, or each queued or running job of a seeds study (TransitionError if none)."""
    study = get_study(session, study_id=study_id)
    if study.kind == StudyKind.SEEDS:
        return _each_job(session, study, lease.ACTIVE, lifecycle.request_pause, "queued or running", "pause")
    return lease.pause(study, f"study {study_id}")


def resume_study(session: Session, *, study_id: int) -> Study:
    """Queues a paused or failed robustness study, or each paused or failed job of a seeds study."""
    study = get_study(session, study_id=study_id)
    if study.kind == StudyKind.SEEDS:
        return _each_job(session, study, (WorkStatus.PAUSED, WorkStatus.FAILED), lifecycle.requeue,
                         "paused or failed", "resume")
    return lease.requeue(study, f"study {study_id}")


def _each_job(session: Session, study: Study, statuses: tuple[WorkStatus, ...], transition: Any, which: str,
              verb: str) -> Study:
    """A seeds study's transition: each of its jobs in ``statuses`` takes it (TransitionError if none is)."""
    jobs = [j for j in study_jobs(session, study_id=study.id) if j.status in statuses]
    if not jobs:
        raise TransitionError(f"study {study.id} has no {which} job to {verb}")
    for job in jobs:
        transition(session, job_id=job.id)
    return study


def delete_study(session: Session, *, study_id: int) -> None:
    """The study with its cells or its jobs (and their evaluations); TransitionError while any of it runs."""
    study = get_study(session, study_id=study_id)
    jobs = study_jobs(session, study_id=study_id)
    if lease.is_live(study) or any(lifecycle.lease_is_live(j) for j in jobs):
        raise TransitionError(f"study {study_id} is running; pause it first")
    for job in jobs:
        lifecycle.delete_job(session, job_id=job.id, with_its_study=True)
    session.execute(delete(StudyCell).where(StudyCell.study_id == study_id))
    session.execute(delete(Study).where(Study.id == study_id))
