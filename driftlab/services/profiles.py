"""A new job of a calibrated car takes the car's newest profile (driftlab.db.profiles): the controller's model
``driftlab calibrate`` chose for it (``plant.model_drive_coupling``) and the MPC weights it found, unless the job's
config names ``mpc.*`` keys itself (or the paper's controller). Both land in the job's stored config like any other
setting, so the job re-runs bit for bit whatever profiles come later; the job records the profile's id."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from sqlalchemy.orm import Session

from driftlab.core.config import apply_overrides, dotted_config
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
    config = spec.config
    coupling = profile.document.get("plant", {}).get("model_drive_coupling", False)
    if coupling != config.plant.model_drive_coupling and "plant.model_drive_coupling" not in dotted_config(
            config_document or {}):
        config = apply_overrides(config, {"plant.model_drive_coupling": coupling})  # the model refitted
    mpc = replace(config.mpc, **profile.document["weights"])
    return replace(spec, config=replace(config, mpc=mpc)), profile.id
