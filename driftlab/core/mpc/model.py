"""The prediction model: the drift model's Jacobians augmented with path errors, actuator lags and the steering
feedback, in the QP's units, discretized (forward Euler as in the paper, or exact zero-order hold)."""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg

from driftlab.core.equilibrium import Equilibrium
from driftlab.core.mpc_config import KN, N_U, N_X, MpcConfig


def to_scaled(state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    """z = [V, beta, r, delta, Fxr kN] from state [V, beta, r] and inputs [delta, Fxr N]."""
    return np.array([state[0], state[1], state[2], inputs[0], inputs[1] * KN])


def scale_inputs(inputs: np.ndarray) -> np.ndarray:
    """[delta, Fxr kN] from [delta, Fxr N]."""
    return np.array([inputs[0], inputs[1] * KN])


def with_path_errors(a_c: np.ndarray, b_c: np.ndarray, equilibrium: Equilibrium) -> tuple[np.ndarray, np.ndarray]:
    """Adds the lateral error e and course error dpsi to the linearized model (not in the paper).

    With the conventions of :mod:`driftlab.core.track` (e > 0 right of the driving direction, dpsi = path
    heading - course), on a circle of radius R turned in direction s = sign(r_eq):
        e_dot = V sin(dpsi),   dpsi_dot = s V cos(dpsi) / (R + s e) - r - beta_dot,
    linearized at e = dpsi = 0 where s V / R = r_eq.
    """
    speed = equilibrium.speed_mps
    turn = math.copysign(1.0, equilibrium.yaw_rate_radps)
    radius = speed / abs(equilibrium.yaw_rate_radps)
    n = N_X + 2
    a_path = np.zeros((n, n))
    a_path[:N_X, :N_X] = a_c
    a_path[3, 4] = speed
    a_path[4, :N_X] = -a_c[1]
    a_path[4, 0] += turn / radius
    a_path[4, 2] -= 1.0
    a_path[4, 3] = -speed / radius**2
    b_path = np.zeros((n, N_U))
    b_path[:N_X] = b_c
    b_path[4] = -b_c[1]
    return a_path, b_path


def with_actuator_lag(a_c: np.ndarray, b_c: np.ndarray, config: MpcConfig) -> tuple[np.ndarray, np.ndarray]:
    """Continuous model with first-order actuators: states [x, delta_a, Fxr_a], inputs the commands."""
    lags = np.array([max(config.model_steer_lag_s, 1e-4), max(config.model_drive_lag_s, 1e-4)])
    n_x = a_c.shape[0]
    a_sys = np.zeros((n_x + N_U, n_x + N_U))
    a_sys[:n_x, :n_x] = a_c
    a_sys[:n_x, n_x:] = b_c
    a_sys[n_x:, n_x:] = np.diag(-1.0 / lags)
    b_sys = np.zeros((n_x + N_U, N_U))
    b_sys[n_x:, :] = np.diag(1.0 / lags)
    return a_sys, b_sys


def with_steer_feedback(a_sys: np.ndarray, b_sys: np.ndarray, gain_radpm: float, lookahead_m: float) -> np.ndarray:
    """Closes the paper's steering feedback delta_f = delta_mpc + k (e + x_la dpsi) (eq. 11, sin linearized)
    inside the model: the steering command becomes the MPC's input plus k [0 0 0 1 x_la 0 ...] x."""
    row = np.zeros(a_sys.shape[0])
    row[N_X] = gain_radpm
    row[N_X + 1] = gain_radpm * lookahead_m
    return a_sys + np.outer(b_sys[:, 0], row)


def terminal_weight(a_mat: np.ndarray, b_mat: np.ndarray, q_mat: np.ndarray, r_mat: np.ndarray) -> np.ndarray:
    """The infinite-horizon cost-to-go P of the unconstrained problem (discrete Riccati equation): as the last
    stage's weight it makes the finite-horizon MPC equal the LQR where no limit is active, which stabilizes
    the drift's saddle (an MPC without it on a 1 s horizon need not)."""
    try:
        p_mat = scipy.linalg.solve_discrete_are(a_mat, b_mat, q_mat + 1e-9 * np.eye(len(q_mat)), r_mat)
    except (np.linalg.LinAlgError, ValueError):
        return q_mat
    return 0.5 * (p_mat + p_mat.T)


def discretize(a_mat: np.ndarray, b_mat: np.ndarray, dt_s: float, method: str):
    """Discrete (Ad, Bd, Gd) for x+ = Ad x + Bd u + Gd d, with d an additive disturbance on xdot."""
    n, m = b_mat.shape
    if method == "euler":
        return np.eye(n) + dt_s * a_mat, dt_s * b_mat, dt_s * np.eye(n)
    block = np.zeros((2 * n + m, 2 * n + m))
    block[:n, :n] = a_mat
    block[:n, n:n + m] = b_mat
    block[:n, n + m:] = np.eye(n)
    phi = scipy.linalg.expm(block * dt_s)
    return phi[:n, :n], phi[:n, n:n + m], phi[:n, n + m:]
