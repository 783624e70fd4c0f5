"""Where a CommonRoad car can drift a circle both ways (left and right circle of the 8), and, where it cannot, why in
one sentence: its tyres (no countersteer drift at any sideslip, whatever the drive), its engine (the drifts exist,
but STD caps the drive at a_max v_switch / V, and holding them needs more), or the controller's model of it.

The engine is as much a limit as the tyres: the BMW 320i at 0.5 rad, 44 m uses 3.33 of the 4.11 m/s^2 its engine
gives at drift speed (81%); a variant 15% lighter on 10% grippier tyres needs 4.1-4.2 m/s^2 on 44 m where it has
3.97, and has no drift there (docs/calibration.md, "Bring your own car").
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any

from driftlab.core.commonroad.equilibrium import PlantDrift, drive_cap_mps2, unlimited_drive_drifts
from driftlab.core.commonroad.family import countersteer_window, sideslip_window
from driftlab.core.commonroad.parameters import commonroad_model_vehicle
from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.errors import NoEquilibriumError
from driftlab.core.vehicle import VehicleParams, pack_params

Window = tuple[float, float] | None

# The sideslips the windows scan (driftlab.core.commonroad.family.sideslip_window) and the coarser grid on which the
# drifts without the engine's cap are looked for: the reason for an empty window, not a window's edges.
SCAN_RAD = (0.20, 0.80)
COARSE_STEP_RAD = 0.05


def overlap(a: Window, b: Window) -> Window:
    if a is None or b is None or max(a[0], b[0]) > min(a[1], b[1]):
        return None
    return max(a[0], b[0]), min(a[1], b[1])


def range_text(window: tuple[float, float]) -> str:
    return f"{window[0]:.2f} rad" if window[0] == window[1] else f"{window[0]:.2f}-{window[1]:.2f} rad"


@dataclass(frozen=True)
class CircleWindow:
    """The sideslips [rad] at which, on a circle of ``radius_m``, the car's main drift countersteers both ways
    (``car``) and the controller's model of it has a drift (``model``); a job needs both (``job``)."""

    radius_m: float
    car: Window
    model: Window

    @property
    def job(self) -> Window:
        return overlap(self.car, self.model)


# Where the model read off the car's tyres has no drift at the car's speed, its front grip is raised in these steps
# until it has (driftlab.core.vehicle.VehicleParams.front_grip_scale), at most to FRONT_GRIP_LIMIT.
FRONT_GRIP_STEP = 0.05
FRONT_GRIP_LIMIT = 2.0


def widest_front_grip(vehicle: VehicleParams) -> VehicleParams:
    """``vehicle`` with the most front grip a fit may give it: where it drifts, some fit does."""
    return replace(vehicle, front_grip_scale=max(vehicle.front_grip_scale, FRONT_GRIP_LIMIT))


@lru_cache(maxsize=64)
def model_window(vehicle: VehicleParams, radius_m: float) -> tuple[float, float] | None:
    """[lowest, highest] |sideslip| from 0.2 to 0.8 (to 0.01 rad) at which ``vehicle`` (the controller's model) has
    a countersteer drift on a circle of ``radius_m`` (None: nowhere)."""
    params = pack_params(vehicle)

    def drifts(sideslip_rad: float) -> bool:
        try:
            drift_equilibrium(radius_m, -sideslip_rad, params)
        except NoEquilibriumError:
            return False
        return True
    return sideslip_window(drifts)


@lru_cache(maxsize=64)
def circle_window(plant_type: Any, vehicle_id: int, radius_m: float) -> CircleWindow:
    """The car's and its model's windows on this circle (the model with its front grip raised as far as a fit raises
    it: where it drifts, some fit does; driftlab.core.commonroad.model_fit)."""
    car = overlap(countersteer_window(plant_type, vehicle_id, radius_m),
                  countersteer_window(plant_type, vehicle_id, radius_m, right=True))
    model = model_window(widest_front_grip(commonroad_model_vehicle(plant_type.car(vehicle_id))), radius_m)
    return CircleWindow(float(radius_m), car, model)


