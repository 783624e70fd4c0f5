"""Studies: create, list, read, pause, resume, delete; and the comparison of jobs side by side."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response
from sqlalchemy.orm import Session, sessionmaker

from driftlab.db import storage, studies
from driftlab.server import quotas
from driftlab.server.responses import ComparedJob, Study, StudyListItem, errors
from driftlab.server.routes.deps import factory, require_token, wake_runner
from driftlab.server.schemas import StudyCreate, StudyId, check_document_types
from driftlab.services import studies as study_views
from driftlab.services.job_documents import spec_diff

router = APIRouter(tags=["studies"])
Factory = Annotated[sessionmaker[Session], Depends(factory)]
Mutating = [Depends(require_token)]


@router.post("/api/studies", status_code=201, dependencies=Mutating, response_model=Study,
             responses=errors(404, 409, 422, 503))
def create_study(body: StudyCreate, db: Factory, request: Request) -> dict[str, Any]:
    """ConfigError -> 422 naming the field; an unknown evaluation_id -> 404; nothing is stored on error."""
    doc = body.model_dump(exclude_none=True, exclude={"name"})
    check_document_types(doc)
    with storage.transaction(db) as session:
        if body.name and studies.find_study(session, name=body.name) is not None:
            raise HTTPException(409, f"name: a study named {body.name!r} exists")
        study = study_views.start_study(session, doc=doc, name=body.name)
        session.flush()
        quotas.check_study(request.app.state.settings, session, study)  # raised here: nothing is stored
        out = study_views.study_summary(session, study)
    wake_runner(request)
    return out


@router.get("/api/studies", response_model=list[StudyListItem], responses=errors(503))
def list_studies(db: Factory) -> list[dict[str, Any]]:
    with storage.snapshot(db) as session:
        return [{"id": s.id, "name": s.name, "kind": s.kind, "status": studies.study_status(session, s)}
                for s in studies.list_studies(session)]


@router.get("/api/studies/{study_id}", response_model=Study, responses=errors(404, 422, 503))
def get_study(study_id: StudyId, db: Factory) -> dict[str, Any]:
    with storage.snapshot(db) as session:
        return study_views.study_summary(session, studies.get_study(session, study_id=study_id))


@router.post("/api/studies/{study_id}/pause", dependencies=Mutating, response_model=Study,
             responses=errors(404, 409, 422, 503))
def pause(study_id: StudyId, db: Factory) -> dict[str, Any]:
    """409 unless something of it is queued or running."""
    with storage.transaction(db) as session:
        return study_views.study_summary(session, studies.pause_study(session, study_id=study_id))


@router.post("/api/studies/{study_id}/resume", dependencies=Mutating, response_model=Study,
             responses=errors(404, 409, 422, 503))
def resume(study_id: StudyId, db: Factory, request: Request) -> dict[str, Any]:
    """409 unless something of it is paused or failed."""
    with storage.transaction(db) as session:
        out = study_views.study_summary(session, studies.resume_study(session, study_id=study_id))
    wake_runner(request)
    return out


@router.delete("/api/studies/{study_id}", status_code=204, dependencies=Mutating,
               responses=errors(404, 409, 422, 503))
def delete(study_id: StudyId, db: Factory) -> Response:
    """The study with its cells, or its jobs and their evaluations; 409 while any of it runs."""
    with storage.transaction(db) as session:
        studies.delete_study(session, study_id=study_id)
    return Response(status_code=204)


# 1 to MAX_COMPARED_JOBS ids >= 1, comma-separated (spaces allowed): in the schema, so that a client (and
# schemathesis) knows the form; at most 18 digits, so every id is one SQLite can hold.
_ID = " *0*[1-9][0-9]{0,17} *"
JOB_IDS = f"^{_ID}(,{_ID}){{0,{study_views.MAX_COMPARED_JOBS - 1}}}$"


@router.get("/api/compare", response_model=list[ComparedJob], responses=errors(404, 422, 503))
def compare(db: Factory, jobs: str = Query(..., max_length=400, pattern=JOB_IDS,
                                           description=f"job ids, e.g. 1,2,3 (1 to {study_views.MAX_COMPARED_JOBS})")
            ) -> list[dict[str, Any]]:
    """For each job, in the order given: its best (theta, J), n_done and convergence (J and best so far)."""
    ids = [int(part) for part in jobs.split(",")]  # the pattern holds: each part is an id
    with storage.snapshot(db) as session:
        return study_views.compare_jobs(session, job_ids=ids)


@router.get("/api/compare/config", responses=errors(404, 422, 503))
def compare_config(db: Factory, jobs: str = Query(..., max_length=400, pattern=JOB_IDS,
                                                  description="job ids, e.g. 1,2 (the first is the reference)")
                   ) -> dict[str, Any]:
    """The settings that differ between the jobs (spec keys, ``bounds.<name>``, ``config.<section>.<key>``), each
    with one value per job in the order given."""
    ids = [int(part) for part in jobs.split(",")]
    with storage.snapshot(db) as session:
        specs = [storage.get_job(session, job_id=i) for i in ids]
        return {"jobs": [{"id": j.id, "name": j.name} for j in specs],
                "differences": spec_diff([j.spec for j in specs])}
