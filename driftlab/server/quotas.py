"""How much work one request may queue (DRIFTLAB_MAX_EPISODES_PER_JOB, DRIFTLAB_MAX_EPISODES_PER_STUDY,
DRIFTLAB_MAX_QUEUED_JOBS): a job's episodes are at most iterations x (robust_samples + confirm_samples); a seeds
study's, its jobs'; a robustness study's, cells x robust_samples. Each refusal is a 422 naming the field and the
limit, and stores nothing (it is raised inside the request's transaction)."""

from __future__ import annotations

from fastapi import HTTPException
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from driftlab.core.statuses import StudyKind
from driftlab.db.models import Job, Study, WorkStatus
from driftlab.settings import Settings


def job_episodes(spec: dict) -> int:
    return int(spec["iterations"]) * (int(spec.get("robust_samples", 1)) + int(spec.get("confirm_samples", 0)))


def check_job(settings: Settings, spec: dict) -> None:
    episodes = job_episodes(spec)
    if episodes > settings.max_episodes_per_job:
        raise HTTPException(422, f"iterations: {spec['iterations']} iterations x up to "
                                 f"{episodes // int(spec['iterations'])} episodes = {episodes} episodes exceed the "
                                 f"limit of {settings.max_episodes_per_job} a job (DRIFTLAB_MAX_EPISODES_PER_JOB)")


def check_rescore(settings: Settings, samples: int) -> None:
    """A rescore's episodes count against the same limit as a job's."""
    if samples > settings.max_episodes_per_job:
        raise HTTPException(422, f"samples: {samples} episodes exceed the limit of {settings.max_episodes_per_job} "
                                 "a job (DRIFTLAB_MAX_EPISODES_PER_JOB)")


def check_queue(settings: Settings, session: Session, adding: int) -> None:
    queued = session.scalar(select(func.count()).select_from(Job).where(Job.status == WorkStatus.QUEUED)) or 0
    if queued + adding > settings.max_queued_jobs:
        raise HTTPException(422, f"jobs: {queued} jobs are queued and this adds {adding}; the limit is "
                                 f"{settings.max_queued_jobs} (DRIFTLAB_MAX_QUEUED_JOBS): wait, or delete some")


def check_study(settings: Settings, session: Session, study: Study) -> None:
    if study.kind == StudyKind.SEEDS:
        jobs = list(session.scalars(select(Job).where(Job.study_id == study.id)))
        for job in jobs:
            check_job(settings, job.spec)
        episodes = sum(job_episodes(job.spec) for job in jobs)
        check_queue(settings, session, 0)  # its jobs are queued already: the count includes them
        field = "seeds"
    else:
        episodes = len(study.cells) * int(study.spec.get("robust_samples", 1))
        field = "grid"
    if episodes > settings.max_episodes_per_study:
        raise HTTPException(422, f"{field}: this study runs up to {episodes} episodes, over the limit of "
                                 f"{settings.max_episodes_per_study} a study (DRIFTLAB_MAX_EPISODES_PER_STUDY)")


# The most points a calibration's default tiling gives (driftlab.core.calibration.default_points: every 0.05 rad of
# the 0.2-0.8 rad scan on the scenario's circle, and one point on each of two other circles), and the candidate
# models a point may search (two rear models x two steering limits, driftlab.core.calibration_run).
DEFAULT_POINTS_AT_MOST = 15
CANDIDATES_AT_MOST = 4


def calibration_episodes(*, points: int | None, iterations: int, seeds: int, rounds: int) -> int:
    """The most episodes a calibration may run: each point's rounds, each round searching every candidate model's
    weights (and, after the first, a theta: fewer episodes than a candidate's search)."""
    return (points or DEFAULT_POINTS_AT_MOST) * rounds * iterations * seeds * CANDIDATES_AT_MOST


def check_calibration(settings: Settings, *, points: int | None, iterations: int, seeds: int, rounds: int) -> None:
    """A calibration counts against the limit of a study: it is many searches of a job's size."""
    episodes = calibration_episodes(points=points, iterations=iterations, seeds=seeds, rounds=rounds)
    if episodes > settings.max_episodes_per_study:
        shown = f"{points} points" if points else f"up to {DEFAULT_POINTS_AT_MOST} points (the default tiling)"
        raise HTTPException(422, f"iterations: {shown} x {rounds} rounds x {iterations} iterations x {seeds} seeds x "
                                 f"up to {CANDIDATES_AT_MOST} candidate models = {episodes} episodes exceed the limit "
                                 f"of {settings.max_episodes_per_study} (DRIFTLAB_MAX_EPISODES_PER_STUDY)")

