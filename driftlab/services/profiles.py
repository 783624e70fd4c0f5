"""A new job of a calibrated car takes the car's profile (driftlab.db.profiles) that drove the job's drift best
(:func:`profile_for`): the controller's model ``driftlab calibrate`` chose for it (``plant.model_drive_coupling``)
and the MPC weights it found, unless the job's config names ``mpc.*`` keys itself (or the paper's controller). Both
land in the job's stored config like any other setting, so the job re-runs bit for bit whatever profiles come
later; the job records the profile's id.

Profiles come from two places: this database's own (``driftlab calibrate`` run here) and the ones DriftLab ships
(``driftlab/profiles/*.json``, each written by ``driftlab calibrate --out`` and naming the command that made it).
A job takes a shipped profile only where none of the database's own applies; the one it takes is copied into the
database then (once), so that the job's ``profile_id`` names a stored row like any other."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from functools import lru_cache
from importlib import resources
from typing import Any

from sqlalchemy.orm import Session

from driftlab.core.calibration import POINT_SPACING_RAD, VERIFIED_SHARE
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


# How far apart two drifts are: 0.05 rad of sideslip counts as much as 20 % of the circle's radius (about the spacing
# of the default calibration points, driftlab.core.calibration.default_points: 0.05 rad, 44 to 52 m).
SIDESLIP_STEP_RAD = POINT_SPACING_RAD
RADIUS_STEP = 0.2


def drift_distance(sideslip_rad: float, radius_m: float, point: dict[str, Any]) -> float:
    """How far a calibrated point (``sideslip_rad``, ``radius_m``) lies from the drift (sideslip, radius)."""
    # Rounded: 0.69 - 0.64 is a whole step, as 0.55 - 0.50 is (in floating point one is just under 0.05, one over).
    return round(abs(point["sideslip_rad"] - sideslip_rad) / SIDESLIP_STEP_RAD
                 + abs(point["radius_m"] - radius_m) / (RADIUS_STEP * radius_m), 9)


def _tally(record: dict[str, Any]) -> tuple[int, int]:
    """(completed, episodes) of a profile's record at a point: of the fresh seeds its weights were checked on, or, for
    a profile of a release before that check, of its search's own episodes."""
    checked = record.get("verified")
    return (checked["completed"], checked["seeds"]) if checked else (record["completed"], record["episodes"])


def checked_drifts(document: dict[str, Any]) -> list[dict[str, Any]]:
    """Every drift a profile's weights were checked at, as {sideslip_rad, radius_m, completed, episodes,
    mean_abs_e_m}: each calibrated point (its fresh seeds, or its search's episodes for a profile stored before that
    check) and the drifts half a step either side of it (``verified_around``)."""
    out = []
    for record in document.get("per_point") or []:
        completed, episodes = _tally(record)
        error = (record.get("verified") or record).get("mean_abs_e_m")
        out.append({"sideslip_rad": record["sideslip_rad"], "radius_m": record["radius_m"], "completed": completed,
                    "episodes": episodes, "mean_abs_e_m": error})
        out += [{"sideslip_rad": near["sideslip_rad"], "radius_m": near["radius_m"], "completed": near["completed"],
                 "episodes": near["seeds"], "mean_abs_e_m": near.get("mean_abs_e_m")}
                for near in record.get("verified_around") or []]
    return out


def _drives(drift: dict[str, Any]) -> bool:
    return bool(drift["episodes"]) and drift["completed"] >= VERIFIED_SHARE * drift["episodes"]


def calibrated_window(documents: list[dict[str, Any]]) -> dict[float, list[tuple[float, float]]]:
    """Where a calibration's profiles drive the car, per radius [m]: the sideslip ranges [rad] over which the drifts
    their weights were checked at (:func:`checked_drifts`: each point and half a step either side) complete at
    least VERIFIED_SHARE of their fresh seeds (by the best profile there). Neighbouring checked drifts join a range
    (half a step apart; a whole step for profiles stored before the drifts around a point were checked). A radius
    none of whose drifts passes has no range."""
    passed: dict[tuple[float, float], bool] = {}
    around: set[float] = set()
    for document in documents:
        for record in document.get("per_point") or []:
            if record.get("verified_around") is not None:
                around.add(record["radius_m"])
        for drift in checked_drifts(document):
            key = (drift["radius_m"], round(drift["sideslip_rad"], 4))
            passed[key] = passed.get(key, False) or _drives(drift)
    window: dict[float, list[tuple[float, float]]] = {}
    for radius_m in sorted({r for r, _ in passed}):
        joins_rad = 1.5 * POINT_SPACING_RAD * (0.5 if radius_m in around else 1.0)
        ranges: list[tuple[float, float]] = []
        last: float | None = None
        for sideslip_rad in sorted(b for r, b in passed if r == radius_m):
            if passed[(radius_m, sideslip_rad)]:
                if ranges and last is not None and ranges[-1][1] == last and sideslip_rad - last <= joins_rad:
                    ranges[-1] = (ranges[-1][0], sideslip_rad)
                else:
                    ranges.append((sideslip_rad, sideslip_rad))
            last = sideslip_rad
        window[radius_m] = ranges
    return window


