"""Single evaluations and their trajectories."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Query, Response
from sqlalchemy.orm import Session, sessionmaker

from driftlab.db import storage
from driftlab.server.responses import Evaluation, TrajectoryDocument, errors, media
from driftlab.server.routes.deps import factory, trajectory_documents
from driftlab.server.schemas import EvaluationId
from driftlab.server.serialize import evaluation_dict
from driftlab.server.trajectory_documents import TrajectoryDocuments

router = APIRouter(prefix="/api/evaluations", tags=["evaluations"])
Factory = Annotated[sessionmaker[Session], Depends(factory)]
Documents = Annotated[TrajectoryDocuments, Depends(trajectory_documents)]


@router.get("/{evaluation_id}", response_model=Evaluation, responses=errors(404, 422, 503))
def get_evaluation(evaluation_id: EvaluationId, db: Factory) -> dict[str, Any]:
    with storage.snapshot(db) as session:
        return evaluation_dict(storage.get_evaluation(session, evaluation_id=evaluation_id))


@router.get("/{evaluation_id}/trajectory", response_model=TrajectoryDocument, responses={
    **media("text/csv", {"type": "string"}, "format=csv (the default): a header and one row per control step, "
            "nothing else (pandas.read_csv reads it as it is); format=json: the document below, with the metadata"),
    **errors(404, 422, 503)})
def trajectory(evaluation_id: EvaluationId, db: Factory, documents: Documents,
               format: str = Query("csv", pattern="^(csv|json)$")) -> Response:  # noqa: A002
    """The stored episode (its seed: the evaluation's ``trajectory_seed``), one row per control step; the JSON also
    holds its metadata (a ``metadata`` object), which a CSV response names in a ``Link`` header (rel="describedby")."""
    with storage.snapshot(db) as session:
        text = documents.document(session, evaluation_id=evaluation_id, format="json" if format == "json" else "csv")
    headers = {"Content-Disposition": f'attachment; filename="evaluation-{evaluation_id}.{format}"'}
    if format == "csv":
        headers["Link"] = f'</api/evaluations/{evaluation_id}/trajectory?format=json>; rel="describedby"'
    return Response(text, media_type="application/json" if format == "json" else "text/csv", headers=headers)
