"""Single-track drift dynamics: the paper's 3-state model (Zhou et al. 2025, eq. 1-6).

One compiled function, :func:`drift_derivatives`, serves the controller's model, its linearization,
the equilibrium solver and the plant. The plant switches on what the paper's model leaves out
(rear friction circle, longitudinal load transfer) through flags in the packed parameter vector; with the
flags off it *is* the paper's model.

Sign convention (docs/reference.md, The car): y to the left, sideslip ``beta = atan(vy / vx)``, yaw rate and
steering positive to the left, tyre slip = wheel velocity direction minus wheel heading, tyre force opposes
slip. A left-hand drift has r > 0, beta < 0 and countersteer delta < 0.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np
from numba import njit

from driftlab.core.errors import ConfigError
from driftlab.core.validation import check_ranges

# Layout of the packed parameter vector the compiled functions read (named, never bare numbers).
P_MASS = 0
P_YAW_INERTIA = 1
P_CG_TO_FRONT = 2
P_CG_TO_REAR = 3
P_FRICTION = 4
P_TYRE_B = 5
P_TYRE_C = 6
P_GRAVITY = 7
P_CG_HEIGHT = 8
P_FRICTION_CIRCLE = 9
P_LOAD_TRANSFER = 10
P_STEER_OFFSET = 11
P_DRIVE_OFFSET = 12
P_FRONT_GRIP = 13
P_REAR_COUPLING = 14
N_PARAMS = 15

# Fixed-point passes for the load-transfer loop (loads depend on Fyf, which depends on loads). The loop
# gain is roughly h/L * mu * |sin(delta)| ~ 0.05, so each pass shrinks the error about twentyfold.
_LOAD_TRANSFER_PASSES = 3


@dataclass(frozen=True)
class VehicleParams:
    """A car for the single-track model. Defaults: the Table-I fit of docs/reference.md (The car).

    Attributes:
        mass_kg: vehicle mass m [kg].
        yaw_inertia_kgm2: yaw moment of inertia Iz [kg m^2].
        cg_to_front_m: distance a from the CG to the front axle [m].
        cg_to_rear_m: distance b from the CG to the rear axle [m].
        friction: tyre-road friction coefficient mu [-].
        tyre_b: simplified Pacejka stiffness factor B [1/rad].
        tyre_c: simplified Pacejka shape factor C [-].
        cg_height_m: CG height above ground [m]; used only where load transfer is switched on.
        gravity_mps2: gravitational acceleration g [m/s^2].
        steer_offset_rad: the model's tyres see the steering command plus this, toward the countersteer of a
            left-hand drift (mirrored for a right-hand one) [rad]; 0 in the paper.
        drive_offset_n: the model's rear tyre sees the drive command plus this [N]; 0 in the paper.
            The two offsets let a model whose tyres differ from a car's (PAC2002 with combined slip and wheel
            speeds, say) have its drift equilibrium at that car's measured steady drift
            (driftlab.core.commonroad.model_fit): the MPC then
            linearizes and regulates about the drift the car actually holds. A plant never has them.
        steer_offset_right_rad, drive_offset_right_n: the same for the right-hand drift, in its mirror image
            (a car whose tyres are not symmetric, as PAC2002's shifts make them, drifts differently each way;
            a symmetric one has them equal to the left-hand ones).
        front_grip_scale: the front tyre's peak force is friction x this x its load (1 in the paper): where
            on its curve the front tyre sits in the drift, hence how strongly the yaw rate answers the steering
            (fitted to a car's measured response, driftlab.core.commonroad.steering_gain).
        rear_friction_circle: the rear drive force takes its share of the rear tyre's grip, the lateral peak
            shrinking to sqrt((mu Fzr)^2 - Fxr^2) (off in the paper). A car whose rear wheels spin under the drive
            (the multi-body car's) answers more drive with more yaw rate and sideslip; the paper's model answers
            with less, and an MPC that uses the drive to hold the sideslip then pushes the wrong way
            (driftlab.core.commonroad.model_fit).
        rear_coupling: how much of the drive force the rear friction circle takes, sqrt((mu Fzr)^2 - (k Fxr)^2)
            (1: the whole circle); a model's, fitted to a car's yaw answer to a drive step
            (driftlab.core.commonroad.model_fit). Only with ``rear_friction_circle``.
    """

    mass_kg: float = 1844.7
    yaw_inertia_kgm2: float = 2300.0
    cg_to_front_m: float = 1.39
    cg_to_rear_m: float = 1.0008
    friction: float = 0.85
    tyre_b: float = 11.697
    tyre_c: float = 1.4478
    cg_height_m: float = 0.45
    gravity_mps2: float = 9.81
    steer_offset_rad: float = 0.0
    drive_offset_n: float = 0.0
    steer_offset_right_rad: float = 0.0
    drive_offset_right_n: float = 0.0
    front_grip_scale: float = 1.0
    rear_friction_circle: bool = False
    rear_coupling: float = 1.0

    def __post_init__(self) -> None:
        limits = {
            "mass_kg": (100.0, 20000.0),
            "yaw_inertia_kgm2": (10.0, 50000.0),
            "cg_to_front_m": (0.1, 5.0),
            "cg_to_rear_m": (0.1, 5.0),
            "friction": (0.05, 2.0),
            "tyre_b": (0.5, 50.0),
            "tyre_c": (0.5, 2.5),
            "cg_height_m": (0.0, 2.0),
            "gravity_mps2": (1.0, 30.0),
            "steer_offset_rad": (-0.5, 0.5),
            "drive_offset_n": (-10000.0, 10000.0),
            "steer_offset_right_rad": (-0.5, 0.5),
            "drive_offset_right_n": (-10000.0, 10000.0),
            "front_grip_scale": (0.2, 5.0),
            "rear_coupling": (0.0, 1.0),
        }
        check_ranges(self, "vehicle", limits)
        if not isinstance(self.rear_friction_circle, bool):
            raise ConfigError(f"vehicle.rear_friction_circle must be true or false, got {self.rear_friction_circle!r}",
                              field="vehicle.rear_friction_circle")

    @property
    def wheelbase_m(self) -> float:
        return self.cg_to_front_m + self.cg_to_rear_m

    def static_axle_loads_n(self) -> tuple[float, float]:
        """Static normal loads (Fzf, Fzr) [N] (paper: Fzf = m g b / L, Fzr = m g a / L)."""
        weight = self.mass_kg * self.gravity_mps2
        return weight * self.cg_to_rear_m / self.wheelbase_m, weight * self.cg_to_front_m / self.wheelbase_m

    def scaled(self, **factors: float) -> VehicleParams:
        """This car with fields multiplied by factors, e.g. ``scaled(friction=1.1, mass_kg=1.05)``."""
        values = asdict(self)
        for name, factor in factors.items():
            if name not in values:
                raise ConfigError(f"vehicle has no field {name!r}")
            values[name] = values[name] * factor
        return replace(self, **values)


def pack_params(
    vehicle: VehicleParams, *, friction_circle: bool = False, load_transfer: bool = False, right: bool = False,
    mirrored: bool = False
) -> np.ndarray:
    """The float64 parameter vector read by the compiled dynamics.

    With both flags off (and the vehicle's ``rear_friction_circle``) this is the paper's 3-state model.
    ``right``: with the right-hand drift's offsets; ``mirrored``: for states of a right-hand drift itself (the
    steering offset, given in the left-hand form, flips sign), not for its mirror image, which drift_equilibrium
    solves.
    """
    p = np.zeros(N_PARAMS)
    p[P_MASS] = vehicle.mass_kg
    p[P_YAW_INERTIA] = vehicle.yaw_inertia_kgm2
    p[P_CG_TO_FRONT] = vehicle.cg_to_front_m
    p[P_CG_TO_REAR] = vehicle.cg_to_rear_m
    p[P_FRICTION] = vehicle.friction
    p[P_TYRE_B] = vehicle.tyre_b
    p[P_TYRE_C] = vehicle.tyre_c
    p[P_GRAVITY] = vehicle.gravity_mps2
    p[P_CG_HEIGHT] = vehicle.cg_height_m
    p[P_FRICTION_CIRCLE] = 1.0 if (friction_circle or vehicle.rear_friction_circle) else 0.0
    p[P_LOAD_TRANSFER] = 1.0 if load_transfer else 0.0
    steer_offset = vehicle.steer_offset_right_rad if right else vehicle.steer_offset_rad
    p[P_STEER_OFFSET] = -steer_offset if mirrored else steer_offset
    p[P_DRIVE_OFFSET] = vehicle.drive_offset_right_n if right else vehicle.drive_offset_n
    p[P_FRONT_GRIP] = vehicle.front_grip_scale
    p[P_REAR_COUPLING] = vehicle.rear_coupling
    return p


@njit(cache=True)
def pacejka_lateral_force(slip_rad, peak_force_n, tyre_b, tyre_c):
    """Simplified Pacejka lateral force (paper eq. 4): Fy = -Fpeak sin(C atan(B alpha)) [N]."""
    return -peak_force_n * math.sin(tyre_c * math.atan(tyre_b * slip_rad))


@njit(cache=True)
def slip_angles(speed_mps, sideslip_rad, yaw_rate_radps, steer_rad, p):
    """Front and rear slip angles alpha_f, alpha_r [rad] (paper eq. 5-6).

    atan2 equals the paper's atan(vy / vx) while the car moves forward (vx > 0) and stays defined past
    90 degrees of sideslip, where a spinning plant may go before the episode flags it.
    """
    vx = speed_mps * math.cos(sideslip_rad)
    vy = speed_mps * math.sin(sideslip_rad)
    alpha_f = math.atan2(vy + p[P_CG_TO_FRONT] * yaw_rate_radps, vx) - steer_rad
    alpha_r = math.atan2(vy - p[P_CG_TO_REAR] * yaw_rate_radps, vx)
    return alpha_f, alpha_r


@njit(cache=True)
def tyre_forces(speed_mps, sideslip_rad, yaw_rate_radps, steer_rad, drive_force_n, p):
    """Tyre forces (Fyf, Fyr, Fxr) [N] acting on the body.

    Paper: static loads, independent rear Fx and Fy. With P_LOAD_TRANSFER the axle loads shift by
    m * ax * h / L, ax being the body-frame longitudinal acceleration (sum of x forces / m). With
    P_FRICTION_CIRCLE the rear drive force is capped at mu Fzr and the rear lateral peak shrinks to
    sqrt((mu Fzr)^2 - Fxr^2) (the coupling used by Hindiyeh & Gerdes 2014).
    """
    m = p[P_MASS]
    a = p[P_CG_TO_FRONT]
    b = p[P_CG_TO_REAR]
    mu = p[P_FRICTION]
    wheelbase = a + b
    weight = m * p[P_GRAVITY]
    alpha_f, alpha_r = slip_angles(speed_mps, sideslip_rad, yaw_rate_radps, steer_rad, p)
    fzf = weight * b / wheelbase
    fzr = weight * a / wheelbase
    fxr = drive_force_n
    passes = _LOAD_TRANSFER_PASSES if p[P_LOAD_TRANSFER] > 0.5 else 1
    fyf = 0.0
    fyr = 0.0
    for _ in range(passes):
        fxr = drive_force_n
        rear_peak = mu * fzr
        if p[P_FRICTION_CIRCLE] > 0.5:
            cap = 0.999 * rear_peak
            fxr = min(max(drive_force_n, -cap), cap)
            coupled = p[P_REAR_COUPLING] * fxr  # exactly fxr at the whole circle's coupling 1
            rear_peak = math.sqrt(rear_peak * rear_peak - coupled * coupled)
        fyf = pacejka_lateral_force(alpha_f, mu * p[P_FRONT_GRIP] * fzf, p[P_TYRE_B], p[P_TYRE_C])
        fyr = pacejka_lateral_force(alpha_r, rear_peak, p[P_TYRE_B], p[P_TYRE_C])
        if p[P_LOAD_TRANSFER] > 0.5:
            transfer = (fxr - fyf * math.sin(steer_rad)) * p[P_CG_HEIGHT] / wheelbase
            fzf = max(weight * b / wheelbase - transfer, 0.0)
            fzr = max(weight * a / wheelbase + transfer, 0.0)
    return fyf, fyr, fxr


@njit(cache=True)
def drift_derivatives(speed_mps, sideslip_rad, yaw_rate_radps, steer_rad, drive_force_n, p):
    """Time derivatives (Vdot, betadot, rdot) of the 3-state drift model (paper eq. 1-3)."""
    steer_rad = steer_rad + p[P_STEER_OFFSET]  # exact for the paper's model (offsets 0)
    drive_force_n = drive_force_n + p[P_DRIVE_OFFSET]
    fyf, fyr, fxr = tyre_forces(speed_mps, sideslip_rad, yaw_rate_radps, steer_rad, drive_force_n, p)
    m = p[P_MASS]
    speed_dot = (-fyf * math.sin(steer_rad - sideslip_rad) + fyr * math.sin(sideslip_rad)
                 + fxr * math.cos(sideslip_rad)) / m
    sideslip_dot = (fyf * math.cos(steer_rad - sideslip_rad) + fyr * math.cos(sideslip_rad)
                    - fxr * math.sin(sideslip_rad)) / (m * speed_mps) - yaw_rate_radps
    yaw_rate_dot = (p[P_CG_TO_FRONT] * fyf * math.cos(steer_rad) - p[P_CG_TO_REAR] * fyr) / p[P_YAW_INERTIA]
    return speed_dot, sideslip_dot, yaw_rate_dot


@njit(cache=True)
def drift_derivatives_vec(state, inputs, p):
    """:func:`drift_derivatives` on arrays: state [V, beta, r], inputs [delta, Fxr] -> [Vdot, betadot, rdot]."""
    out = np.empty(3)
    out[0], out[1], out[2] = drift_derivatives(state[0], state[1], state[2], inputs[0], inputs[1], p)
    return out


@njit(cache=True)
def pose_derivatives(speed_mps, sideslip_rad, yaw_rate_radps, heading_rad):
    """Pose kinematics: (xdot, ydot, psidot); the course angle is psi + beta."""
    course = heading_rad + sideslip_rad
    return speed_mps * math.cos(course), speed_mps * math.sin(course), yaw_rate_radps
