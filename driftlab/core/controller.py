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

from driftlab.core.equilibrium import Equilibrium, drift_equilibrium
from driftlab.core.mpc import DisturbanceEstimator, MpcConfig, MpcSolution, ReferenceQp, scale_inputs, to_scaled
from driftlab.core.track import LEFT, RIGHT
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


@lru_cache(maxsize=16)
def _reference_equilibria(vehicle: VehicleParams, left_radius_m: float, right_radius_m: float,
                          sideslip_rad: float) -> tuple[Equilibrium, Equilibrium]:
    params = pack_params(vehicle)
    return (drift_equilibrium(left_radius_m, -abs(sideslip_rad), params),
            drift_equilibrium(right_radius_m, abs(sideslip_rad), params))


@lru_cache(maxsize=16)
def build_controller_model(vehicle: VehicleParams, mpc: MpcConfig, left_radius_m: float,
                           right_radius_m: float, sideslip_rad: float, feedback_gain_radpm: float = 0.0,
                           lookahead_m: float = 0.0) -> ControllerModel:
    """Equilibria and condensed QPs for both sides; cached, as BO reuses them for every episode. Holds
    constants only: what a solver learns during an episode lives in :class:`DriftController`. The QPs
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
                           ReferenceQp(mpc, right, params, feedback_gain_radpm, lookahead_m))


def lookahead_error_m(lateral_error_m: float, course_error_rad: float, lookahead_m: float) -> float:
    """e_la = e + x_la sin(dpsi) (paper section III-B)."""
    return lateral_error_m + lookahead_m * np.sin(course_error_rad)


class DriftController:
    """One episode's controller state: last inputs, disturbance estimate."""

    def __init__(self, model: ControllerModel, mpc: MpcConfig, speed_offset_mps: float,
                 feedback_gain_radpm: float, lookahead_m: float) -> None:
        self.model = model
        self.mpc = mpc
        self.speed_offset_mps = speed_offset_mps
        self.feedback_gain_radpm = feedback_gain_radpm
        self.lookahead_m = lookahead_m
        start = model.left
        self.last_mpc_inputs = start.inputs.copy()  # [delta_mpc rad, Fxr N]
        self.last_applied = start.inputs.copy()
        self.last_state: np.ndarray | None = None
        self.last_actuators: np.ndarray | None = None
        self.direction = LEFT
        self.last_direction = LEFT
        self.hold_steps = 0
        # Disturbances beyond these are not a model mismatch the linear MPC can use.
        limit = np.array([5.0, 2.0, 5.0])
        self.estimator = DisturbanceEstimator(mpc.disturbance_gain, mpc.dt_s, limit, mpc.disturbance_start_gain)
        # Solver state lives and dies with this episode (the cached model holds only constants).
        self.sessions = {LEFT: model.left_qp.session(), RIGHT: model.right_qp.session()}

    def reference(self, direction: int) -> np.ndarray:
        """z_ref = [V_eq + dV, beta_eq, r_eq, delta_eq, Fxr_eq kN] of the side being driven.

        With the offset-free extension on, the equilibrium is first moved to where the linear model plus
        the estimated disturbance is steady at the same beta and path radius (:func:`steady_state_target`).
        """
        eq = self.model.equilibrium(direction)
        z_eq = to_scaled(eq.state, eq.inputs)
        if self.mpc.disturbance_gain > 0.0:
            z_eq = steady_state_target(self.model.qp(direction), self.estimator.value * _mirror(direction))
        z_ref = z_eq.copy()
        z_ref[0] += self.speed_offset_mps
        if self.mpc.disturbance_gain > 0.0:
            z_ref[2] = z_ref[0] * eq.yaw_rate_radps / eq.speed_mps  # keep r = V / R
        return z_ref

    def freeze_estimate(self, frozen: bool) -> None:
        """Hold the disturbance estimate during a flick and for ``estimator_hold_s`` after it: the mismatch
        there is not that of a steady drift."""
        if frozen:
            self.hold_steps = int(round(self.mpc.estimator_hold_s / self.mpc.dt_s))
        elif self.hold_steps > 0:
            self.hold_steps -= 1
        self.estimator.frozen = frozen or self.hold_steps > 0

    def _update_disturbance(self, state: np.ndarray, actuators: np.ndarray) -> np.ndarray:
        if self.last_state is None or self.mpc.disturbance_gain == 0.0:
            return self.estimator.value
        # One-step prediction under the inputs the actuators actually applied (measured at both ends of the
        # step, shaped by the model's lag). With the MPC's own linear model the estimate also absorbs the
        # linearization error, so the target it implies is a steady state of the MPC's prediction: offset-free.
        # (With the nonlinear model the car settled off its target, metres off its circle.)
        if self.mpc.estimator_uses_actuators:
            start, end, lag = self.last_actuators, actuators, self.mpc.model_steer_lag_s
        else:
            start, end, lag = self.last_applied, self.last_applied, 0.0
        if self.mpc.estimator_model == "linear":
            qp = self.model.qp(self.last_direction)
            x_eq, u_eq = qp.equilibrium.state, scale_inputs(qp.equilibrium.inputs)

            def derivatives(x, u):
                return qp.a_cont @ (x - x_eq) + qp.b_cont @ (scale_inputs(u) - u_eq)
        else:
            def derivatives(x, u):
                return drift_derivatives_vec(x, u, self.model.params)
        predicted = _rk4_step(derivatives, self.last_state, start, end, lag, self.mpc.dt_s)
        # The estimate is kept in left-hand form; a right-hand drift sees it mirrored (paper eq. 9).
        return self.estimator.update((state - predicted) * _mirror(self.direction)) * _mirror(self.direction)

    def step(self, state: np.ndarray, actuators: np.ndarray, direction: int, lateral_error_m: float,
             course_error_rad: float) -> tuple[float, float, MpcSolution]:
        """Commands (steer rad, drive N) for the measured state [V, beta, r] and actuator positions
        [delta rad, Fxr N] (used where the controller models actuator lag)."""
        self.last_direction = self.direction
        self.direction = direction
        disturbance = self._update_disturbance(state, actuators)
        qp = self.model.qp(direction)
        z_now = qp.pack_state(state, np.array([lateral_error_m, course_error_rad]), scale_inputs(actuators),
                              scale_inputs(self.last_mpc_inputs))
        solution = self.sessions[direction].solve(z_now, self.reference(direction), disturbance)
        self.last_mpc_inputs = np.array([solution.steer_rad, solution.drive_force_n])
        e_la = lookahead_error_m(lateral_error_m, course_error_rad, self.lookahead_m)
        limit = self.mpc.steer_limit_rad
        steer = float(np.clip(solution.steer_rad + self.feedback_gain_radpm * e_la, -limit, limit))
        self.last_applied = np.array([steer, solution.drive_force_n])
        self.last_state = state.copy()
        self.last_actuators = actuators.copy()
        return steer, solution.drive_force_n, solution


