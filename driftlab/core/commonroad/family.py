"""A CommonRoad car's steady drifts, whichever model it is (its catalog entry, driftlab.core.plants, knows which
solver: STD's family in full, driftlab.core.commonroad.equilibrium; MB's main drift,
driftlab.core.commonroad.mb_equilibrium): what the drivability check, the controller's model fit and
`driftlab equilibrium` all read.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache
from typing import Any

from driftlab.core.commonroad.equilibrium import PlantDrift, describe_family, frozen_front_wheel_drifts

__all__ = ["PlantDrift", "countersteer_window", "describe_family", "drift_family", "family_summary", "sideslip_window"]


def drift_family(plant_type: Any, vehicle_id: int, radius_m: float, sideslip_rad: float, right: bool = False,
                 friction_scale: float = 1.0, mass_scale: float = 1.0) -> tuple[PlantDrift, ...]:
    """The car's steady drifts at (radius, |sideslip|), left- or ``right``-hand, fastest (the main one) first.
    ``plant_type``: a CommonRoad catalog entry (driftlab.core.plants.CommonRoadPlantType)."""
    return plant_type.drifts(vehicle_id, radius_m, sideslip_rad, right, friction_scale, mass_scale)


@lru_cache(maxsize=64)
def countersteer_window(plant_type: Any, vehicle_id: int, radius_m: float, right: bool = False,
                        friction_scale: float = 1.0, mass_scale: float = 1.0) -> tuple[float, float] | None:
    """[lowest, highest] |sideslip| from 0.2 to 0.8 (to 0.01 rad) at which the car's main drift at this radius
    countersteers (None: nowhere): the drivability check's answer for one sideslip, over the range."""
    def countersteers(sideslip_rad: float) -> bool:
        family = drift_family(plant_type, vehicle_id, radius_m, sideslip_rad, right, friction_scale, mass_scale)
        return bool(family and family[0].countersteer)
    return sideslip_window(countersteers)


def sideslip_window(holds: Callable[[float], bool], low_cent: int = 20, high_cent: int = 80,
                    coarse_cent: int = 5) -> tuple[float, float] | None:
    """[lowest, highest] sideslip [rad] on the 0.01 rad grid over [low, high] where ``holds``, taken as one run:
    a grid ``coarse_cent`` hundredths apart finds it, bisection finds its two edges (about 20 calls of ``holds``
    instead of 61; a run narrower than the coarse grid can be missed)."""
    coarse = list(range(low_cent, high_cent + 1, coarse_cent))
    if coarse[-1] != high_cent:
        coarse.append(high_cent)
    inside = [c for c in coarse if holds(c / 100)]
    if not inside:
        return None
    first, last = coarse.index(inside[0]), coarse.index(inside[-1])
    low = inside[0] if first == 0 else _edge(holds, coarse[first - 1], inside[0])
    high = inside[-1] if last == len(coarse) - 1 else _edge(holds, coarse[last + 1], inside[-1])
    return low / 100, high / 100


def _edge(holds: Callable[[float], bool], outside_cent: int, inside_cent: int) -> int:
    """The grid point nearest ``outside_cent`` (where ``holds`` fails) at which it still holds, by bisection."""
    while abs(outside_cent - inside_cent) > 1:
        middle = (outside_cent + inside_cent) // 2
        if holds(middle / 100):
            inside_cent = middle
        else:
            outside_cent = middle
    return inside_cent


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
