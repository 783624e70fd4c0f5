"""Whether a configuration can drift the scenario at all, decided before any episode runs.

A plant without a countersteer drift equilibrium at a circle's radius and the scenario's sideslip cannot hold
the sustained drift whatever the controller does (e.g. the default plant with 15% more friction: its front
tyre cannot make the countersteer force), so an episode on it is not a result about the controller. Such a
configuration is refused with the reason instead of being run as a failed episode. The same holds for the
controller's own model (it has nothing to linearize about).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from driftlab.core.config import MODEL_FIT, EpisodeConfig
from driftlab.core.errors import ConfigError
from driftlab.core.plant import PlantConfig
from driftlab.core.plants import entry_of
from driftlab.core.track import tiled_radii
from driftlab.core.vehicle import VehicleParams


class NotDrivableError(ConfigError):
    """The plant or the controller's model has no drift equilibrium at the scenario's radius and sideslip."""


def check_drivable(config: EpisodeConfig) -> None:
    """Raises :class:`NotDrivableError` naming the circle, the radius, the sideslip and what lacks a drift. A
    config whose controller's model is still to be fitted (driftlab.core.configure.fitted) is checked without the fit:
    where it cannot be fitted, the plant's OutsideDriftWindowError names the window (PlantType.check_fit)."""
    s = config.scenario
    if MODEL_FIT in config.to_fit:
        for radius_m in dict.fromkeys((s.left_radius_m, s.right_radius_m)):
            entry_of(config.plant).check_fit(config.plant, radius_m, s.sideslip_rad)
    reason = _reason(_checked_model(config), config.plant, s.left_radius_m, s.right_radius_m, s.sideslip_rad)
    if reason is not None:
        raise NotDrivableError(reason)


def _checked_model(config: EpisodeConfig) -> VehicleParams | None:
    """The controller's model the check reads: None while it is still to be fitted (PlantType.check_fit decides)."""
    return None if MODEL_FIT in config.to_fit else config.vehicle


def drivable_reason(config: EpisodeConfig) -> str | None:
    """None when the configuration is drivable, else why not (the message of :func:`check_drivable`)."""
    try:
        check_drivable(config)
    except ConfigError as exc:  # NotDrivableError, or a model that cannot be fitted (OutsideDriftWindowError)
        return str(exc)
    return None


@lru_cache(maxsize=256)
def _reason(vehicle: VehicleParams | None, plant: PlantConfig, left_radius_m: float, right_radius_m: float,
            sideslip_rad: float) -> str | None:
    """The controller's model on each circle (``vehicle``; None: still to be fitted, where the plant's fit check
    decides), then the plant's own drift (its catalog entry's check). A right-hand drift mirrors a left-hand one
    (same V, delta, Fxr): one solve per radius is enough."""
    entry = entry_of(plant)
    circles = [("left", left_radius_m)] + ([("right", right_radius_m)] if right_radius_m != left_radius_m else [])
    for circle, radius in circles:
        reason = (entry.model_reason(vehicle, radius, sideslip_rad, circle) if vehicle is not None
                  else _fit_reason(plant, radius, sideslip_rad))
        if reason is not None:
            return reason + entry.not_drivable_hint
    for circle, radius in circles:
        reason = entry.plant_reason(plant, vehicle, radius, sideslip_rad, circle)
        if reason is not None:
            return reason
    return None


def _fit_reason(plant: PlantConfig, radius_m: float, sideslip_rad: float) -> str | None:
    try:
        entry_of(plant).check_fit(plant, radius_m, sideslip_rad)
    except ConfigError as exc:
        return str(exc)
    return None


@dataclass(frozen=True)
class DriftWindow:
    """The sideslips [rad] at which a job of a configuration drifts both circles of an 8 of one radius (plant and
    model both have a countersteer drift there, left- and right-hand), scanned on a grid; where there are none, why
    (``reason``, one sentence)."""

    radius_m: float
    sideslips_rad: tuple[float, ...]
    reason: str | None = None

    @property
    def ranges_rad(self) -> list[tuple[float, float]]:
        """The drivable sideslips as [low, high] runs of the grid."""
        runs: list[tuple[float, float]] = []
        for beta in self.sideslips_rad:
            if runs and beta - runs[-1][1] <= WINDOW_STEP_RAD * 1.5:
                runs[-1] = (runs[-1][0], beta)
            else:
                runs.append((beta, beta))
        return runs

    def as_dict(self) -> dict:
        reason = {} if self.reason is None else {"reason": self.reason}
        return {"radius_m": self.radius_m, "sideslip_ranges_rad": [list(r) for r in self.ranges_rad], **reason}


WINDOW_STEP_RAD = 0.01
# Where every window is scanned (`driftlab equilibrium --window`, the calibration's points, a profile's window, the
# view): CommonRoad's drift families are scanned over it (driftlab.core.commonroad.family); beyond 0.8 rad the
# failure limits (1.2 rad) leave a flick no room.
WINDOW_SCAN_RAD = (0.2, 0.8)


def drift_window(config: EpisodeConfig, radius_m: float, low_rad: float = WINDOW_SCAN_RAD[0],
                 high_rad: float = WINDOW_SCAN_RAD[1]) -> DriftWindow:
    """Where a job of ``config``'s car (its plant and controller's model) drifts both circles of an 8 of
    ``radius_m``: the sideslips of a WINDOW_STEP_RAD grid over [low, high] that the drivability check accepts, the
    decision a job's config gets there. A plant that fits its model at each drift (PlantType.fits_model) is checked
    as a job is, with the model still to be fitted, so that a fit made at another drift does not decide; its check
    reads both the left- and the right-hand drift (a CommonRoad car's PAC2002 tyres are not symmetric). The one
    scan `driftlab equilibrium --window`, the calibration's points and the view all read. Where the grid has no
    sideslip, ``reason`` says why (PlantType.window_reason)."""
    entry = entry_of(config.plant)
    if entry.fits_model:
        config = replace(config, to_fit=config.to_fit | {MODEL_FIT})
    grid = np.round(np.arange(low_rad, high_rad + 1e-9, WINDOW_STEP_RAD), 4)
    model = _checked_model(config)
    ok = tuple(float(b) for b in grid if _reason(model, config.plant, radius_m, radius_m, float(b)) is None)
    s = config.scenario  # the other circles named where this one has no drift: those a calibration of it tiles
    elsewhere = tuple(sorted({*tiled_radii(s.left_radius_m), *tiled_radii(s.right_radius_m)}))
    reason = None if ok else entry.window_reason(config.plant, model, float(radius_m), low_rad, high_rad, elsewhere)
    return DriftWindow(float(radius_m), ok, reason)
