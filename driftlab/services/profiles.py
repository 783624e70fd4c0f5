"""A new job of a calibrated car takes the car's profile (driftlab.db.profiles) that drove the job's drift best
(driftlab.core.car_profile.profile_for): the controller's model ``driftlab calibrate`` chose for it
(``plant.model_drive_coupling``) and the MPC weights it found, unless the job's config names ``mpc.*`` keys itself
(or the paper's controller). Both land in the job's stored config like any other setting, so the job re-runs bit for
bit whatever profiles come later; the job records the profile's id.

Profiles come from two places: this database's own (``driftlab calibrate`` run here) and the ones DriftLab ships
(``driftlab/profiles/*.json``, each written by ``driftlab calibrate --out`` and naming the command that made it). A
job takes a shipped profile only where none of the database's own applies; the one it takes is copied into the
database then (once), so that the job's ``profile_id`` names a stored row like any other."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from functools import lru_cache
from importlib import resources
from typing import Any

from sqlalchemy.orm import Session

from driftlab.core.car_profile import (
    checked_drifts,
    drift_distance,
    limits_of,
    point_text,
    profile_for,
    record_text,
    same_model,
)
from driftlab.core.config import dotted_config
from driftlab.core.configure import apply_overrides
from driftlab.core.mpc_config import MpcConfig
from driftlab.core.tuning import TuningSpec
from driftlab.core.warm_start import profile_start
from driftlab.db import profiles


def gives_weights(config_document: Any) -> bool:
    """Whether a posted or ``--set`` config names MPC settings itself."""
    return any(key.startswith("mpc.") for key in dotted_config(config_document or {}))


def known_weight_sets(session: Session, car: MpcConfig) -> list[tuple[str, MpcConfig]]:
    """Every weight set DriftLab knows to drive some car, other than ``car``'s own: the newest profile of each
    calibrated car in this database, newest first, then the weights each plant of the catalog ships
    (driftlab.core.plants). A calibration tries them after the car's own (driftlab.core.calibration.calibrate)."""
    from driftlab.core.plants import built_in_names, plant_type

    found = [(f"profile {profile.id} ({profile.plant_model}, vehicle {profile.vehicle_id})",
              replace(car, **profile.document["weights"])) for profile in profiles.newest_profiles(session)]
    found += [(f"{name}'s shipped weights", plant_type(name).controller()) for name in built_in_names()]
    unique, seen = [], {car}
    for label, mpc in found:
        if mpc not in seen:
            seen.add(mpc)
            unique.append((label, mpc))
    return unique


# The key a shipped profile copied into a database carries in its document: "<file name>#<index in the file>".
SHIPPED_KEY = "shipped"


@dataclass(frozen=True)
class ShippedProfile:
    """A profile of ``driftlab/profiles/<file>``: ``id`` its place in the file (later is newer), ``key`` where it is."""

    id: int
    key: str
    document: dict[str, Any]


@lru_cache(maxsize=1)
def _shipped_files() -> tuple[tuple[str, tuple[dict[str, Any], ...]], ...]:
    folder = resources.files("driftlab.profiles")
    return tuple((entry.name, tuple(json.loads(entry.read_text())["profiles"]))
                 for entry in sorted(folder.iterdir(), key=lambda e: e.name) if entry.name.endswith(".json"))


def shipped_profiles(plant_model: str, vehicle_id: int) -> list[ShippedProfile]:
    """The profiles DriftLab ships for one car (each document as ``driftlab calibrate --out`` wrote it)."""
    return [ShippedProfile(index + 1, f"{name}#{index}", {k: v for k, v in document.items() if k != "profile_id"})
            for name, documents in _shipped_files() for index, document in enumerate(documents)
            if document["plant_model"] == plant_model and document["vehicle_id"] == vehicle_id]


def car_profile_for(session: Session, plant_model: str, vehicle_id: int, sideslip_rad: float,
                    radius_m: float, wheel_liftoff: bool = False) -> Any | None:
    """The stored profile a job of this car at this drift takes (driftlab.core.car_profile.profile_for): the database's
    own first; where none of them applies, a shipped one, copied into the database the first time a job takes
    it. Only profiles calibrated on the same model of the car (driftlab.core.car_profile.same_model) apply."""
    stored = [p for p in profiles.car_profiles(session, plant_model=plant_model, vehicle_id=vehicle_id)
              if same_model(p, wheel_liftoff)]
    own = profile_for([p for p in stored if SHIPPED_KEY not in p.document], sideslip_rad, radius_m)
    if own is not None:
        return own
    shipped = profile_for([p for p in shipped_profiles(plant_model, vehicle_id) if same_model(p, wheel_liftoff)],
                          sideslip_rad, radius_m)
    if shipped is None:
        return None
    copied = next((p for p in stored if p.document.get(SHIPPED_KEY) == shipped.key), None)
    return copied or profiles.add_profile(session, plant_model=plant_model, vehicle_id=vehicle_id,
                                          document={**shipped.document, SHIPPED_KEY: shipped.key})


