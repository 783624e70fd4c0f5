"""What one MPC step returns, and the condensed QP's constants as the compiled loop reads them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


@dataclass
class MpcSolution:
    """One step's result."""

    steer_rad: float
    drive_force_n: float
    used_osqp: bool
    ok: bool
    increments: np.ndarray  # the whole optimal increment sequence, [d_delta, d_Fxr kN] per step


class QpArrays(NamedTuple):
    """A :class:`ReferenceQp`'s constants as the compiled closed loop reads them (numba takes a named tuple)."""

    a_cont: np.ndarray  # continuous Jacobians at the equilibrium, A (3x3) and B (3x2, per kN)
    b_cont: np.ndarray
    x_eq: np.ndarray  # [V, beta, r]
    u_eq_scaled: np.ndarray  # [delta, Fxr kN]
    z_eq: np.ndarray  # [V, beta, r, delta, Fxr kN]
    speed_mps: float
    yaw_rate_radps: float
    z_lin: np.ndarray  # the linearization point in the QP's state layout
    gain_state: np.ndarray
    gain_disturbance: np.ndarray
    gain_reference: np.ndarray
    gamma_t_q: np.ndarray
    phi: np.ndarray
    lam: np.ndarray
    repeat: np.ndarray
    cumsum: np.ndarray
    step_limit: np.ndarray
    input_lo: np.ndarray
    input_hi: np.ndarray
    path_states: bool
    models_lag: bool
    horizon: int
    steer_limit_rad: float
    drive_min_kn: float
    drive_max_kn: float
    hessian: np.ndarray  # the condensed QP's H, and DAQP's constraint senses (all inequalities), for the kernel's solve
    daqp_sense: np.ndarray
