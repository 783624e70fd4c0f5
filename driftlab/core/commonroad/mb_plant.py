"""CommonRoad's MB as a plant of the episode loop: the loop's eight states, MB's 29, the drive actuator; DriftLab's
actuators in front as for STD (:mod:`driftlab.core.commonroad.plant`), and the episode kernel with MB stepped in
compiled code.

A module of its own, imported only where an MB episode runs: the shared kernel
(:func:`driftlab.core.closed_loop.run_until_constrained`) leaves a plant it does not step (``PLANT_EXTERNAL``) to
its caller after each control step, so that its first compile does not carry MB's derivatives (~8 s);
:func:`run_mb_until_constrained`, compiled here, steps MB and goes on, and returns to Python only for a constrained
QP or the end.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from driftlab.core.closed_loop import run_until_constrained
from driftlab.core.commonroad.mb import (
    MB_LIFTOFF,
    N_MB,
    mb_acceleration_constraints,
    mb_derivatives_into,
    mb_wheel_loads,
    pack_mb,
)
from driftlab.core.commonroad.mb import M as MB_MASS
from driftlab.core.commonroad.plant import _rate
from driftlab.core.integrator import rk4_stage_into, rk4_update_into
from driftlab.core.loop_state import DONE, I_PLANT_DUE, I_STATUS, INVALID, NEEDS_PLANT
from driftlab.core.plant import (
    A_DRIVE_LAG,
    A_DRIVE_RATE,
    A_STEER_LAG,
    A_STEER_RATE,
    DRIVE,
    HEADING,
    N_PLANT_STATES,
    PLANT_EXTERNAL,
    SIDESLIP,
    SPEED,
    STEER,
    X_POS,
    Y_POS,
    YAW_RATE,
    PlantConfig,
)

MB_SUSPENSION = [6, 8, 11, 13, 16, 18, 21, 27, 28]  # roll, pitch, heave, the axles' roll and heave, compliance
MB_WHEELS = slice(23, 27)  # front left, front right, rear left, rear right wheel speeds [rad/s]
A_LOCKED_DIFFERENTIAL = 4  # MB's actuator vector carries the differential after DriftLab's four actuator settings
# Layout: the loop's eight, MB's 29 states, the drive actuator's force.
MB_FIRST = N_PLANT_STATES
MB_DRIVE_ACTUATOR = N_PLANT_STATES + N_MB
N_MB_PLANT_STATES = MB_DRIVE_ACTUATOR + 1


@njit(cache=True, error_model="numpy")
def _mb_integrated_derivatives(z, steer_cmd, drive_cmd, p, act, u, dz):
    """d/dt of [MB's 29 states, drive actuator force], written into ``dz`` (``u``: room for MB's two inputs)."""
    u[0] = _rate(z[2], steer_cmd, act[A_STEER_LAG], act[A_STEER_RATE])
    u[1] = z[N_MB] / p[MB_MASS]
    mb_derivatives_into(z, u, p, dz)
    if act[A_LOCKED_DIFFERENTIAL] > 0.5:
        # One rear axle shaft: both wheels turn together, driven by the sum of the torques (the package's mean).
        locked = 0.5 * (dz[25] + dz[26])
        dz[25] = dz[26] = locked
    dz[N_MB] = _rate(z[N_MB], drive_cmd, act[A_DRIVE_LAG], act[A_DRIVE_RATE]) if act[A_DRIVE_LAG] > 0.0 else 0.0


@njit(cache=True, error_model="numpy")
def mb_plant_step(state, steer_cmd, drive_cmd, duration_s, substep_s, p, act):
    """Advance the MB plant by ``duration_s`` with commands held; the loop's eight states follow from MB's.

    Classical RK4, each stage's arithmetic in the order of ``z + (h / 2) k1`` ... ``z + (h / 6)(k1 + 2 k2 + 2 k3 +
    k4)``, in buffers: a substep allocates nothing (the derivatives, ~1.3 us, are most of its cost)."""
    n = N_MB + 1
    z = state[MB_FIRST:].copy()
    if act[A_DRIVE_LAG] <= 0.0:
        reach = act[A_DRIVE_RATE] * duration_s
        z[N_MB] += min(max(drive_cmd - z[N_MB], -reach), reach)
    n_sub = max(1, int(round(duration_s / substep_s)))
    h = duration_s / n_sub
    half = 0.5 * h
    u, stage = np.empty(2), np.empty(n)
    k1, k2, k3, k4 = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    for _ in range(n_sub):
        _mb_integrated_derivatives(z, steer_cmd, drive_cmd, p, act, u, k1)
        rk4_stage_into(stage, z, half, k1)
        _mb_integrated_derivatives(stage, steer_cmd, drive_cmd, p, act, u, k2)
        rk4_stage_into(stage, z, half, k2)
        _mb_integrated_derivatives(stage, steer_cmd, drive_cmd, p, act, u, k3)
        rk4_stage_into(stage, z, h, k3)
        _mb_integrated_derivatives(stage, steer_cmd, drive_cmd, p, act, u, k4)
        rk4_update_into(z, h, k1, k2, k3, k4)
        for i in range(23, 27):  # the package clamps the wheel speeds of its state at 0
            z[i] = max(0.0, z[i])
    out = np.empty(N_MB_PLANT_STATES)
    _mb_to_loop(z, p, out)
    out[MB_FIRST:] = z
    return out


@njit(cache=True)
def _mb_to_loop(z, p, out):
    out[X_POS], out[Y_POS], out[HEADING] = z[0], z[1], z[4]
    out[SPEED] = math.sqrt(z[3] ** 2 + z[10] ** 2)
    out[SIDESLIP] = math.atan2(z[10], z[3])
    out[YAW_RATE], out[STEER] = z[5], z[2]
    out[DRIVE] = p[MB_MASS] * mb_acceleration_constraints(z[3], z[N_MB] / p[MB_MASS], p)


# An MB episode's validity record, sampled each control step: seconds with a wheel off the road (its tyre spring's
# load below zero: with plant.wheel_liftoff the wheel is in the air, without it the published model's tyre pulls
# the road), when that first was (NaN: never), seconds stepped, seconds with both wheels of one side off the road
# (the car on two wheels: a rollover under way), seconds outside the model's validity (the published model: any
# wheel pulling; with lift-off: two wheels of one side in the air, beyond what MB's linear roll springs describe),
# and the limit on that time after which the episode ends as invalid (FailureLimits.max_invalid_s; inf: never).
(R_NEGATIVE_LOAD_S, R_FIRST_NEGATIVE_LOAD_S, R_ELAPSED_S, R_SIDE_OFF_S, R_INVALID_S,
 R_MAX_INVALID_S) = range(6)


@njit(cache=True, error_model="numpy")
def mb_recorded_step(state, steer_cmd, drive_cmd, duration_s, substep_s, p, act, lowest_load_n, record):
    """:func:`mb_plant_step`, then the step's tyre loads noted: ``lowest_load_n`` keeps each wheel's lowest [N],
    ``record`` the validity record (``R_*``)."""
    new = mb_plant_step(state, steer_cmd, drive_cmd, duration_s, substep_s, p, act)
    loads = mb_wheel_loads(new[MB_FIRST:MB_FIRST + N_MB], p)
    for i in range(4):  # np.minimum's rule: a NaN (a diverged step) stays
        if math.isnan(loads[i]) or loads[i] < lowest_load_n[i]:
            lowest_load_n[i] = loads[i]
    record[R_ELAPSED_S] += duration_s
    off = loads.min() < 0.0
    if off:
        record[R_NEGATIVE_LOAD_S] += duration_s
        if math.isnan(record[R_FIRST_NEGATIVE_LOAD_S]):
            record[R_FIRST_NEGATIVE_LOAD_S] = record[R_ELAPSED_S]
    # The package's order: lf, rf, lr, rr; one side is lf and lr, the other rf and rr.
    one_side = (loads[0] < 0.0 and loads[2] < 0.0) or (loads[1] < 0.0 and loads[3] < 0.0)
    if one_side:
        record[R_SIDE_OFF_S] += duration_s
    if one_side if p[MB_LIFTOFF] > 0.5 else off:
        record[R_INVALID_S] += duration_s
    return new


@njit(cache=True)
def _ended_invalid(st, record):
    """Ends the episode as invalid once its time outside the model exceeds the limit (True then)."""
    if record[R_INVALID_S] > record[R_MAX_INVALID_S]:
        st.ints[I_STATUS] = INVALID
        return True
    return False


@njit(cache=True, error_model="numpy")
def run_mb_until_constrained(cfg, st, qa_left, qa_right, model_params, p, act, noise, lowest_load_n, record):
    """:func:`~driftlab.core.closed_loop.run_until_constrained` (DONE or NEEDS_QP), MB stepped as
    :meth:`CommonRoadMbPlant.step` steps it whenever the kernel asks, in compiled code."""
    while True:
        code = run_until_constrained(cfg, st, qa_left, qa_right, model_params, p, act, noise)
        if code != NEEDS_PLANT:
            return code
        st.plant[:] = mb_recorded_step(st.plant, st.last_applied[0], st.last_applied[1], cfg.dt_s, cfg.substep_s,
                                       p, act, lowest_load_n, record)
        st.ints[I_PLANT_DUE] = 0
        if _ended_invalid(st, record):
            return DONE


class CommonRoadMbPlant:
    """CommonRoad's MB as the loop's plant (see :class:`driftlab.core.plant.Plant` for the interface)."""

    kind = PLANT_EXTERNAL

    def __init__(self, config: PlantConfig, car) -> None:
        self.config = config
        self.car = car
        self.params = pack_mb(self.car, friction_scale=config.friction_scale, mass_scale=config.mass_scale,
                              steer_rate_radps=config.steer_rate_radps, wheel_liftoff=config.wheel_liftoff)
        self.actuators = np.append(config.actuator_params(), 1.0 if config.locked_differential else 0.0)
        self.steady: np.ndarray | None = None
        self.min_wheel_load_n = np.full(4, np.inf)
        self.record = np.array([0.0, np.nan, 0.0, 0.0, 0.0, np.inf])  # R_* of mb_recorded_step

    def end_invalid_after(self, seconds: float) -> None:
        """End the episode as invalid once it has been outside the model's validity for longer than this."""
        self.record[R_MAX_INVALID_S] = seconds

    def ended_invalid(self, loop: Any) -> bool:
        """After a step from Python: whether the episode ends invalid now (its status set)."""
        return bool(_ended_invalid(loop, self.record))

    def start_in_drift_of(self, radius_m: float, sideslip_rad: float) -> None:
        """Start the suspension as it sits in the car's steady drift there (if one was found)."""
        from driftlab.core.commonroad.mb_equilibrium import mb_steady_state

        found = mb_steady_state(self.car, radius_m, sideslip_rad, False,
                                self.config.friction_scale, self.config.mass_scale)
        self.steady = None if found is None else found[1]

    def start_state(self, loop_state: np.ndarray) -> np.ndarray:
        """The package's own init_mb (suspension at its static deflection), the rear wheels at the configured slip
        ratio, the front ones rolling."""
        from vehiclemodels.init_mb import init_mb

        from driftlab.core.commonroad.parameters import package_parameters

        p = package_parameters(self.car)
        s = loop_state
        z = np.array(init_mb([s[X_POS], s[Y_POS], s[STEER], s[SPEED], s[HEADING], s[YAW_RATE], s[SIDESLIP]], p))
        rear = max(z[3], 0.0) * (1.0 - self.config.initial_rear_slip) / p.R_w
        z[25] = z[26] = rear
        if self.steady is not None:  # the body rolled and the axles deflected as in the drift, not at rest
            z[MB_SUSPENSION] = self.steady[MB_SUSPENSION]
            # Every wheel at its slip in MB's own drift (rear -0.35 at 0.5 rad, not STD's -0.5): a start at
            # another slip is a rear-force step of ~2 kN that the first second spends recovering from.
            z[MB_WHEELS] = self.steady[MB_WHEELS] * max(z[3], 0.0) / self.steady[3]
        out = np.zeros(N_MB_PLANT_STATES)
        zz = np.zeros(N_MB + 1)
        zz[:N_MB], zz[N_MB] = z, s[DRIVE]
        _mb_to_loop(zz, self.params, out)
        out[MB_FIRST:] = zz
        return out

    def step(self, state: np.ndarray, steer_cmd_rad: float, drive_cmd_n: float, duration_s: float) -> np.ndarray:
        return mb_recorded_step(state, steer_cmd_rad, drive_cmd_n, duration_s, self.config.substep_s, self.params,
                                self.actuators, self.min_wheel_load_n, self.record)

    def run_loop(self, settings: Any, loop: Any, qa_left: Any, qa_right: Any, model_params: Any,
                 noise: np.ndarray) -> int:
        """The episode kernel's :func:`~driftlab.core.closed_loop.run_until_constrained` with this plant stepped
        inside compiled code, as :meth:`step` would step it (the same bits), instead of a return to Python per
        control step (which cost MB's episode ~1/5 of its time)."""
        return run_mb_until_constrained(settings, loop, qa_left, qa_right, model_params, self.params,
                                        self.actuators, noise, self.min_wheel_load_n, self.record)

    def validity(self) -> dict[str, object]:
        """Where the episode left the model's validity (:data:`R_INVALID_S`): the time any wheel was off the road
        (``negative_wheel_load_s``: its tyre spring's load below zero; the published model does not clamp it, so its
        tyre pulls the road), when that first was, the time both wheels of one side were (``one_side_off_s``), the
        time outside the model (``invalid_s``), and each wheel's lowest load (the package's names: its "l" wheels
        sit at -y)."""
        lowest = {name: float(v) for name, v in zip(("lf", "rf", "lr", "rr"), self.min_wheel_load_n, strict=True)}
        first_s = float(self.record[R_FIRST_NEGATIVE_LOAD_S])
        return {"negative_wheel_load_s": round(float(self.record[R_NEGATIVE_LOAD_S]), 6),
                "first_negative_wheel_load_s": None if math.isnan(first_s) else round(first_s, 6),
                "one_side_off_s": round(float(self.record[R_SIDE_OFF_S]), 6),
                "invalid_s": round(float(self.record[R_INVALID_S]), 6),
                "wheel_liftoff": bool(self.config.wheel_liftoff),
                "min_wheel_load_n": lowest}
