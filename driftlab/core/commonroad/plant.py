"""CommonRoad's STD as a plant of the episode loop: the loop's state layout, DriftLab's actuators in front.

Inputs: the loop sends a steering angle and a rear drive force. STD takes a steering velocity and a longitudinal
acceleration, so the steering is a position servo, u0 = clip((delta_cmd - delta) / steer_lag_s, +-steer_rate)
(the package's own rate limit, 0.4 rad/s, makes every drift impossible: the loop spins out at 0.4, 1 and 2 rad/s
and completes from 4-8; the default is DriftLab's 8 rad/s), and the drive force goes through DriftLab's drive
actuator (lag, rate limit) and becomes u1 = F / m: the rear torque m R_w u1, hence a rear tyre force of m u1 in
steady state (the rear force itself is not an input: wheel speed is a state and the force follows from the
combined slip). Integration: RK4 at ``substep_s`` (2 ms by default: the rear wheel-speed mode is ~ -400 1/s at
19 m/s, |lambda h| ~ 0.8), the wheel speeds clamped at 0 after each substep as the package clamps them.

State layout: the loop's eight (x, y, psi, V, beta, r, steer, drive; ``drive`` is the force the car applies,
m times the constrained acceleration) and three of the plant's own: front and rear wheel speeds [rad/s] and the
drive actuator's force [N].
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from driftlab.core.commonroad.parameters import CR_CG_TO_FRONT, CR_MASS, CR_WHEEL_RADIUS, pack_commonroad
from driftlab.core.commonroad.std import (
    N_STD,
    S_OMEGA_F,
    S_OMEGA_R,
    S_SIDESLIP,
    S_SPEED,
    S_STEER,
    S_X,
    S_Y,
    S_YAW,
    S_YAW_RATE,
    acceleration_constraints,
    std_derivatives,
)
from driftlab.core.integrator import rk4_stage_into, rk4_update_into
from driftlab.core.plant import (
    A_DRIVE_LAG,
    A_DRIVE_RATE,
    A_STEER_LAG,
    A_STEER_RATE,
    DRIVE,
    HEADING,
    N_PLANT_STATES,
    PLANT_COMMONROAD_STD,
    SIDESLIP,
    SPEED,
    STEER,
    X_POS,
    Y_POS,
    YAW_RATE,
    PlantConfig,
)

OMEGA_F, OMEGA_R, DRIVE_ACTUATOR = N_PLANT_STATES, N_PLANT_STATES + 1, N_PLANT_STATES + 2
N_STD_PLANT_STATES = N_PLANT_STATES + 3
_DRIVE_SLOT = N_STD  # the drive actuator's force, after STD's nine states in the integrated vector


@njit(cache=True)
def _rate(actual, command, lag_s, rate_limit):
    return min(max((command - actual) / lag_s, -rate_limit), rate_limit)


@njit(cache=True)
def _integrated_derivatives_into(dz, z, steer_cmd, drive_cmd, cp, act, u):
    """d/dt of [STD's nine states, drive actuator force], written into ``dz`` (``u``: STD's inputs, a buffer)."""
    u[0] = _rate(z[S_STEER], steer_cmd, act[A_STEER_LAG], act[A_STEER_RATE])
    u[1] = z[_DRIVE_SLOT] / cp[CR_MASS]
    dz[:N_STD] = std_derivatives(z[:N_STD], u, cp)
    dz[_DRIVE_SLOT] = _rate(z[_DRIVE_SLOT], drive_cmd, act[A_DRIVE_LAG], act[A_DRIVE_RATE]) \
        if act[A_DRIVE_LAG] > 0.0 else 0.0


@njit(cache=True)
def std_plant_step(state, steer_cmd, drive_cmd, duration_s, substep_s, cp, act):
    """Advance the STD plant by ``duration_s`` with commands held (zero-order hold). Returns a new state."""
    z = np.empty(N_STD + 1)
    z[S_X], z[S_Y], z[S_STEER], z[S_SPEED] = state[X_POS], state[Y_POS], state[STEER], state[SPEED]
    z[S_YAW], z[S_YAW_RATE], z[S_SIDESLIP] = state[HEADING], state[YAW_RATE], state[SIDESLIP]
    z[S_OMEGA_F], z[S_OMEGA_R], z[_DRIVE_SLOT] = state[OMEGA_F], state[OMEGA_R], state[DRIVE_ACTUATOR]
    if act[A_DRIVE_LAG] <= 0.0:
        reach = act[A_DRIVE_RATE] * duration_s
        z[_DRIVE_SLOT] += min(max(drive_cmd - z[_DRIVE_SLOT], -reach), reach)
    n_sub = max(1, int(round(duration_s / substep_s)))
    h = duration_s / n_sub
    k1, k2, k3, k4, stage = np.empty((5, N_STD + 1))  # allocated once a step, as in the DriftLab plant
    u = np.empty(2)
    for _ in range(n_sub):
        _integrated_derivatives_into(k1, z, steer_cmd, drive_cmd, cp, act, u)
        rk4_stage_into(stage, z, 0.5 * h, k1)
        _integrated_derivatives_into(k2, stage, steer_cmd, drive_cmd, cp, act, u)
        rk4_stage_into(stage, z, 0.5 * h, k2)
        _integrated_derivatives_into(k3, stage, steer_cmd, drive_cmd, cp, act, u)
        rk4_stage_into(stage, z, h, k3)
        _integrated_derivatives_into(k4, stage, steer_cmd, drive_cmd, cp, act, u)
        rk4_update_into(z, h, k1, k2, k3, k4)
        z[S_OMEGA_F] = max(0.0, z[S_OMEGA_F])
        z[S_OMEGA_R] = max(0.0, z[S_OMEGA_R])
    out = np.empty(N_STD_PLANT_STATES)
    out[X_POS], out[Y_POS], out[HEADING] = z[S_X], z[S_Y], z[S_YAW]
    out[SPEED], out[SIDESLIP], out[YAW_RATE], out[STEER] = z[S_SPEED], z[S_SIDESLIP], z[S_YAW_RATE], z[S_STEER]
    out[DRIVE] = cp[CR_MASS] * acceleration_constraints(z[S_SPEED], z[_DRIVE_SLOT] / cp[CR_MASS], cp)
    out[OMEGA_F], out[OMEGA_R], out[DRIVE_ACTUATOR] = z[S_OMEGA_F], z[S_OMEGA_R], z[_DRIVE_SLOT]
    return out


def std_start_state(loop_state: np.ndarray, cp: np.ndarray, rear_slip: float) -> np.ndarray:
    """The plant's full state from the loop's eight: front wheel rolling freely, the rear at slip ratio
    ``rear_slip`` (negative: spinning faster than the ground, as in a power-on drift), the drive actuator at
    the start drive force."""
    s = np.zeros(N_STD_PLANT_STATES)
    s[:N_PLANT_STATES] = loop_state
    speed, beta, yaw_rate, steer = loop_state[SPEED], loop_state[SIDESLIP], loop_state[YAW_RATE], loop_state[STEER]
    radius = cp[CR_WHEEL_RADIUS]
    front_ground = speed * math.cos(beta) * math.cos(steer) + (speed * math.sin(beta)
                                                                + cp[CR_CG_TO_FRONT] * yaw_rate) * math.sin(steer)
    s[OMEGA_F] = max(front_ground, 0.0) / radius
    s[OMEGA_R] = max(speed * math.cos(beta), 0.0) * (1.0 - rear_slip) / radius
    s[DRIVE_ACTUATOR] = loop_state[DRIVE]
    return s



class CommonRoadStdPlant:
    """CommonRoad's STD as the loop's plant (see :class:`driftlab.core.plant.Plant` for the interface)."""

    kind = PLANT_COMMONROAD_STD  # stepped inside the loop's kernel

    def __init__(self, config: PlantConfig, car) -> None:
        self.config = config
        self.params = pack_commonroad(car, friction_scale=config.friction_scale, mass_scale=config.mass_scale,
                                      steer_rate_radps=config.steer_rate_radps)
        self.actuators = config.actuator_params()

    def start_state(self, loop_state: np.ndarray) -> np.ndarray:
        return std_start_state(loop_state, self.params, self.config.initial_rear_slip)

    def step(self, state: np.ndarray, steer_cmd_rad: float, drive_cmd_n: float, duration_s: float) -> np.ndarray:
        return std_plant_step(state, steer_cmd_rad, drive_cmd_n, duration_s, self.config.substep_s, self.params,
                              self.actuators)
