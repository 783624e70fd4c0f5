"""A car's profile as data: what ``driftlab calibrate`` found for a car (the weights, the controller's limits, the
theta, each calibrated point's record) and which profile a job at a given drift takes (:func:`profile_for`); the
calibrated window a calibration prints (:func:`calibrated_window`). Pure functions of profile documents: storing
and shipping them is driftlab.db.profiles' and driftlab.services.profiles'."""

from __future__ import annotations

import json
from typing import Any

from driftlab.core.calibration import POINT_SPACING_RAD, VERIFIED_SHARE

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


def same_model(profile: Any, wheel_liftoff: bool) -> bool:
    """Whether a profile was calibrated on the plant's model as the job runs it: weights found on MB as published
    (its tyres pull the road) are not weights for the car that lifts a wheel (PlantConfig.wheel_liftoff)."""
    return bool(profile.document.get("plant", {}).get("wheel_liftoff", False)) == wheel_liftoff


def point_text(point: dict[str, Any]) -> str:
    return f"{point['sideslip_rad']:g} rad, {point['radius_m']:g} m"


def record_text(drift: dict[str, Any]) -> str:
    return f"{drift['completed']} of {drift['episodes']} episodes completed"


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
