"""The drift controller: MPC toward the planner's reference plus performance-driven control.

Performance-driven control (paper section III-B): the reference speed is V_hat = V_eq + dV (eq. 10), and
the steering sent to the car is delta_f = delta_mpc + k e_la with e_la = e + x_la sin(dpsi) (eq. 11). With
the error conventions of :mod:`driftlab.core.track` (e > 0 and dpsi > 0 to the right of the path), k > 0
steers back toward the path. The MPC's own input state keeps delta_mpc, as in the paper's block diagram.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit

from driftlab.core.blas_threads import with_one_blas_thread
from driftlab.core.equilibrium import Equilibrium, drift_equilibrium, has_drift_equilibrium
from driftlab.core.errors import NoEquilibriumError
from driftlab.core.integrator import rk4_stage, rk4_update
from driftlab.core.mpc import KN, MpcConfig, ReferenceQp
from driftlab.core.track import LEFT
from driftlab.core.vehicle import VehicleParams, drift_derivatives_vec, pack_params


@dataclass(frozen=True)
class ControllerModel:
    """What the controller knows: its vehicle model, the two reference equilibria and their QPs."""

    params: np.ndarray
    left: Equilibrium
    right: Equilibrium
    left_qp: ReferenceQp
    right_qp: ReferenceQp

    def equilibrium(self, direction: int) -> Equilibrium:
        return self.left if direction == LEFT else self.right

    def qp(self, direction: int) -> ReferenceQp:
        return self.left_qp if direction == LEFT else self.right_qp


# Disturbances beyond these [Vdot m/s^2, betadot rad/s, rdot rad/s^2] are not a model mismatch the linear MPC
# can use.
DISTURBANCE_LIMIT = np.array([5.0, 2.0, 5.0])


DriftProblem = tuple[float, float, np.ndarray]  # radius [m], sideslip [rad], packed parameters


def _drift_problems(vehicle: VehicleParams, left_radius_m: float, right_radius_m: float,
                    sideslip_rad: float) -> tuple[DriftProblem, DriftProblem | None]:
    """(radius, sideslip, packed parameters) of each side's drift; the right side None where it is the left one
    mirrored (equal radii, a symmetric model: the same solve in the same left-hand form, the same bits)."""
    left_params, right_params = pack_params(vehicle), pack_params(vehicle, right=True)
    left = (left_radius_m, -abs(sideslip_rad), left_params)
    if right_radius_m == left_radius_m and np.array_equal(right_params, left_params):
        return left, None
    return left, (right_radius_m, abs(sideslip_rad), right_params)


@lru_cache(maxsize=16)
def _reference_equilibria(vehicle: VehicleParams, left_radius_m: float, right_radius_m: float,
                          sideslip_rad: float) -> tuple[Equilibrium, Equilibrium]:
    # One solve instead of two where the right drift is the left one mirrored (~3.4 ms; with the model corrections
    # every evaluation's theta is a new model, built in each worker that runs one of its seeds).
    left_problem, right_problem = _drift_problems(vehicle, left_radius_m, right_radius_m, sideslip_rad)
    left = drift_equilibrium(*left_problem)
    return left, left.mirrored() if right_problem is None else drift_equilibrium(*right_problem)


def no_drift_reason(vehicle: VehicleParams, left_radius_m: float, right_radius_m: float,
                    sideslip_rad: float) -> str | None:
    """Why the controller's model ``vehicle`` has no drift to hold on these circles (None: it has one), without
    building its QPs: what :func:`build_controller_model` would raise."""
    try:
        _reference_equilibria(vehicle, left_radius_m, right_radius_m, sideslip_rad)
    except NoEquilibriumError as exc:
        return str(exc)
    return None


def has_drift(vehicle: VehicleParams, left_radius_m: float, right_radius_m: float, sideslip_rad: float) -> bool:
    """Whether :func:`no_drift_reason` is None, answered by each side's first start that finds its drift
    (:func:`driftlab.core.equilibrium.has_drift_equilibrium`): the optimizer's check of every proposal."""
    return all(problem is None or has_drift_equilibrium(*problem)
               for problem in _drift_problems(vehicle, left_radius_m, right_radius_m, sideslip_rad))


@lru_cache(maxsize=16)
@with_one_blas_thread  # cached: its bits must not depend on the first caller's threads
def build_controller_model(vehicle: VehicleParams, mpc: MpcConfig, left_radius_m: float,
                           right_radius_m: float, sideslip_rad: float, feedback_gain_radpm: float = 0.0,
                           lookahead_m: float = 0.0) -> ControllerModel:
    """Equilibria and condensed QPs for both sides; cached, as BO reuses them for every episode. Holds
    constants only: what a solver learns during an episode lives in the episode's closed loop. The QPs
    depend on the steering feedback (k, x_la) only when ``mpc.feedback_in_model`` is on.

    Raises:
        NoEquilibriumError: the model has no drift at one of the radii.
    """
    if not (mpc.feedback_in_model and mpc.path_states) and (feedback_gain_radpm or lookahead_m):
        # The QPs do not depend on the feedback: share one cache entry for every k.
        return build_controller_model(vehicle, mpc, left_radius_m, right_radius_m, sideslip_rad)
    params = pack_params(vehicle)
    left, right = _reference_equilibria(vehicle, left_radius_m, right_radius_m, sideslip_rad)
    return ControllerModel(params, left, right, ReferenceQp(mpc, left, params, feedback_gain_radpm, lookahead_m),
                           ReferenceQp(mpc, right, pack_params(vehicle, right=True, mirrored=True), feedback_gain_radpm,
                                       lookahead_m))