def _mirror(direction: int) -> np.ndarray:
    """Sign flips taking a left-hand (V, beta, r) quantity to the given side."""
    return np.array([1.0, 1.0, 1.0]) if direction == LEFT else np.array([1.0, -1.0, -1.0])


def steady_state_target(qp: ReferenceQp, disturbance: np.ndarray) -> np.ndarray:
    """Offset-free target: the steady state of the linear model plus disturbance d at the same beta and
    path radius as the reference equilibrium.

    Unknowns dV, d_delta, d_Fxr with x_s = x_eq + [dV, 0, dV / R]; solves A (x_s - x_eq) + B (u_s - u_eq)
    + d = 0 (3 equations, 3 unknowns). Returns z_s (Fxr in kN).
    """
    z_eq = to_scaled(qp.equilibrium.state, qp.equilibrium.inputs)
    radius = z_eq[0] / z_eq[2]
    a_c, b_c = qp.a_cont, qp.b_cont
    lhs = np.column_stack([a_c[:, 0] + a_c[:, 2] / radius, b_c[:, 0], b_c[:, 1]])
    dv, dsteer, ddrive = np.linalg.solve(lhs, -disturbance)
    return z_eq + np.array([dv, 0.0, dv / radius, dsteer, ddrive])


def _rk4_step(derivatives, state: np.ndarray, inputs_start: np.ndarray, inputs_end: np.ndarray, lag_s: float,
              dt_s: float) -> np.ndarray:
    """RK4 step of a 3-state model xdot = derivatives(x, u) (one step; its modes are slow against dt) with the
    inputs moving from ``inputs_start`` to ``inputs_end`` as a first-order actuator of time constant ``lag_s``
    does (at once when 0)."""
    mid = inputs_end + (inputs_start - inputs_end) * _lag_shape(0.5 * dt_s, lag_s, dt_s)
    start = inputs_start if lag_s > 0.0 else inputs_end
    k1 = derivatives(state, start)
    k2 = derivatives(state + 0.5 * dt_s * k1, mid)
    k3 = derivatives(state + 0.5 * dt_s * k2, mid)
    k4 = derivatives(state + dt_s * k3, inputs_end)
    return state + dt_s / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def _lag_shape(t_s: float, lag_s: float, dt_s: float) -> float:
    """Share of the start value left at time t of a first-order move that ends at dt (1 at t = 0, 0 at dt)."""
    if lag_s <= 0.0:
        return 0.0
    end = math.exp(-dt_s / lag_s)
    return (math.exp(-t_s / lag_s) - end) / (1.0 - end)
