"""A new job of a calibrated car takes the car's newest profile (driftlab.db.profiles): the MPC weights
``driftlab calibrate`` found for it, unless the job's config names ``mpc.*`` keys itself (or the paper's
controller). The weights land in the job's stored config like any other setting, so the job re-runs bit for bit
whatever profiles come later; the job records the profile's id."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from sqlalchemy.orm import Session

from driftlab.core.config import dotted_config
from driftlab.core.tuning import TuningSpec
from driftlab.db import profiles


def gives_weights(config_document: Any) -> bool:
    """Whether a posted or ``--set`` config names MPC settings itself."""
    return any(key.startswith("mpc.") for key in dotted_config(config_document or {}))


def with_profile(session: Session, spec: TuningSpec, config_document: Any) -> tuple[TuningSpec, int | None]:
    """``spec`` with its car's newest profile's weights, and that profile's id (None: none applies)."""
    if gives_weights(config_document):
        return spec, None
    plant = spec.config.plant
    profile = profiles.latest_profile(session, plant_model=plant.model, vehicle_id=plant.commonroad_vehicle)
    if profile is None:
        return spec, None
    mpc = replace(spec.config.mpc, **profile.document["weights"])
    return replace(spec, config=replace(spec.config, mpc=mpc)), profile.id
