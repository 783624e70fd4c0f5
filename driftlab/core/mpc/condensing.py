"""The condensed QP for one reference equilibrium: built once, reused every step of every episode."""

from __future__ import annotations

import numpy as np
import scipy.linalg

from driftlab.core.equilibrium import Equilibrium, jacobians
from driftlab.core.mpc.arrays import QpArrays
from driftlab.core.mpc.kernels import pack_state
from driftlab.core.mpc.model import (
    discretize,
    scale_inputs,
    terminal_weight,
    to_scaled,
    with_actuator_lag,
    with_path_errors,
    with_steer_feedback,
)
from driftlab.core.mpc_config import KN, N_U, N_X, MpcConfig


class ReferenceQp:
    """The condensed QP for one reference equilibrium (built once, reused every step)."""

    def __init__(self, config: MpcConfig, equilibrium: Equilibrium, p_model: np.ndarray,
                 feedback_gain_radpm: float = 0.0, lookahead_m: float = 0.0) -> None:
        self.config = config
        self.equilibrium = equilibrium
        a_c, b_c = jacobians(equilibrium.state, equilibrium.inputs, p_model)
        b_c = b_c.copy()
        b_c[:, 1] /= KN  # per kN
        self.a_cont, self.b_cont = a_c, b_c
        self.models_lag = config.models_actuator_lag
        self.path_states = config.path_states
        a_sys, b_sys = with_path_errors(a_c, b_c, equilibrium) if self.path_states else (a_c, b_c)
        a_sys, b_sys = with_actuator_lag(a_sys, b_sys, config) if self.models_lag else (a_sys, b_sys)
        if config.feedback_in_model and self.path_states:
            a_sys = with_steer_feedback(a_sys, b_sys, feedback_gain_radpm, lookahead_m)
        n_sys = a_sys.shape[0]  # model states (3 or 5) plus 2 actuator states [delta_a, Fxr_a kN] if modelled
        ad, bd, gd = discretize(a_sys, b_sys, config.dt_s, config.discretization)
        # The disturbance acts on (Vdot, betadot, rdot); the course error's rate holds -betadot, so a sideslip
        # disturbance moves it too (without this the MPC, believing the course drifts, held the car metres
        # off its circle in a steady drift).
        entry = np.zeros((gd.shape[0], N_X))
        entry[:N_X, :N_X] = np.eye(N_X)
        if self.path_states:
            entry[N_X + 1, 1] = -1.0
        gd = gd @ entry
        self.ad, self.bd, self.gd = ad, bd, gd
        self.n_z = n_z = n_sys + N_U
        self.z_lin = self.augmented_reference(to_scaled(equilibrium.state, equilibrium.inputs))
        n_h = config.horizon
        aa = np.zeros((n_z, n_z))
        aa[:n_sys, :n_sys] = ad
        aa[:n_sys, n_sys:] = bd
        aa[n_sys:, n_sys:] = np.eye(N_U)
        ba = np.vstack([bd, np.eye(N_U)])
        ga = np.vstack([gd, np.zeros((N_U, N_X))])
        phi = np.zeros((n_h * n_z, n_z))
        gamma = np.zeros((n_h * n_z, n_h * N_U))
        lam = np.zeros((n_h * n_z, N_X))
        power = np.eye(n_z)
        lam_acc = np.zeros((n_z, N_X))
        a_pow_b = [ba]
        for _ in range(1, n_h):
            a_pow_b.append(aa @ a_pow_b[-1])
        for k in range(n_h):
            lam_acc = aa @ lam_acc + ga
            power = aa @ power
            phi[k * n_z:(k + 1) * n_z] = power
            lam[k * n_z:(k + 1) * n_z] = lam_acc
        # Gamma's block (k, j) is A^(k-j) B: each block column is the stack [B; AB; ...] shifted down j blocks.
        stacked = np.vstack(a_pow_b)
        for j in range(n_h):
            gamma[j * n_z:, j * N_U:(j + 1) * N_U] = stacked[:(n_h - j) * n_z]
        # Q weighs [delta, Fxr] on the actuator states when modelled, else on the held commands.
        lag_part = [config.actuator_weights, np.zeros(N_U)] if self.models_lag else [config.actuator_weights]
        weights = np.concatenate([config.state_weights, *lag_part])
        q_bar = np.diag(np.tile(weights, n_h))  # blkdiag(Q, ..., Q)
        r_bar = np.diag(np.tile(config.input_weights, n_h))
        if config.terminal_cost:
            q_bar[-n_z:, -n_z:] = terminal_weight(aa, ba, np.diag(weights), np.diag(config.input_weights))
        self.gamma_t_q = gamma.T @ q_bar
        hessian = self.gamma_t_q @ gamma + r_bar
        hessian = 0.5 * (hessian + hessian.T)
        self.hessian = hessian
        self.phi = phi
        self.lam = lam
        chol = scipy.linalg.cho_factor(hessian)
        gain = scipy.linalg.cho_solve(chol, self.gamma_t_q)  # H^-1 Gamma' Qbar
        self.gain_state = gain @ phi
        self.gain_disturbance = gain @ lam
        self.gain_reference = gain
        # Constraints on the increments: bounds on each du and on u_{-1} + cumulative sums.
        cumsum = np.kron(np.tril(np.ones((n_h, n_h))), np.eye(N_U))
        self.cumsum = cumsum
        self.repeat = np.tile(np.eye(N_U), (n_h, 1))  # u -> [u, u, ..., u]
        self.constraint_matrix = np.vstack([np.eye(n_h * N_U), cumsum])
        self.daqp_sense = np.zeros(2 * n_h * N_U, dtype=np.intc)  # all inequalities
        step_limit = np.array([config.steer_rate_radps * config.dt_s, config.drive_rate_nps * config.dt_s * KN])
        self.step_limit = np.tile(step_limit, n_h)
        self.input_lo = np.tile(np.array([-config.steer_limit_rad, config.drive_min_n * KN]), n_h)
        self.input_hi = np.tile(np.array([config.steer_limit_rad, config.drive_max_n * KN]), n_h)
        self.arrays = QpArrays(
            a_cont=np.ascontiguousarray(self.a_cont), b_cont=np.ascontiguousarray(self.b_cont),
            x_eq=equilibrium.state, u_eq_scaled=scale_inputs(equilibrium.inputs),
            z_eq=to_scaled(equilibrium.state, equilibrium.inputs), speed_mps=float(equilibrium.speed_mps),
            yaw_rate_radps=float(equilibrium.yaw_rate_radps), z_lin=self.z_lin, gain_state=self.gain_state,
            gain_disturbance=self.gain_disturbance, gain_reference=self.gain_reference, gamma_t_q=self.gamma_t_q,
            phi=self.phi, lam=self.lam, repeat=self.repeat, step_limit=self.step_limit,
            input_lo=self.input_lo, input_hi=self.input_hi, path_states=bool(self.path_states),
            models_lag=bool(self.models_lag), horizon=int(n_h), steer_limit_rad=float(config.steer_limit_rad),
            drive_min_kn=float(config.drive_min_n * KN), drive_max_kn=float(config.drive_max_n * KN),
            # DAQP reads these three through raw pointers in the compiled loop: C order, as the kernel assumes.
            cumsum=np.ascontiguousarray(self.cumsum), hessian=np.ascontiguousarray(self.hessian),
            daqp_sense=np.ascontiguousarray(self.daqp_sense))

    def augmented_reference(self, z_ref: np.ndarray) -> np.ndarray:
        """The 5-entry reference [V, beta, r, delta, Fxr kN] in this QP's state layout (path errors 0)."""
        return self.pack_state(z_ref[:N_X], np.zeros(2), z_ref[N_X:], z_ref[N_X:])

    def pack_state(self, state: np.ndarray, path_errors: np.ndarray, actuators_scaled: np.ndarray,
                   previous_commands_scaled: np.ndarray) -> np.ndarray:
        """z = [V, beta, r, (e, dpsi,) (delta_a, Fxr_a kN,) delta_prev, Fxr_prev kN] for this QP."""
        return pack_state(bool(self.path_states), bool(self.models_lag), np.asarray(state, float),
                          np.asarray(path_errors, float), np.asarray(actuators_scaled, float),
                          np.asarray(previous_commands_scaled, float))