@dataclass(frozen=True)
class DriveShortfall:
    """The drift (of both ways, the one that needs the larger share of its cap) at the sideslip where the car needs
    the least drive beyond what its engine gives: the acceleration input it needs and the cap at its speed."""

    sideslip_rad: float
    drift: PlantDrift
    cap_mps2: float

    def text(self) -> str:
        d = self.drift
        mass_kg = d.drive_n / d.acceleration_mps2  # STD's rear drive force is the mass times the input
        return (f"at {self.sideslip_rad:.2f} rad it needs {d.acceleration_mps2:.2f} m/s^2 of drive ({d.drive_n:.0f} N) "
                f"where the engine gives {self.cap_mps2:.2f} m/s^2 ({mass_kg * self.cap_mps2:.0f} N: "
                f"a_max v_switch / V at {d.speed_mps:.1f} m/s)")


def _coarse_grid() -> list[float]:
    low, high = SCAN_RAD
    count = round((high - low) / COARSE_STEP_RAD)
    return [round(low + i * COARSE_STEP_RAD, 4) for i in range(count + 1)]


@lru_cache(maxsize=64)
def drive_shortfall(plant_type: Any, vehicle_id: int, radius_m: float) -> DriveShortfall | None:
    """Where the car, its engine's cap lifted, countersteers both ways on this circle but needs more drive than the
    cap: the least shortfall (None: its tyres hold no countersteer drift there whatever the drive). STD only: the
    multi-body car's drifts are solved from STD's (driftlab.core.commonroad.mb_equilibrium)."""
    if plant_type.multibody:
        return None
    car = plant_type.car(vehicle_id)
    best: DriveShortfall | None = None
    for sideslip in _coarse_grid():
        mains = [unlimited_drive_drifts(car, radius_m, sideslip, right) for right in (False, True)]
        if not all(family and family[0].countersteer for family in mains):
            continue
        shares = [(f[0].acceleration_mps2 / drive_cap_mps2(car, f[0].speed_mps), f[0]) for f in mains]
        share, drift = max(shares, key=lambda s: s[0])
        if share > 1.0 and (best is None or share < best.drift.acceleration_mps2 / best.cap_mps2):
            best = DriveShortfall(sideslip, drift, drive_cap_mps2(car, drift.speed_mps))
    return best


def no_drift_reason(plant_type: Any, vehicle_id: int, radius_m: float) -> str:
    """Why a job of this car on a circle of ``radius_m`` has no sideslip to drift at: one sentence, for a circle
    whose job window (:func:`circle_window`) is empty."""
    name, window = plant_type.car_name(vehicle_id), circle_window(plant_type, vehicle_id, radius_m)
    scanned = range_text(SCAN_RAD)
    if window.car is not None:
        model = "at no sideslip" if window.model is None else f"only at {range_text(window.model)}"
        return (f"{name} drifts with countersteer both ways on a {radius_m:g} m circle at {range_text(window.car)}, "
                f"but the controller's model of it (the paper's tyre on its mass and geometry) drifts {model}")
    if plant_type.multibody:  # its drifts are not solved without the engine's cap: the cause is not known
        return (f"{name} has no steady drift with countersteer both ways on a {radius_m:g} m circle at any sideslip "
                f"{scanned}")
    shortfall = drive_shortfall(plant_type, vehicle_id, radius_m)
    if shortfall is not None:
        return (f"{name} has no steady drift with countersteer both ways on a {radius_m:g} m circle ({scanned} "
                f"scanned) because holding one needs more rear drive than CommonRoad's engine gives at drift speed: "
                f"{shortfall.text()}")
    return (f"{name} has no steady drift with countersteer both ways on a {radius_m:g} m circle at any sideslip "
            f"{scanned}, even with unlimited drive: its tyres hold no countersteer equilibrium there")


def elsewhere_text(plant_type: Any, vehicle_id: int, radius_m: float, radii_m: tuple[float, ...]) -> str:
    """Where else a job of this car drifts, among the circles ``radii_m`` (e.g. those a calibration tiles)."""
    others = [r for r in radii_m if r != radius_m]
    found = [(r, circle_window(plant_type, vehicle_id, r).job) for r in others]
    drifts = [f"on a {r:g} m circle at {range_text(w)}" for r, w in found if w is not None]
    if drifts:
        return f"it drifts {' and '.join(drifts)}"
    return f"nor on {' or '.join(f'{r:g} m' for r in others)} circles" if others else ""
