"""Single evaluations and their trajectories."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Query, Response
from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.track import FigureEight
from driftlab.db import storage
from driftlab.reports.export import trajectory_csv, trajectory_json, with_lap_column
from driftlab.server.responses import Evaluation, TrajectoryDocument, errors, media
from driftlab.server.routes.deps import factory
from driftlab.server.schemas import EvaluationId
from driftlab.server.serialize import evaluation_dict, trajectory_metadata

router = APIRouter(prefix="/api/evaluations", tags=["evaluations"])
Factory = Annotated[sessionmaker[Session], Depends(factory)]


@router.get("/{evaluation_id}", response_model=Evaluation, responses=errors(404, 422, 503))
def get_evaluation(evaluation_id: EvaluationId, db: Factory) -> dict[str, Any]:
    with storage.snapshot(db) as session:
        return evaluation_dict(storage.get_evaluation(session, evaluation_id=evaluation_id))


@router.get("/{evaluation_id}/trajectory", response_model=TrajectoryDocument, responses={
    **media("text/csv", {"type": "string"}, "format=csv (the default): a '# driftlab: {metadata}' line, then a "
            "header and one row per control step; format=json: the document below"), **errors(404, 422, 503)})
def trajectory(evaluation_id: EvaluationId, db: Factory,
               format: str = Query("csv", pattern="^(csv|json)$")) -> Response:  # noqa: A002
    """The stored episode (its seed: the evaluation's ``trajectory_seed``), one row per control step, with its
    metadata: a ``metadata`` object in JSON, a ``# driftlab: {...}`` first line in CSV."""
    with storage.snapshot(db) as session:
        columns, data = storage.trajectory_array(session, evaluation_id=evaluation_id)
        e = storage.get_evaluation(session, evaluation_id=evaluation_id)
        job = storage.get_job(session, job_id=e.job_id)
        metadata = trajectory_metadata(e, job)
    track = FigureEight.of_scenario(job.spec.get("config", {}).get("scenario", {}))
    columns, data = with_lap_column(columns, data, track)
    headers = {"Content-Disposition": f'attachment; filename="evaluation-{evaluation_id}.{format}"'}
    if format == "json":
        return Response(trajectory_json(columns, data, metadata), media_type="application/json", headers=headers)
    return Response(trajectory_csv(columns, data, metadata), media_type="text/csv", headers=headers)
