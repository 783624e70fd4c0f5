"""The MB plant's steady drift (locked rear differential): the multi-body state that holds a constant V, beta and
r = V / R, found from the STD car's drift as a start.

Unknowns: V, delta, the acceleration input, the front wheel speeds, the (common) rear wheel speed, and the
suspension's roll, pitch, heave and axle states; equations: every derivative of MB zero but the pose's, the rear
wheels' mean (one shaft). Vehicle 2 at R 44, beta -0.5: V 20.39 m/s, delta -0.411 rad, drive 3248 N, rear slip
ratio -0.35, body roll -0.135 rad (STD: 20.50, -0.264, 3636 N).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from driftlab.core.commonroad.equilibrium import PlantDrift, commonroad_drifts
from driftlab.core.commonroad.mb import R_W, A, B, M, mb_derivatives, pack_mb
from driftlab.core.commonroad.parameters import ParameterSet, package_parameters
from driftlab.core.minpack import hybr

_SUSPENSION = [6, 8, 11, 13, 16, 18, 21, 27, 28]  # roll, pitch, heave, front/rear axle roll and heave, compliance
_STEADY = [3, 5, 10, 15, 20, 7, 9, 12, 14, 17, 19, 22, 23, 24]
_GUESSES = ((0.0, 0.0, 1.5), (-2.0, 0.1, 1.8), (0.0, 0.1, 1.2), (-1.0, 0.05, 1.5), (1.0, -0.05, 1.3))


def _state(u, radius_m, sideslip_rad, cp):
    speed, steer = u[0], u[1]
    x = np.zeros(29)
    x[2], x[3], x[10] = steer, speed * math.cos(sideslip_rad), speed * math.sin(sideslip_rad)
    x[5] = -math.copysign(speed / radius_m, sideslip_rad)
    x[23], x[24], x[25], x[26] = u[3], u[4], u[5], u[5]
    x[_SUSPENSION] = u[6:15]
    x[15], x[20] = x[10] + cp[A] * x[5], x[10] - cp[B] * x[5]  # the axles move with the body
    return x


def _residual(u, radius_m, sideslip_rad, cp):
    f = mb_derivatives(_state(u, radius_m, sideslip_rad, cp), np.array([0.0, u[2]]), cp)
    out = np.empty(15)
    out[:14] = f[_STEADY]
    out[14] = 0.5 * (f[25] + f[26])
    out[12:] *= 1e-2  # wheel accelerations to the scale of the others
    return out


def mb_main_drift(car: int | ParameterSet, radius_m: float, sideslip_rad: float, right: bool = False,
                  friction_scale: float = 1.0, mass_scale: float = 1.0) -> PlantDrift | None:
    """The MB car's drift nearest the STD car's (the fastest physical one found), or None."""
    found = mb_steady_state(car, radius_m, sideslip_rad, right, friction_scale, mass_scale)
    return None if found is None else found[0]


def _physical(x, converged: bool, radius_m: float, beta: float, cp) -> bool:
    return bool(converged and np.max(np.abs(_residual(x, radius_m, beta, cp))) < 1e-8 and x[0] > 2.0
                and min(x[3], x[4], x[5]) >= 0.0)


def _solve(guess, radius_m: float, beta: float, cp):
    x, converged = hybr(_residual, guess, (radius_m, beta, cp), xtol=1e-13)
    return x if _physical(x, converged, radius_m, beta, cp) else None


def _solve_from_std(car: int | ParameterSet, radius_m: float, beta: float, cp, friction_scale: float,
                    mass_scale: float, right: bool) -> list[np.ndarray]:
    """MB's drifts found from the STD car's drift at the same sideslip as a start."""
    from vehiclemodels.init_mb import init_mb

    std = commonroad_drifts(car, radius_m, abs(beta), friction_scale, mass_scale, right=right)
    if not std:
        return []
    start = std[0]
    rest = np.array(init_mb([0, 0, start.steer_rad, start.speed_mps, 0, start.yaw_rate_radps, beta],
                            package_parameters(car)))[_SUSPENSION]
    found = []
    for dv, dd, spin in _GUESSES:
        speed = start.speed_mps + dv
        rolling = speed * math.cos(beta) / cp[R_W]
        guess = np.r_[speed, start.steer_rad - math.copysign(dd, beta), start.acceleration_mps2, rolling, rolling,
                      rolling * spin, rest]
        x = _solve(guess, radius_m, beta, cp)
        if x is not None:
            found.append(x)
    return found


# Where the start from STD's drift misses MB's drift, the family is walked from this sideslip (the paper's), in
# steps of _WALK_RAD.
_ANCHOR_RAD = 0.5
_WALK_RAD = 0.01


@lru_cache(maxsize=512)
def _drift_unknowns(car: int | ParameterSet, radius_m: float, abs_sideslip_rad: float, right: bool,
                    friction_scale: float, mass_scale: float) -> np.ndarray | None:
    """The solved unknowns of MB's drift (see _state), or None.

    Started from STD's drift at the same sideslip (the fastest physical solution found); where that start misses
    it, followed from the neighbouring sideslip one _WALK_RAD nearer _ANCHOR_RAD, itself solved the same way. The
    family is continuous, but the start from STD misses it at some sideslips (vehicle 2 at 44 m: 0.46, 0.48, 0.55,
    0.6 rad), and "no drift" there would be false. Cached: a sweep over sideslips walks each step once.
    """
    cp = pack_mb(car, friction_scale=friction_scale, mass_scale=mass_scale)
    beta = abs_sideslip_rad if right else -abs_sideslip_rad
    found = _solve_from_std(car, radius_m, beta, cp, friction_scale, mass_scale, right)
    if found:
        return max(found, key=lambda s: s[0])
    if abs(abs_sideslip_rad - _ANCHOR_RAD) < 0.5 * _WALK_RAD:
        return None
    nearer = round(abs_sideslip_rad + math.copysign(_WALK_RAD, _ANCHOR_RAD - abs_sideslip_rad), 6)
    start = _drift_unknowns(car, radius_m, nearer, right, friction_scale, mass_scale)
    if start is None:
        return None
    for k in range(1, 5):  # quarter steps: from 0.67 to 0.68 rad one step, or two, lands on a wheel at -7e9 rad/s
        start = _solve(start, radius_m, math.copysign(nearer + (abs_sideslip_rad - nearer) * k / 4, beta), cp)
        if start is None:
            return None
    return start


@lru_cache(maxsize=64)
def mb_steady_state(car: int | ParameterSet, radius_m: float, sideslip_rad: float, right: bool = False,
                    friction_scale: float = 1.0, mass_scale: float = 1.0
                    ) -> tuple[PlantDrift, np.ndarray, float] | None:
    """(the drift, MB's full 29-state vector in it, the acceleration input), or None."""
    cp = pack_mb(car, friction_scale=friction_scale, mass_scale=mass_scale)
    beta = abs(sideslip_rad) if right else -abs(sideslip_rad)
    x = _drift_unknowns(car, radius_m, abs(sideslip_rad), right, friction_scale, mass_scale)
    if x is None:
        return None
    speed, steer, accel = float(x[0]), float(x[1]), float(x[2])
    rear_slip = 1.0 - cp[R_W] * x[5] / (speed * math.cos(beta))
    drift = PlantDrift(speed, beta, -math.copysign(speed / radius_m, beta), steer, float(cp[M] * accel), accel,
                       float(cp[M] * accel),
                       float(1.0 - cp[R_W] * x[3] / (speed * math.cos(beta))), float(rear_slip),
                       front_wheel_radps=float(0.5 * (x[3] + x[4])))  # the two front wheels' mean
    return drift, _state(x, radius_m, beta, cp), accel
