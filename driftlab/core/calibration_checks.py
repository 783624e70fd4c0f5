"""What a calibration's chosen weights do on fresh seeds, at each point and half a step either side of it: the
records a profile keeps and the calibrated window is made of (driftlab.core.car_profile.calibrated_window)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict
from typing import Any

from driftlab.core.calibration import (
    POINT_SPACING_RAD,
    VERIFY_SEEDS,
    CalibrationPoint,
    RunBatch,
    split_drivable,
    unfittable,
    verify,
)
from driftlab.core.config import EpisodeConfig, Theta
from driftlab.core.errors import ConfigError


def _record_text(point: CalibrationPoint, record: dict[str, Any]) -> str:
    return (f"{point.label()} {record['completed']}/{record['seeds']} completed"
            + (f" ({record['invalid']} invalid)" if record["invalid"] else "")
            + ("" if record["mean_abs_e_m"] is None else f", mean |e| {record['mean_abs_e_m']:.2f} m"))


def checked_around(base: EpisodeConfig, inside: list[tuple[CalibrationPoint, EpisodeConfig]],
                   weights: dict[str, float], theta: Theta, run_batch: RunBatch, say: Callable[[str], None]
                   ) -> tuple[list[dict[str, Any]], list[list[dict[str, Any]]]]:
    """The chosen weights on VERIFY_SEEDS fresh seeds at each point and half a point's spacing either side of it
    (where the car drifts and the model can be fitted): a job's drift lies within half a step of a calibrated
    point, and weights that hold one drift need not hold its neighbour (the VW Vanagon's weights found at 0.64 rad,
    44 m complete 10 of 10 there and 4 of 10 at 0.62). Returns each point's record and the records around it."""
    half_rad = POINT_SPACING_RAD / 2
    nearby = [CalibrationPoint(round(p.sideslip_rad + side * half_rad, 4), p.radius_m)
              for p, _ in inside for side in (-1, 1)]
    around_inside, _ = split_drivable(base, nearby)
    locations = [*inside, *around_inside]
    try:
        records = verify(locations, weights, run_batch, theta=theta)
    except ConfigError:  # a neighbour where this model has no fit (found by the workers): checked without it
        unfit = {p for p, _ in unfittable(around_inside)}
        locations = [*inside, *((p, c) for p, c in around_inside if p not in unfit)]
        records = verify(locations, weights, run_batch, theta=theta)
    found = {p: {**asdict(p), **record} for (p, _), record in zip(locations, records, strict=True)}
    checked = [found[p] for p, _ in inside]
    around = [[found[q] for q in (CalibrationPoint(round(p.sideslip_rad + side * half_rad, 4), p.radius_m)
                                  for side in (-1, 1)) if q in found] for p, _ in inside]
    say(f"checked on {VERIFY_SEEDS} fresh seeds: " + "; ".join(
        _record_text(p, found[p]) for p in sorted(found, key=lambda q: (q.radius_m, q.sideslip_rad))))
    return [{k: v for k, v in record.items() if k not in ("sideslip_rad", "radius_m")} for record in checked], around
