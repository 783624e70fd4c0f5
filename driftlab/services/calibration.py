"""A calibration run with its profiles stored as they are found (driftlab.db.profiles), the weight sets the
database knows tried after the car's own: the run itself is driftlab.core.calibration_run's."""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.calibration import RunBatch
from driftlab.core.calibration_request import CalibrationRequest
from driftlab.core.calibration_run import Event
from driftlab.core.calibration_run import run_calibration as run_calibration_on
from driftlab.core.mpc_config import MpcConfig
from driftlab.db import profiles, storage
from driftlab.services.profiles import known_weight_sets


def run_calibration(request: CalibrationRequest, factory: sessionmaker[Session], run_batch: RunBatch, *,
                    on_event: Event = lambda event: None) -> list[dict[str, Any]]:
    """Runs ``request`` on ``run_batch``, storing each profile in ``factory``'s database as it is found."""
    def known(car: MpcConfig) -> list[tuple[str, MpcConfig]]:
        with storage.transaction(factory) as session:
            return known_weight_sets(session, car)

    def store(document: dict[str, Any]) -> dict[str, Any]:
        with storage.transaction(factory) as session:
            profile = profiles.add_profile(session, plant_model=document["plant_model"],
                                           vehicle_id=document["vehicle_id"], document=document)
            return {"profile_id": profile.id, **document}

    return run_calibration_on(request, run_batch, known=known, store=store, on_event=on_event)
