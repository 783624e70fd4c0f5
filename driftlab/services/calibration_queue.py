"""Calibrations as the API and the dashboard see them (POST/GET/DELETE /api/calibrations): queued in the database
for the runner (driftlab.worker.calibrating), read back as one document."""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.calibration_request import CalibrationRequest
from driftlab.db import calibrations, storage
from driftlab.db.calibrations import CalibrationBusy
from driftlab.db.models import Calibration

__all__ = ["CalibrationBusy", "cancel", "document", "listing", "queue", "status"]


def document(calibration: Calibration) -> dict[str, Any]:
    """Its request, status, latest progress (``tried`` of ``of`` in the current ``step`` of ``round`` of
    ``group``), messages, the profiles stored so far, and why it failed."""
    return {"id": calibration.id, "status": calibration.status, "request": calibration.request,
            "progress": calibration.progress, "messages": calibration.messages,
            "profile_ids": calibration.profile_ids, "error": calibration.error,
            "created_at": calibration.created_at.isoformat(), "updated_at": calibration.updated_at.isoformat()}


def queue(factory: sessionmaker[Session], request: CalibrationRequest) -> dict[str, Any]:
    """Queue a validated request (raises ConfigError naming the field; CalibrationBusy while another runs)."""
    request.validate()
    with storage.transaction(factory) as session:
        return document(calibrations.queue(session, request=request.as_dict()))


def status(factory: sessionmaker[Session], calibration_id: int) -> dict[str, Any]:
    with storage.snapshot(factory) as session:
        return document(calibrations.get(session, calibration_id=calibration_id))


def listing(factory: sessionmaker[Session]) -> list[dict[str, Any]]:
    with storage.snapshot(factory) as session:
        return [document(c) for c in calibrations.list_all(session)]


def cancel(factory: sessionmaker[Session], calibration_id: int) -> dict[str, Any]:
    with storage.transaction(factory) as session:
        return document(calibrations.cancel(session, calibration_id=calibration_id))
