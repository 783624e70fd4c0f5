"""CommonRoad parameter sets, packed for the compiled STD port (named indices, never bare numbers).

The package's parameter objects are slow to read (attribute access costs microseconds): they are read once here.
Vehicle 1 (Ford Escort) is front-wheel drive (``T_se`` 1): a power-on drift needs a driven rear axle, so it is
refused. Vehicles 2 (BMW 320i) and 3 (VW Vanagon) drive the rear axle.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass, replace
from functools import lru_cache

import numpy as np

from driftlab.core.errors import ConfigError

EXTRA = "pip install 'driftlab[commonroad]'"
VEHICLE_NAMES = {1: "Ford Escort", 2: "BMW 320i", 3: "VW Vanagon"}
DRIVABLE_VEHICLES = (2, 3)

# Tyre coefficients of PAC2002 as vehiclemodels' TireParameters names them, in packed order.
TYRE_KEYS = ("p_cx1", "p_dx1", "p_dx3", "p_ex1", "p_kx1", "p_hx1", "p_vx1", "r_bx1", "r_bx2", "r_cx1", "r_ex1",
             "r_hx1", "p_cy1", "p_dy1", "p_dy3", "p_ey1", "p_ky1", "p_hy1", "p_hy3", "p_vy1", "p_vy3", "r_by1",
             "r_by2", "r_by3", "r_cy1", "r_ey1", "r_hy1", "r_vy1", "r_vy3", "r_vy4", "r_vy5", "r_vy6")
(CR_MASS, CR_YAW_INERTIA, CR_CG_TO_FRONT, CR_CG_TO_REAR, CR_CG_HEIGHT, CR_WHEEL_RADIUS, CR_WHEEL_INERTIA,
 CR_BRAKE_SPLIT, CR_DRIVE_SPLIT, CR_STEER_MIN, CR_STEER_MAX, CR_STEER_RATE_MIN, CR_STEER_RATE_MAX, CR_SPEED_MIN,
 CR_SPEED_MAX, CR_SPEED_SWITCH, CR_ACCEL_MAX) = range(17)
CR_TYRE = 17  # TYRE_KEYS follow from here
N_CR_PARAMS = CR_TYRE + len(TYRE_KEYS)
T = {name: CR_TYRE + i for i, name in enumerate(TYRE_KEYS)}  # packed index of each tyre coefficient


def _vehiclemodels():
    try:
        import vehiclemodels.vehicle_parameters as parameters
    except ImportError:
        raise ConfigError(f"plant.model: the CommonRoad plants need the optional extra: {EXTRA}",
                          field="plant.model") from None
    return parameters


def check_vehicle(vehicle_id: int) -> None:
    if vehicle_id not in VEHICLE_NAMES:
        raise ConfigError(f"plant.commonroad_vehicle must be one of 1, 2, 3, got {vehicle_id!r}",
                          field="plant.commonroad_vehicle")
    if vehicle_id not in DRIVABLE_VEHICLES:
        raise ConfigError("plant.commonroad_vehicle 1 (Ford Escort) is front-wheel drive: a power-on drift needs "
                          "a driven rear axle; choose 2 (BMW 320i) or 3 (VW Vanagon)", field="plant.commonroad_vehicle")


@dataclass(frozen=True)
class ParameterSet:
    """A car of one's own built on a CommonRoad parameter set: the package's vehicle ``vehicle_id`` with some of
    its parameters scaled. ``scales`` pairs a parameter's name in the package's object (``"m"``, ``"h_s"``,
    ``"tire.p_dy1"``, ``"steering.max"``) with its factor. Everything that reads a car's parameters takes one of
    these or a bare vehicle id (the package's set as published); both are hashable, so the drift solvers cache by
    them.
    """

    vehicle_id: int
    scales: tuple[tuple[str, float], ...] = ()

    def __post_init__(self) -> None:
        check_vehicle(self.vehicle_id)
        base = _published(self.vehicle_id)
        for name, factor in self.scales:
            value = _lookup(base, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ConfigError(f"{name!r} names no number of CommonRoad's parameter set {self.vehicle_id} (a "
                                  f"field of vehiclemodels' VehicleParameters: 'm', 'I_z', 'h_s', 'tire.p_dy1', ...)",
                                  field="plant.model")
            if not (isinstance(factor, int | float) and 0.0 < factor < float("inf")):
                raise ConfigError(f"the scale of {name!r} must be a positive finite number, got {factor!r}",
                                  field="plant.model")

    def parameters(self):
        """The package's parameter object with the scales applied."""
        p = _published(self.vehicle_id)
        for name, factor in self.scales:
            p = _scaled(p, name.split("."), factor)
        return p


def _lookup(obj, dotted: str):
    for part in dotted.split("."):
        if not is_dataclass(obj) or part not in {f.name for f in fields(obj)}:
            return None
        obj = getattr(obj, part)
    return obj


def _scaled(obj, path: list[str], factor: float):
    head, rest = path[0], path[1:]
    value = getattr(obj, head)
    return replace(obj, **{head: _scaled(value, rest, factor) if rest else value * factor})


@lru_cache(maxsize=8)
def _published(vehicle_id: int):
    return _vehiclemodels().setup_vehicle_parameters(vehicle_id=vehicle_id)


@lru_cache(maxsize=16)
def package_parameters(car: int | ParameterSet):
    """The package's parameter object of a car: vehicle id 1, 2 or 3 as published, or a :class:`ParameterSet`."""
    return car.parameters() if isinstance(car, ParameterSet) else _published(car)


@lru_cache(maxsize=16)
def _base_vector(car: int | ParameterSet) -> tuple[float, ...]:
    p = package_parameters(car)
    v = np.zeros(N_CR_PARAMS)
    v[CR_MASS], v[CR_YAW_INERTIA], v[CR_CG_TO_FRONT], v[CR_CG_TO_REAR] = p.m, p.I_z, p.a, p.b
    v[CR_CG_HEIGHT], v[CR_WHEEL_RADIUS], v[CR_WHEEL_INERTIA] = p.h_s, p.R_w, p.I_y_w
    v[CR_BRAKE_SPLIT], v[CR_DRIVE_SPLIT] = p.T_sb, p.T_se
    v[CR_STEER_MIN], v[CR_STEER_MAX] = p.steering.min, p.steering.max
    v[CR_STEER_RATE_MIN], v[CR_STEER_RATE_MAX] = p.steering.v_min, p.steering.v_max
    v[CR_SPEED_MIN], v[CR_SPEED_MAX] = p.longitudinal.v_min, p.longitudinal.v_max
    v[CR_SPEED_SWITCH], v[CR_ACCEL_MAX] = p.longitudinal.v_switch, p.longitudinal.a_max
    for name in TYRE_KEYS:
        v[T[name]] = getattr(p.tire, name)
    return tuple(float(x) for x in v)


def pack_commonroad(car: int | ParameterSet, *, friction_scale: float = 1.0, mass_scale: float = 1.0,
                    steer_rate_radps: float | None = None) -> np.ndarray:
    """The packed parameters of a car (a vehicle id or a :class:`ParameterSet`), with the plant's friction
    (PAC2002's peak coefficients p_dx1, p_dy1: the slip stiffnesses stay) and mass (with yaw inertia) scaled, and
    the steering rate limit replaced (``None``: the package's own, 0.4 rad/s for every vehicle, at which no drift
    can be caught)."""
    v = np.array(_base_vector(car))
    v[T["p_dx1"]] *= friction_scale
    v[T["p_dy1"]] *= friction_scale
    v[CR_MASS] *= mass_scale
    v[CR_YAW_INERTIA] *= mass_scale
    if steer_rate_radps is not None:
        v[CR_STEER_RATE_MIN], v[CR_STEER_RATE_MAX] = -steer_rate_radps, steer_rate_radps
    return v


def steering_reach_rad(car: int | ParameterSet) -> float:
    """How far the car steers either way [rad] (the package's ``steering.min``/``max``: 1.066 for the BMW 320i,
    1.023 for the VW Vanagon), within what an MPC may be given (driftlab.core.mpc.MpcConfig)."""
    from driftlab.core.mpc_config import STEER_LIMIT_RANGE_RAD

    p = package_parameters(car)
    reach = min(abs(float(p.steering.min)), float(p.steering.max))
    return min(max(reach, STEER_LIMIT_RANGE_RAD[0]), STEER_LIMIT_RANGE_RAD[1])


def commonroad_model_vehicle(car: int | ParameterSet):
    """The controller's model of a CommonRoad car: mass, geometry, yaw inertia and CG height of the parameter set,
    and the paper's simplified Pacejka (mu, B, C) read off PAC2002's pure lateral formula at zero camber:
    mu = p_dy1, C = p_cy1, B = K / (C D) per unit load = |p_ky1| / (p_cy1 p_dy1) (PAC2002's E, -0.0075 for
    vehicle 2, and its shifts, zero at zero camber, are what the simplified form leaves out).
    """
    from driftlab.core.vehicle import VehicleParams

    p = package_parameters(car)
    tyre = p.tire
    return VehicleParams(mass_kg=float(p.m), yaw_inertia_kgm2=float(p.I_z), cg_to_front_m=float(p.a),
                         cg_to_rear_m=float(p.b), friction=float(tyre.p_dy1), tyre_c=float(tyre.p_cy1),
                         tyre_b=float(abs(tyre.p_ky1) / (tyre.p_cy1 * tyre.p_dy1)), cg_height_m=float(p.h_s),
                         gravity_mps2=9.81)
