"""The STD plant's own steady drifts: its drift family at a radius and sideslip.

Unknowns V, delta, omega_f, omega_r and the acceleration input u (beta and r = V / R given); equations: every
derivative of STD zero but the pose's. Unlike the 3-state model's, the family need not be unique (at small
sideslip vehicle 2 has several into-the-turn drifts), so the solve starts from a grid of guesses and returns every
distinct physical solution. The *main* drift is the fastest one (lowest wheelspin): the one a car at drift speed
settles in; an episode can hold the scenario's drift only if the main drift countersteers.

Low-speed, high-wheelspin countersteer "drifts" also solve the equations (vehicle 2, R 44, beta -0.4: V ~10-11 m/s,
rear slip ratio ~-1.5), but only with the front wheel turning backwards: the package sets a wheel's acceleration to
zero once its speed is negative (``d_omega = ... if omega >= 0 else 0``), which drops the front wheel's equation and
leaves a one-parameter family held by a frozen wheel. They are reported apart (``frozen_front_wheel_drifts``), never
taken as the main drift: no car holds a wheel spinning backwards without a torque.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from itertools import product

import numpy as np
from numba import njit

from driftlab.core.commonroad.parameters import (
    CR_ACCEL_MAX,
    CR_CG_TO_FRONT,
    CR_MASS,
    CR_STEER_MAX,
    CR_WHEEL_RADIUS,
    ParameterSet,
    pack_commonroad,
)
from driftlab.core.commonroad.std import (
    N_STD,
    S_OMEGA_F,
    S_OMEGA_R,
    S_SIDESLIP,
    S_SPEED,
    S_STEER,
    S_YAW_RATE,
    acceleration_constraints,
    rear_tyre_state,
    std_derivatives,
)
from driftlab.core.minpack import hybr
from driftlab.core.results_cache import kept_on_disk

_GUESS_SPEEDS_MPS = (8.0, 10.0, 12.0, 14.0, 17.0, 20.0, 23.0)
_GUESS_STEERS_RAD = (-0.9, -0.6, -0.3, 0.0, 0.2)
_GUESS_REAR_SLIPS = (-0.3, -0.8, -1.4, -2.0)


@dataclass(frozen=True)
class PlantDrift:
    """One steady drift of a CommonRoad plant (left-hand: beta < 0, r > 0; right-hand: beta > 0, r < 0); it
    countersteers when delta has the sign of beta. PAC2002's shifts make the car slightly asymmetric: vehicle 2
    at R 44, |beta| 0.5 drifts left at V 20.50, delta -0.264 and right at V 20.40, delta +0.225."""

    speed_mps: float
    sideslip_rad: float
    yaw_rate_radps: float
    steer_rad: float
    rear_force_n: float  # the rear tyres' longitudinal force
    acceleration_mps2: float  # the input u
    drive_n: float  # m u: the drive force the loop commands to hold it
    front_slip: float
    rear_slip: float
    front_wheel_radps: float = 0.0  # negative: held only by the package's frozen wheel (see the module docstring)

    @property
    def countersteer(self) -> bool:
        return self.steer_rad * self.sideslip_rad > 0.0

    def as_dict(self) -> dict[str, float | bool]:
        return {"V": self.speed_mps, "beta": self.sideslip_rad, "r": self.yaw_rate_radps, "delta": self.steer_rad,
                "Fxr": self.rear_force_n, "acceleration_mps2": self.acceleration_mps2, "drive_n": self.drive_n,
                "front_slip": self.front_slip,
                "rear_slip": self.rear_slip, "front_wheel_radps": self.front_wheel_radps,
                "countersteer": self.countersteer}


@njit(cache=True)
def _state(speed, sideslip, radius, steer, omega_f, omega_r):
    """A steady-drift state; the turn's direction follows the sideslip's sign (beta < 0: left, r > 0)."""
    x = np.zeros(N_STD)
    x[S_STEER], x[S_SPEED], x[S_SIDESLIP] = steer, speed, sideslip
    x[S_YAW_RATE] = -math.copysign(speed / radius, sideslip)
    x[S_OMEGA_F], x[S_OMEGA_R] = omega_f, omega_r
    return x


@njit(cache=True)
def _residual(unknowns, radius_m, sideslip_rad, cp):
    """Compiled: a family's solve evaluates it ~10^4 times (the same arithmetic as STD's step, in one call instead
    of a dozen NumPy ones)."""
    speed, steer, omega_f, omega_r, accel = unknowns[0], unknowns[1], unknowns[2], unknowns[3], unknowns[4]
    u = np.empty(2)
    u[0], u[1] = 0.0, accel
    f = std_derivatives(_state(speed, sideslip_rad, radius_m, steer, omega_f, omega_r), u, cp)
    # V, r, beta and both wheel speeds steady; scaled to comparable magnitudes.
    out = np.empty(5)
    out[0], out[1], out[2] = f[S_SPEED], f[S_YAW_RATE], f[S_SIDESLIP]
    out[3], out[4] = f[S_OMEGA_F] * 1e-2, f[S_OMEGA_R] * 1e-2
    return out


def _physical(x, cp) -> bool:
    """A state a car can be in (the front wheel's sign aside: see ``plant_drifts``)."""
    speed, steer, omega_f, omega_r, accel = x
    return (speed > 2.0 and omega_r >= 0.0 and abs(steer) < cp[CR_STEER_MAX]
            and acceleration_constraints(speed, accel, cp) == accel)


Family = tuple[tuple[PlantDrift, ...], tuple[PlantDrift, ...]]


def plant_drifts(radius_m: float, sideslip_rad: float, cp: np.ndarray) -> Family:
    """Every distinct steady drift at ``radius_m`` and ``sideslip_rad`` (beta < 0: left-hand, > 0: right-hand),
    fastest first: (the ones a car can hold, the ones held only by a backward-turning front wheel), from one solve.

    A family takes 140 MINPACK solves (30-60 ms, most of it the solver's calls back into Python), and every process
    that checks or fits a car at a drift needs the same ones (the CLI, the server, a calibration's checks): each is
    solved once and kept on disk for the others (driftlab.core.results_cache)."""
    return _solve(float(radius_m), float(sideslip_rad),  # one compiled signature
                  np.ascontiguousarray(cp, dtype=np.float64))


@kept_on_disk
def _solve(radius_m: float, sideslip_rad: float, cp: np.ndarray) -> Family:
    found: list[np.ndarray] = []
    wheel = cp[CR_WHEEL_RADIUS]
    side = -1.0 if sideslip_rad < 0 else 1.0
    for speed, steer, slip in product(_GUESS_SPEEDS_MPS, _GUESS_STEERS_RAD, _GUESS_REAR_SLIPS):
        ground = speed * math.cos(sideslip_rad) / wheel
        guess = np.array([speed, -side * steer, ground, ground * (1.0 - slip), 3.0])
        x, converged = hybr(_residual, guess, (radius_m, sideslip_rad, cp), xtol=1e-12)
        if not converged or np.max(np.abs(_residual(x, radius_m, sideslip_rad, cp))) > 1e-7:
            continue
        if not _physical(x, cp):
            continue
        if all(np.max(np.abs(x[:2] - f[:2])) > 1e-5 for f in found):
            found.append(x)
    drifts = sorted((_drift(x, radius_m, sideslip_rad, cp) for x in found), key=lambda d: -d.speed_mps)
    return (tuple(d for d in drifts if d.front_wheel_radps >= 0.0),
            tuple(d for d in drifts if d.front_wheel_radps < 0.0))


def _drift(x, radius_m, sideslip_rad, cp) -> PlantDrift:
    speed, steer, omega_f, omega_r, accel = (float(v) for v in x)
    state = _state(speed, sideslip_rad, radius_m, steer, omega_f, omega_r)
    rear_slip, rear_force = rear_tyre_state(state, accel, cp)
    u_wf = max(0.0, speed * math.cos(sideslip_rad) * math.cos(steer)
               + (speed * math.sin(sideslip_rad) + cp[CR_CG_TO_FRONT] * state[S_YAW_RATE]) * math.sin(steer))
    front_slip = 1.0 - cp[CR_WHEEL_RADIUS] * omega_f / max(u_wf, 0.1)
    return PlantDrift(speed, sideslip_rad, float(state[S_YAW_RATE]), steer, float(rear_force), accel,
                      float(cp[CR_MASS] * accel),
                      float(front_slip), float(rear_slip), omega_f)


@lru_cache(maxsize=256)
def _family(car: int | ParameterSet, radius_m: float, sideslip_rad: float, friction_scale: float,
            mass_scale: float, right: bool) -> Family:
    cp = pack_commonroad(car, friction_scale=friction_scale, mass_scale=mass_scale)
    return plant_drifts(radius_m, abs(sideslip_rad) if right else -abs(sideslip_rad), cp)


def commonroad_drifts(car: int | ParameterSet, radius_m: float, sideslip_rad: float,
                      friction_scale: float = 1.0, mass_scale: float = 1.0,
                      right: bool = False) -> tuple[PlantDrift, ...]:
    """The drift family of a CommonRoad car (a vehicle id or a ParameterSet) at a radius and |sideslip|
    (left-hand, or ``right``-hand), fastest first."""
    return _family(car, radius_m, sideslip_rad, friction_scale, mass_scale, right)[0]


def frozen_front_wheel_drifts(car: int | ParameterSet, radius_m: float, sideslip_rad: float,
                              friction_scale: float = 1.0, mass_scale: float = 1.0,
                              right: bool = False) -> tuple[PlantDrift, ...]:
    """The steady states that the package's frozen backward-turning front wheel holds (module docstring), fastest
    first: what a solver that does not check the wheel's sign reports as low-speed, high-wheelspin drifts."""
    return _family(car, radius_m, sideslip_rad, friction_scale, mass_scale, right)[1]


@lru_cache(maxsize=256)
def unlimited_drive_drifts(car: int | ParameterSet, radius_m: float, sideslip_rad: float,
                           right: bool = False) -> tuple[PlantDrift, ...]:
    """:func:`commonroad_drifts` with no cap on the drive (the package's a_max v_switch / V lifted): the drifts the
    car's tyres can hold, whatever its engine gives. Where the car has none that countersteers but these do, its
    engine is what it lacks (driftlab.core.commonroad.window)."""
    cp = pack_commonroad(car)
    cp[CR_ACCEL_MAX] = math.inf  # acceleration_constraints then passes any drive (and braking: none in a drift)
    return plant_drifts(radius_m, abs(sideslip_rad) if right else -abs(sideslip_rad), cp)[0]


def drive_cap_mps2(car: int | ParameterSet, speed_mps: float) -> float:
    """The most acceleration input STD applies at ``speed_mps`` (the package's own rule: a_max, and a_max v_switch
    / V above v_switch); in a steady drift the rear tyres' drive force is the mass times it."""
    return float(acceleration_constraints(speed_mps, math.inf, pack_commonroad(car)))


def describe_family(drifts: tuple[PlantDrift, ...], frozen: tuple[PlantDrift, ...] = ()) -> str | None:
    """None when the main (fastest) drift countersteers; else why the scenario's drift cannot be held (naming the
    ``frozen`` front-wheel countersteer states when given, so that nobody mistakes them for a drift to hold)."""
    low = next((d for d in drifts[1:] if d.countersteer), None)
    frozen_low = next((d for d in frozen if d.countersteer), None)
    if drifts and drifts[0].countersteer:
        return None
    if not drifts:
        reason = "the plant has no steady drift at all there"
    else:
        main = drifts[0]
        reason = (f"the plant's drift near drift speed steers into the turn (V {main.speed_mps:.2f} m/s, delta "
                  f"{main.steer_rad:+.3f} rad): no countersteer drift to hold")
    if low is not None:
        reason += (f"; the only countersteer drift there is a low-speed, high-wheelspin one (V {low.speed_mps:.2f} "
                   f"m/s, delta {low.steer_rad:+.3f} rad, rear slip ratio {low.rear_slip:.2f})")
    elif frozen_low is not None:
        reason += (f"; the only countersteer drifts there are low-speed, high-wheelspin ones (e.g. V "
                   f"{frozen_low.speed_mps:.2f} m/s, delta {frozen_low.steer_rad:+.3f} rad, rear slip ratio "
                   f"{frozen_low.rear_slip:.2f}), and they hold only with the front wheel turning backwards "
                   f"({frozen_low.front_wheel_radps:.1f} rad/s), which the package freezes: not a drift a car can hold")
    return reason

