"""A job's search space as its models see it, rescoring its best from the server, and what a new-job form
starts from."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, HTTPException, Query, Request
from pydantic import BaseModel, ConfigDict, Field
from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.config import THETA_KEYS
from driftlab.core.limits import MAX_GRID
from driftlab.server import quotas
from driftlab.server.heavy_reads import heavy_read
from driftlab.server.responses import Rescore, SearchSpace, errors
from driftlab.server.routes.deps import factory, require_token, wake_runner
from driftlab.server.schemas import JobId
from driftlab.services import rescores
from driftlab.services.job_documents import job_form
from driftlab.services.search_space import search_space

router = APIRouter(tags=["jobs"])
Factory = Annotated[sessionmaker[Session], Depends(factory)]
MAX_RESCORE_SAMPLES = 1000
ThetaKey = Literal[THETA_KEYS]  # type: ignore[valid-type]  # a job learns some of them (its bounds' keys)


class RescoreCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    samples: int = Field(default=20, ge=1, le=MAX_RESCORE_SAMPLES, strict=True,
                         description="fresh seeds the best theta runs on")


@router.get("/api/jobs/{job_id}/search-space", response_model=SearchSpace, dependencies=[Depends(heavy_read)],
            responses=errors(404, 422, 503))
def get_search_space(job_id: JobId, db: Factory, request: Request,
                     x: Annotated[ThetaKey | None, Query(description="parameter along x")] = None,
                     y: Annotated[ThetaKey | None, Query(description="parameter along y")] = None,
                     grid: Annotated[int, Query(ge=2, le=MAX_GRID, description="points per axis")] = 30
                     ) -> dict[str, Any]:
    """The GP's mean and standard deviation of J and the failure probability over (x, y), the other parameters
    at the best theta, and each parameter's importance (default x, y: the two most important)."""
    return search_space(request.app.state.search_spaces, db, job_id=job_id, x=x, y=y, grid=grid)


@router.post("/api/jobs/{job_id}/rescore", status_code=202, dependencies=[Depends(require_token)],
             response_model=Rescore, responses=errors(404, 409, 422, 503))
def start_rescore(job_id: JobId, body: RescoreCreate, db: Factory, request: Request) -> dict[str, Any]:
    """Queue the best theta, exactly as stored, on ``samples`` fresh seeds; the job runner runs it beside the jobs
    (stored as it goes: it survives a restart). Follow it with GET, stop it with DELETE. 404 without a completed
    evaluation, 409 while one is queued or running for this job, 422 past the global rescore budget."""
    settings = request.app.state.settings
    quotas.check_rescore(settings, body.samples)
    try:
        state = rescores.queue(db, job_id, body.samples, settings.max_rescore_episodes)
    except rescores.RescoreBusy as exc:
        raise HTTPException(409, str(exc)) from None
    except rescores.RescoreBudget as exc:
        raise HTTPException(422, str(exc)) from None
    wake_runner(request)
    return state


@router.get("/api/jobs/{job_id}/rescore", response_model=Rescore, responses=errors(404, 422, 503))
def rescore_status(job_id: JobId, db: Factory) -> dict[str, Any]:
    """The job's latest rescore: queued, running (``done`` of ``samples``), finished (``result``), failed
    (``error``), cancelled, or none."""
    return rescores.status(db, job_id)


@router.delete("/api/jobs/{job_id}/rescore", dependencies=[Depends(require_token)], response_model=Rescore,
               responses=errors(404, 422, 503))
def cancel_rescore(job_id: JobId, db: Factory) -> dict[str, Any]:
    """Cancel the job's queued or running rescore (the samples back so far stay); 404 if none is."""
    return rescores.cancel(db, job_id)


@router.get("/api/config/job-form", responses=errors(503))
def get_job_form() -> dict[str, Any]:
    """What a new job starts from: each plant preset as ``config`` keys (POST /api/jobs), the default config
    (dotted keys), the default bounds of theta and of the model corrections, the settings' limits."""
    return job_form()