def window_text(window: dict[float, list[tuple[float, float]]]) -> str:
    """The calibrated window as a calibration prints it, one clause per radius."""
    def ranges_text(ranges: list[tuple[float, float]]) -> str:
        return ", ".join(f"{lo:g}" if lo == hi else f"{lo:g}-{hi:g}" for lo, hi in ranges) + " rad" if ranges \
            else "none"
    return (f"calibrated window (the drifts whose weights complete at least {VERIFIED_SHARE:.0%} of their fresh "
            "seeds): " + "; ".join(f"R {radius_m:g} m: {ranges_text(ranges)}" for radius_m, ranges in window.items()))


def profile_for(candidates: list[Any], sideslip_rad: float, radius_m: float) -> Any | None:
    """Of a car's profiles (each with ``id`` and ``document``), the one whose weights drove the calibrated point
    nearest this drift best: one that completed every episode of its point first (the VW Vanagon's weights that
    completed 1 of 3 at its own 0.69 rad, 44 m complete none of 20 fresh seeds of a job there, those that completed
    3 of 3 at 0.69 rad, 52 m complete 20 of 20), then the nearest point (a profile calibrated at the job's own drift
    wins), then the share of its episodes completed there, then their mean |e|, then the newest. A calibration
    over several points finds one weight set for all of them; where a car needs other weights at another drift
    (the BMW at 0.45 rad does), a calibration at that point alone (the default of ``driftlab calibrate``) gives
    them, and the jobs there take them. A profile is taken only where it was calibrated less than one step from the
    job's drift
    (:func:`drift_distance` < 1) and its weights completed some of their episodes there: weights do not carry over
    further (the BMW's, found at 0.50 rad, spin out every episode of a job at 0.55; the set shipped for the whole
    window completes them), so the car's default weights are the job's then. A profile stored without its record
    (none of this release's) applies anywhere, the newest first."""
    def record_here(profile) -> dict[str, Any] | None:
        drifts = checked_drifts(profile.document)
        return min(drifts, key=lambda drift: drift_distance(sideslip_rad, radius_m, drift), default=None)

    def rank(profile) -> tuple[bool, float, float, float, int]:
        here = record_here(profile)
        if here is None:
            return (True, float("inf"), 0.0, float("inf"), -profile.id)
        completed, episodes, error = here["completed"], here["episodes"], here["mean_abs_e_m"]
        return (completed < episodes, drift_distance(sideslip_rad, radius_m, here), -completed / max(episodes, 1),
                float("inf") if error is None else error, -profile.id)
    usable = [p for p in candidates if (here := record_here(p)) is None
              or (here["completed"] > 0 and drift_distance(sideslip_rad, radius_m, here) < 1.0)]
    return min(usable, key=rank, default=None)


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


def _same_model(profile: Any, wheel_liftoff: bool) -> bool:
    """Whether a profile was calibrated on the plant's model as the job runs it: weights found on MB as published
    (its tyres pull the road) are not weights for the car that lifts a wheel (PlantConfig.wheel_liftoff)."""
    return bool(profile.document.get("plant", {}).get("wheel_liftoff", False)) == wheel_liftoff


