"""A CommonRoad car's steady drifts, whichever model it is (its catalog entry, driftlab.core.plants, knows which
solver: STD's family in full, driftlab.core.commonroad.equilibrium; MB's main drift,
driftlab.core.commonroad.mb_equilibrium): what the drivability check, the controller's model fit and
`driftlab equilibrium` all read.
"""

from __future__ import annotations

from typing import Any

from driftlab.core.commonroad.equilibrium import PlantDrift, describe_family, frozen_front_wheel_drifts

__all__ = ["PlantDrift", "countersteer_window", "describe_family", "drift_family", "family_summary"]


def drift_family(plant_type: Any, vehicle_id: int, radius_m: float, sideslip_rad: float, right: bool = False,
                 friction_scale: float = 1.0, mass_scale: float = 1.0) -> tuple[PlantDrift, ...]:
    """The car's steady drifts at (radius, |sideslip|), left- or ``right``-hand, fastest (the main one) first.
    ``plant_type``: a CommonRoad catalog entry, or its ``plant.model`` name."""
    if isinstance(plant_type, str):
        from driftlab.core.plants import plant_type as entry_of

        plant_type = entry_of(plant_type)
    return plant_type.drifts(vehicle_id, radius_m, sideslip_rad, right, friction_scale, mass_scale)


def countersteer_window(plant_type: Any, vehicle_id: int, radius_m: float, right: bool = False,
                        friction_scale: float = 1.0, mass_scale: float = 1.0) -> list[float] | None:
    """[lowest, highest] |sideslip| on a 0.01 rad grid from 0.2 to 0.8 at which the car's main drift at this radius
    countersteers (None: nowhere): the drivability check's answer for one sideslip, over the range."""
    inside = []
    for i in range(20, 81):
        family = drift_family(plant_type, vehicle_id, radius_m, i / 100, right, friction_scale, mass_scale)
        if family and family[0].countersteer:
            inside.append(i / 100)
    return [inside[0], inside[-1]] if inside else None


def family_summary(plant_type: Any, plant: Any, radius_m: float, beta_rad: float) -> dict[str, Any]:
    """What `driftlab equilibrium --plant commonroad_*` prints for a plant config at (radius, beta): every steady
    drift (``branches``), the main one's values, whether it countersteers, why not, and the window where it does."""
    args = (plant_type, plant.commonroad_vehicle, radius_m)
    scales = (plant.friction_scale, plant.mass_scale)
    family = drift_family(*args, beta_rad, beta_rad > 0, *scales)
    # STD's frozen-front-wheel states, shown apart so that nobody takes them for drifts (equilibrium's docstring).
    frozen = (frozen_front_wheel_drifts(*args[1:], beta_rad, *scales, right=beta_rad > 0)
              if not plant_type.multibody else ())
    out: dict[str, Any] = {"branches": [d.as_dict() for d in family],
                           "frozen_front_wheel_branches": [d.as_dict() for d in frozen],
                           "countersteer": bool(family and family[0].countersteer),
                           "countersteer_window_rad": countersteer_window(*args, beta_rad > 0, *scales)}
    why = describe_family(family, frozen)
    if why is not None:
        out["error"] = f"not drivable at radius {radius_m:g} m, beta {beta_rad:g} rad: {why}"
    if family:
        main = out["branches"][0]
        out.update({k: main[k] for k in ("V", "beta", "r", "delta", "Fxr", "drive_n", "rear_slip", "front_slip")})
    return out