def with_profile(session: Session, spec: TuningSpec, config_document: Any) -> tuple[TuningSpec, int | None]:
    """``spec`` with the weights of its car's profile for its drift (:func:`car_profile_for`), asking first the theta
    they were found with (driftlab.core.warm_start.profile_start), and that profile's id (None: none applies)."""
    if gives_weights(config_document):
        return spec, None
    plant, scenario = spec.config.plant, spec.config.scenario
    profile = car_profile_for(session, plant.model, plant.commonroad_vehicle, scenario.sideslip_rad,
                              scenario.left_radius_m, plant.wheel_liftoff)
    if profile is None:
        return spec, None
    config = spec.config
    coupling = profile.document.get("plant", {}).get("model_drive_coupling", False)
    if coupling != config.plant.model_drive_coupling and "plant.model_drive_coupling" not in dotted_config(
            config_document or {}):
        config = apply_overrides(config, {"plant.model_drive_coupling": coupling})  # the model refitted
    mpc = replace(config.mpc, **profile.document["weights"], **limits_of(profile.document))
    spec = replace(spec, config=replace(config, mpc=mpc))
    start = profile_start(profile.id, profile.document.get("theta"), spec.bounds)
    if start is not None:
        spec = replace(spec, warm_start=start if spec.warm_start is None else spec.warm_start.joined(start))
    return spec, profile.id


def uncalibrated_warning(session: Session, spec: TuningSpec) -> str | None:
    """What a job that took no profile (:func:`with_profile`) is told: its car has calibrated weights, but none for
    its drift; the nearest calibrated drift, how its weights did there, and the command that calibrates the job's
    own. None for a car no profile was ever found for (nothing nearer to name) and for a drift a profile applies to.
    A drift where the car has no equilibrium at all is refused before this (driftlab.core.drivability)."""
    plant, scenario = spec.config.plant, spec.config.scenario
    candidates = [*(p for p in profiles.car_profiles(session, plant_model=plant.model,
                                                     vehicle_id=plant.commonroad_vehicle)
                    if same_model(p, plant.wheel_liftoff) and SHIPPED_KEY not in p.document),
                  *(p for p in shipped_profiles(plant.model, plant.commonroad_vehicle)
                    if same_model(p, plant.wheel_liftoff))]
    records = [drift for p in candidates for drift in checked_drifts(p.document) if drift["completed"]]
    if not records:
        return None
    nearest = min(records, key=lambda r: drift_distance(scenario.sideslip_rad, scenario.left_radius_m, r))
    here = {"sideslip_rad": scenario.sideslip_rad, "radius_m": scenario.left_radius_m}
    return (f"no calibrated weights for {point_text(here)}: the job drives the car's default weights; the nearest "
            f"calibrated drift is {point_text(nearest)} ({record_text(nearest)}); `driftlab calibrate --plant "
            f"{plant.model} --points {scenario.sideslip_rad:g}@{scenario.left_radius_m:g}` calibrates this one")


def profile_summary(profile: Any) -> dict[str, Any]:
    """A stored profile in a few fields: its car, where it was calibrated and how it did there, the command."""
    document = profile.document
    return {"id": profile.id, "plant_model": profile.plant_model, "vehicle_id": profile.vehicle_id,
            "created_at": profile.created_at.isoformat(), "per_point": document.get("per_point"),
            "round": document.get("round"), "command": document.get("command"),
            "shipped": document.get(SHIPPED_KEY)}


def list_profile_summaries(factory: Any) -> list[dict[str, Any]]:
    from driftlab.db import storage

    with storage.snapshot(factory) as session:
        return [profile_summary(p) for p in profiles.list_profiles(session)]


def profile_document(factory: Any, profile_id: int) -> dict[str, Any]:
    """The whole stored profile, as ``driftlab calibrate --out`` writes one (raises storage.NotFound)."""
    from driftlab.db import storage

    with storage.snapshot(factory) as session:
        profile = profiles.get_profile(session, profile_id=profile_id)
        return {"profile_id": profile.id, **profile.document}