def car_profile_for(session: Session, plant_model: str, vehicle_id: int, sideslip_rad: float,
                    radius_m: float, wheel_liftoff: bool = False) -> Any | None:
    """The stored profile a job of this car at this drift takes (:func:`profile_for`): the database's own first;
    where none of them applies, a shipped one, copied into the database the first time a job takes it. Only
    profiles calibrated on the same model of the car (:func:`_same_model`) apply."""
    stored = [p for p in profiles.car_profiles(session, plant_model=plant_model, vehicle_id=vehicle_id)
              if _same_model(p, wheel_liftoff)]
    own = profile_for([p for p in stored if SHIPPED_KEY not in p.document], sideslip_rad, radius_m)
    if own is not None:
        return own
    shipped = profile_for([p for p in shipped_profiles(plant_model, vehicle_id) if _same_model(p, wheel_liftoff)],
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


def _point_text(point: dict[str, Any]) -> str:
    return f"{point['sideslip_rad']:g} rad, {point['radius_m']:g} m"


def _record_text(drift: dict[str, Any]) -> str:
    return f"{drift['completed']} of {drift['episodes']} episodes completed"


def uncalibrated_warning(session: Session, spec: TuningSpec) -> str | None:
    """What a job that took no profile (:func:`with_profile`) is told: its car has calibrated weights, but none for
    its drift; the nearest calibrated drift, how its weights did there, and the command that calibrates the job's
    own. None for a car no profile was ever found for (nothing nearer to name) and for a drift a profile applies to.
    A drift where the car has no equilibrium at all is refused before this (driftlab.core.drivability)."""
    plant, scenario = spec.config.plant, spec.config.scenario
    candidates = [*(p for p in profiles.car_profiles(session, plant_model=plant.model,
                                                     vehicle_id=plant.commonroad_vehicle)
                    if _same_model(p, plant.wheel_liftoff) and SHIPPED_KEY not in p.document),
                  *(p for p in shipped_profiles(plant.model, plant.commonroad_vehicle)
                    if _same_model(p, plant.wheel_liftoff))]
    records = [drift for p in candidates for drift in checked_drifts(p.document) if drift["completed"]]
    if not records:
        return None
    nearest = min(records, key=lambda r: drift_distance(scenario.sideslip_rad, scenario.left_radius_m, r))
    here = {"sideslip_rad": scenario.sideslip_rad, "radius_m": scenario.left_radius_m}
    return (f"no calibrated weights for {_point_text(here)}: the job drives the car's default weights; the nearest "
            f"calibrated drift is {_point_text(nearest)} ({_record_text(nearest)}); `driftlab calibrate --plant "
            f"{plant.model} --points {scenario.sideslip_rad:g}@{scenario.left_radius_m:g}` calibrates this one")


# The MPC settings a profile carries besides its weights (driftlab.core.calibration searches only the weights).
PROFILE_LIMITS = ("steer_limit_rad",)


# What a job reads of a profile, and where it came from (its provenance); the rest of a calibration's document (the
# start, the candidates, the known sets it tried, the points it skipped) is its log, kept in the database only.
PROFILE_KEYS = ("plant_model", "vehicle_id", "weights", "theta", "per_point", "window", "score",
                "completed", "episodes", "round", "seeds", "iterations", "command", "driftlab_version", "wall_s")
PROFILE_PLANT = ("model_drive_coupling", "wheel_liftoff")  # the plant settings a profile's weights hold for


def profile_data(document: dict[str, Any]) -> dict[str, Any]:
    """A profile as data (what ``driftlab calibrate --out`` writes and DriftLab ships): :data:`PROFILE_KEYS`, the
    plant settings its weights were found on (:data:`PROFILE_PLANT`) and the controller's limits
    (:func:`limits_of`), without the calibration's log."""
    plant = document.get("plant", {})
    return {**{k: document[k] for k in PROFILE_KEYS if k in document},
            "plant": {k: plant[k] for k in PROFILE_PLANT if k in plant}, "mpc": limits_of(document)}


def profiles_file(documents: list[dict[str, Any]]) -> str:
    """The text of a profiles file (``driftlab calibrate --out``, ``driftlab/profiles/*.json``): each stored
    document's :func:`profile_data` with its id, one profile a line."""
    lines = [json.dumps({"profile_id": d["profile_id"], **profile_data(d)}, allow_nan=False) for d in documents]
    return '{"profiles": [\n' + ",\n".join(lines) + "\n]}\n"


def limits_of(document: dict[str, Any]) -> dict[str, Any]:
    """The controller's limits a profile's weights were found with (what its ``mpc`` stored): weights found for
    0.6 rad of steering do not carry over to the car's whole reach."""
    stored = document.get("mpc", {})
    return {name: stored[name] for name in PROFILE_LIMITS if name in stored}


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
