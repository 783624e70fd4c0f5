"""Stored calibrations (driftlab.db.models.Calibration): queued by a request, claimed by a runner under the same
lease as a job (driftlab.db.lease), their progress and profiles recorded as they run, cancelled by a request."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from driftlab.db import lease
from driftlab.db.models import Calibration, WorkStatus
from driftlab.db.storage import NotFound, get_row

ACTIVE = (WorkStatus.QUEUED, WorkStatus.RUNNING)
MESSAGES_KEPT = 200  # the newest messages a calibration keeps (a 5-point, 5-round run says about 60)


class CalibrationBusy(Exception):
    """Another calibration is queued or running (one at a time: each uses every episode slot it is given)."""


def queue(session: Session, *, request: dict[str, Any]) -> Calibration:
    """A new queued calibration (raises CalibrationBusy while one is queued or running)."""
    active = session.scalar(select(Calibration).where(Calibration.status.in_(ACTIVE)).limit(1))
    if active is not None:
        raise CalibrationBusy(f"calibration {active.id} is {active.status}; one runs at a time (cancel it with "
                              f"DELETE /api/calibrations/{active.id})")
    calibration = Calibration(request=request, messages=[], profile_ids=[], status=WorkStatus.QUEUED)
    session.add(calibration)
    session.flush()
    return calibration


def get(session: Session, *, calibration_id: int) -> Calibration:
    return get_row(session, Calibration, calibration_id, "calibration")


def list_all(session: Session) -> list[Calibration]:
    return list(session.scalars(select(Calibration).order_by(Calibration.id)))


def cancel(session: Session, *, calibration_id: int) -> Calibration:
    """A queued or running calibration stops (its runner sees it at its next event); raises NotFound."""
    calibration = get(session, calibration_id=calibration_id)
    if calibration.status not in ACTIVE:
        raise NotFound(f"calibration {calibration_id} is {calibration.status}, not queued or running")
    return lease.cancel(calibration)


def record(session: Session, *, calibration_id: int, runner: str, progress: dict[str, Any] | None = None,
           messages: Sequence[str] = (), profile_id: int | None = None) -> bool:
    """Store what the run reported and renew the lease; False when ``runner`` no longer holds it (cancelled or
    taken over: stop)."""
    calibration = session.get(Calibration, calibration_id)
    if calibration is None or calibration.runner_id != runner or calibration.status != WorkStatus.RUNNING:
        return False
    if progress is not None:
        calibration.progress = progress
    if messages:  # new lists: JSON columns track assignment, not mutation
        calibration.messages = [*calibration.messages, *messages][-MESSAGES_KEPT:]
    if profile_id is not None:
        calibration.profile_ids = [*calibration.profile_ids, profile_id]
    return lease.renew(session, Calibration, row_id=calibration_id, runner=runner)


def finish(session: Session, *, calibration_id: int, runner: str, status: WorkStatus,
           error: str | None = None) -> None:
    lease.release(session, Calibration, row_id=calibration_id, runner=runner, status=status, error=error)