@njit(cache=True)
def lookahead_error_m(lateral_error_m, course_error_rad, lookahead_m):
    """e_la = e + x_la sin(dpsi) (paper section III-B)."""
    return lateral_error_m + lookahead_m * math.sin(course_error_rad)


@njit(cache=True)
def mirror(direction):
    """Sign flips taking a left-hand (V, beta, r) quantity to the given side (paper eq. 9)."""
    return np.array([1.0, 1.0, 1.0]) if direction == LEFT else np.array([1.0, -1.0, -1.0])


@njit(cache=True)
def steady_state_target(qa, disturbance):
    """Offset-free target: the steady state of the linear model (QP constants ``qa``) plus disturbance d at the
    same beta and path radius as the reference equilibrium.

    Unknowns dV, d_delta, d_Fxr with x_s = x_eq + [dV, 0, dV / R]; solves A (x_s - x_eq) + B (u_s - u_eq)
    + d = 0 (3 equations, 3 unknowns). Returns z_s (Fxr in kN).
    """
    z_eq = qa.z_eq
    radius = z_eq[0] / z_eq[2]
    a_c, b_c = qa.a_cont, qa.b_cont
    lhs = np.empty((3, 3))
    lhs[:, 0] = a_c[:, 0] + a_c[:, 2] / radius
    lhs[:, 1] = b_c[:, 0]
    lhs[:, 2] = b_c[:, 1]
    shift = np.linalg.solve(lhs, -disturbance)
    return z_eq + np.array([shift[0], 0.0, shift[0] / radius, shift[1], shift[2]])


@njit(cache=True)
def drift_reference(qa, estimate, direction, speed_offset_mps, offset_free):
    """z_ref = [V_eq + dV, beta_eq, r_eq, delta_eq, Fxr_eq kN] of the side being driven (paper eq. 10).

    Offset-free (``disturbance_gain`` > 0): the equilibrium first moves to where the linear model plus the
    estimated disturbance (kept in left-hand form, mirrored to the side) is steady at the same beta and path
    radius (:func:`steady_state_target`), and r follows V along the path (r = V / R).
    """
    z_ref = steady_state_target(qa, estimate * mirror(direction)) if offset_free else qa.z_eq.copy()
    z_ref[0] += speed_offset_mps
    if offset_free:
        z_ref[2] = z_ref[0] * qa.yaw_rate_radps / qa.speed_mps
    return z_ref


@njit(cache=True)
def hold_estimate(in_flick, hold_steps_left, hold_steps):
    """(frozen, steps left): the disturbance estimate is held during a flick and for ``hold_steps`` control
    steps after it (``mpc.estimator_hold_s``): the mismatch there is not that of a steady drift."""
    if in_flick:
        hold_steps_left = hold_steps
    elif hold_steps_left > 0:
        hold_steps_left -= 1
    return in_flick or hold_steps_left > 0, hold_steps_left


@njit(cache=True)
def _model_derivatives(qa, params, linear, x, u):
    """[Vdot, betadot, rdot] of the estimator's model at state x and inputs u = [delta, Fxr N]: the MPC's
    linearization (``qa``) or the nonlinear 3-state model (``params``)."""
    if linear:
        u_scaled = np.array([u[0], u[1] * KN])
        return np.dot(qa.a_cont, x - qa.x_eq) + np.dot(qa.b_cont, u_scaled - qa.u_eq_scaled)
    return drift_derivatives_vec(x, u, params)


@njit(cache=True)
def _lag_shape(t_s, lag_s, dt_s):
    """Share of the start value left at time t of a first-order move that ends at dt (1 at t = 0, 0 at dt)."""
    if lag_s <= 0.0:
        return 0.0
    end = math.exp(-dt_s / lag_s)
    return (math.exp(-t_s / lag_s) - end) / (1.0 - end)


@njit(cache=True)
def predict_one_step(qa, params, linear, state, inputs_start, inputs_end, lag_s, dt_s):
    """RK4 step of the estimator's model (one step; its modes are slow against dt) with the inputs moving from
    ``inputs_start`` to ``inputs_end`` as a first-order actuator of time constant ``lag_s`` does (at once
    when 0).

    With the MPC's own linear model the estimate also absorbs the linearization error, so the target it
    implies is a steady state of the MPC's prediction: offset-free (with the nonlinear model the car settled
    off its target, metres off its circle).
    """
    mid = inputs_end + (inputs_start - inputs_end) * _lag_shape(0.5 * dt_s, lag_s, dt_s)
    start = inputs_start if lag_s > 0.0 else inputs_end
    k1 = _model_derivatives(qa, params, linear, state, start)
    k2 = _model_derivatives(qa, params, linear, rk4_stage(state, 0.5 * dt_s, k1), mid)
    k3 = _model_derivatives(qa, params, linear, rk4_stage(state, 0.5 * dt_s, k2), mid)
    k4 = _model_derivatives(qa, params, linear, rk4_stage(state, dt_s, k3), inputs_end)
    return rk4_update(state, dt_s, k1, k2, k3, k4)
