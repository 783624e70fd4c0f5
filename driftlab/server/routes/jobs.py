"""Jobs: create, list, read, pause, resume, extend, delete; their evaluations and best."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response
from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.tuning import TuningSpec
from driftlab.db import lifecycle, storage
from driftlab.server import quotas
from driftlab.server.evaluation_pages import EvaluationPages
from driftlab.server.responses import Enqueued, Evaluation, Job, errors, media
from driftlab.server.routes.deps import evaluation_pages, factory, require_token, wake_runner
from driftlab.server.schemas import (
    JOBS_PAGE,
    After,
    EnqueueRequest,
    JobCreate,
    JobId,
    JobPatch,
    JobsAfter,
    JobsLimit,
    Limit,
    WaitingAfter,
    WaitingLimit,
    check_document_types,
)
from driftlab.server.serialize import evaluation_dict, evaluations_csv, job_dict
from driftlab.services.enqueue import WAITING_PAGE, enqueue_thetas, waiting_document
from driftlab.services.profiles import gives_weights, uncalibrated_warning, with_profile
from driftlab.services.warm_start import with_warm_start

router = APIRouter(prefix="/api/jobs", tags=["jobs"])
Factory = Annotated[sessionmaker[Session], Depends(factory)]
Pages = Annotated[EvaluationPages, Depends(evaluation_pages)]
Mutating = [Depends(require_token)]


@router.post("", status_code=201, dependencies=Mutating, response_model=Job, responses=errors(409, 422, 503))
def create_job(body: JobCreate, db: Factory, request: Request) -> dict[str, Any]:
    doc = body.model_dump(exclude_none=True, exclude={"name", "warm_start_from"})
    check_document_types(doc)
    if "bounds" in doc:
        doc["bounds"] = {k: list(v) for k, v in doc["bounds"].items()}
    spec = TuningSpec.from_dict(doc)  # ConfigError -> 422 naming the field
    deferred = request.app.state.drift_check.check(spec.config)  # NotDrivableError (a ConfigError) -> 422
    settings = request.app.state.settings
    quotas.check_job(settings, spec.to_dict())
    with storage.transaction(db) as session:
        if body.name and storage.find_job(session, name=body.name) is not None:
            raise HTTPException(409, f"name: a job named {body.name!r} exists")
        quotas.check_queue(settings, session, 1)
        name = body.name or storage.unique_job_name(session, "job")
        spec, profile_id = with_profile(session, spec, doc.get("config"))
        warning = None if profile_id is not None or gives_weights(doc.get("config")) else uncalibrated_warning(
            session, spec)
        warning = "; ".join(w for w in (deferred, warning) if w) or None
        if body.warm_start_from:
            spec = with_warm_start(session, spec, body.warm_start_from)
        out = job_dict(session, storage.create_job(session, name=name, spec=spec.to_dict(), seed=spec.seed,
                                                   profile_id=profile_id))
    wake_runner(request)
    return {**out, "warning": warning}


@router.get("", response_model=list[Job], responses=errors(422, 503))
def list_jobs(db: Factory, response: Response, after: JobsAfter = 0, limit: JobsLimit = JOBS_PAGE
              ) -> list[dict[str, Any]]:
    """Jobs in id order, a page at a time: when more follow, a ``Link: <...?after=ID&limit=N>; rel="next"`` header
    names the next page."""
    with storage.snapshot(db) as session:
        jobs = storage.list_jobs(session, after=after, limit=limit + 1)  # one more: whether a next page exists
        page = [job_dict(session, j) for j in jobs[:limit]]
    if len(jobs) > limit:
        response.headers["Link"] = f'</api/jobs?after={page[-1]["id"]}&limit={limit}>; rel="next"'
    return page


@router.get("/{job_id}", response_model=Job, responses=errors(404, 422, 503))
def get_job(job_id: JobId, db: Factory) -> dict[str, Any]:
    with storage.snapshot(db) as session:
        return job_dict(session, storage.get_job(session, job_id=job_id))


@router.post("/{job_id}/pause", dependencies=Mutating, response_model=Job, responses=errors(404, 409, 422, 503))
def pause(job_id: JobId, db: Factory) -> dict[str, Any]:
    """409 unless queued or running; a running job stops after the evaluations in flight."""
    with storage.transaction(db) as session:
        return job_dict(session, lifecycle.request_pause(session, job_id=job_id))


@router.post("/{job_id}/enqueue", status_code=202, dependencies=Mutating, response_model=Enqueued,
             responses=errors(404, 409, 422, 503))
def enqueue(job_id: JobId, body: EnqueueRequest, db: Factory, request: Request) -> dict[str, Any]:
    """Hand-picked thetas, evaluated next in the order given (before the optimizer's next proposal) and told to its
    optimizer like any other; their evaluations carry ``enqueued: true``. 409 for a finished job (raise its budget
    first); a paused or queued job evaluates them when it runs."""
    with storage.transaction(db) as session:
        added = enqueue_thetas(session, job_id=job_id, thetas=body.thetas)
        out = waiting_document(session, job_id=job_id, added=added)
    wake_runner(request)
    return out


@router.get("/{job_id}/enqueue", response_model=Enqueued, responses=errors(404, 422, 503))
def enqueued_thetas(job_id: JobId, db: Factory, after: WaitingAfter = 0, limit: WaitingLimit = WAITING_PAGE
                    ) -> dict[str, Any]:
    """The thetas enqueued for the job and not yet stored as its evaluations, next first: at most ``limit`` with an
    id above ``after`` (the last id of the page before), and how many wait in all."""
    with storage.snapshot(db) as session:
        storage.get_job(session, job_id=job_id)
        return waiting_document(session, job_id=job_id, after=after, limit=limit)


@router.post("/{job_id}/resume", dependencies=Mutating, response_model=Job, responses=errors(404, 409, 422, 503))
def resume(job_id: JobId, db: Factory, request: Request) -> dict[str, Any]:
    """409 unless paused or failed."""
    with storage.transaction(db) as session:
        out = job_dict(session, lifecycle.requeue(session, job_id=job_id))
    wake_runner(request)
    return out


@router.patch("/{job_id}", dependencies=Mutating, response_model=Job, responses=errors(404, 422, 503))
def extend(job_id: JobId, body: JobPatch, db: Factory, request: Request) -> dict[str, Any]:
    """A new budget (>= the evaluations stored; a finished job with more iterations continues), new notes, or both."""
    try:
        with storage.transaction(db) as session:
            job = storage.get_job(session, job_id=job_id)
            if body.iterations is not None:
                quotas.check_job(request.app.state.settings, {**job.spec, "iterations": body.iterations})
                lifecycle.extend(session, job_id=job_id, iterations=body.iterations)
            if body.notes is not None:
                storage.set_notes(session, job_id=job_id, notes=body.notes)
            out = job_dict(session, job)
    except lifecycle.TransitionError as exc:
        raise HTTPException(422, f"iterations: {exc}") from None
    if body.iterations is not None:
        wake_runner(request)
    return out


@router.delete("/{job_id}", status_code=204, dependencies=Mutating, responses=errors(404, 409, 422, 503))
def delete(job_id: JobId, db: Factory) -> Response:
    """The job, its evaluations and trajectories; 409 while a runner holds it (pause it first)."""
    with storage.transaction(db) as session:
        lifecycle.delete_job(session, job_id=job_id)
    return Response(status_code=204)


@router.get("/{job_id}/evaluations", response_model=list[Evaluation], responses={
    **media("text/csv", {"type": "string"}, "format=csv: one row per evaluation"), **errors(404, 422, 503)})
def list_evaluations(job_id: JobId, db: Factory, pages: Pages, after: After = -1, limit: Limit = 1000,
                     format: str = Query("json", pattern="^(csv|json)$")) -> Response:  # noqa: A002
    """Evaluations with index > after, in order, at most ``limit`` (page with the last index you have).
    ``format=csv``: one row per evaluation, theta at full precision (what you copy reproduces)."""
    with storage.snapshot(db) as session:
        if format == "json":  # each evaluation's JSON made once (driftlab.server.evaluation_pages)
            return Response(pages.page(session, job_id=job_id, after=after, limit=limit),
                            media_type="application/json")
        storage.get_job(session, job_id=job_id)
        rows = [evaluation_dict(e) for e in storage.evaluations(session, job_id=job_id, after=after, limit=limit)]
    return Response(evaluations_csv(rows), media_type="text/csv", headers={
        "Content-Disposition": f'attachment; filename="job-{job_id}-evaluations.csv"'})


@router.get("/{job_id}/best", response_model=Evaluation, responses=errors(404, 422, 503))
def best(job_id: JobId, db: Factory) -> dict[str, Any]:
    with storage.snapshot(db) as session:
        storage.get_job(session, job_id=job_id)
        e = storage.best_evaluation(session, job_id=job_id)
        if e is None:
            raise HTTPException(404, f"job {job_id} has no evaluations yet")
        return evaluation_dict(e)
