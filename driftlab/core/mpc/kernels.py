"""The compiled per-step pieces of the condensed QP (the closed loop calls them every control step)."""

from __future__ import annotations

import numpy as np
from numba import njit

from driftlab.core.mpc_config import N_U, N_X


@njit(cache=True)
def clip(x, lo, hi):
    """np.clip of a scalar, to the bit (NaN passes through; max first, then min)."""
    if x != x:
        return x
    x = x if x > lo else lo
    return x if x < hi else hi


@njit(cache=True)
def pack_state(path_states, models_lag, state, path_errors, actuators_scaled, previous_commands_scaled):
    """z = [V, beta, r, (e, dpsi,) (delta_a, Fxr_a kN,) delta_prev, Fxr_prev kN]: the QP's state, with the
    path errors if ``path_states`` and the actuator states if ``models_lag``."""
    n = 3 + (2 if path_states else 0) + (N_U if models_lag else 0) + N_U
    z = np.empty(n)
    z[:3] = state
    i = 3
    if path_states:
        z[i:i + 2] = path_errors
        i += 2
    if models_lag:
        z[i:i + N_U] = actuators_scaled
        i += N_U
    z[i:i + N_U] = previous_commands_scaled
    return z


@njit(cache=True)
def _reference_deviation(qa, z_ref):
    """The reference's deviation from the linearization point, repeated over the horizon."""
    aug = pack_state(qa.path_states, qa.models_lag, z_ref[:N_X], np.zeros(2), z_ref[N_X:], z_ref[N_X:]) - qa.z_lin
    n_z = aug.shape[0]
    deviation = np.empty(qa.horizon * n_z)
    for k in range(qa.horizon):
        deviation[k * n_z:(k + 1) * n_z] = aug
    return deviation


@njit(cache=True)
def reference_gain_term(qa, z_ref):
    """The reference's share of the unconstrained minimizer (every step needs it)."""
    return np.dot(qa.gain_reference, _reference_deviation(qa, z_ref))


@njit(cache=True)
def reference_linear_term(qa, z_ref):
    """The reference's share of the QP's linear term (only a step with an active limit needs it)."""
    return np.dot(qa.gamma_t_q, _reference_deviation(qa, z_ref))


@njit(cache=True)
def reference_terms(qa, z_ref):
    """The reference's share of the unconstrained minimizer and of the QP's linear term."""
    deviation = _reference_deviation(qa, z_ref)
    return np.dot(qa.gain_reference, deviation), np.dot(qa.gamma_t_q, deviation)


@njit(cache=True)
def unconstrained_increments(qa, z_now, ref_gain_term, disturbance):
    """(du, dz, offset, within): the unconstrained minimizer, the state's deviation from the linearization
    point, the previous command repeated over the horizon, and whether du satisfies every limit (then it *is*
    the QP's solution: the QP is strictly convex and no constraint is active)."""
    dz = z_now - qa.z_lin
    du = ref_gain_term - np.dot(qa.gain_state, dz) - np.dot(qa.gain_disturbance, disturbance)
    u_prev = z_now[-N_U:].copy()
    offset = np.dot(qa.repeat, u_prev)
    cumulative = offset + np.dot(qa.cumsum, du)
    tol = 1e-9
    within = ((np.abs(du) - qa.step_limit).max() <= tol and (qa.input_lo - cumulative).max() <= tol
              and (cumulative - qa.input_hi).max() <= tol)
    return du, dz, offset, within


@njit(cache=True)
def constrained_terms(qa, dz, disturbance, ref_linear_term, offset):
    """OSQP's (q, l, u) for this step: the condensed QP's linear term and the limits on [du, cumulative u]."""
    q = np.dot(qa.gamma_t_q, np.dot(qa.phi, dz) + np.dot(qa.lam, disturbance)) - ref_linear_term
    lower = np.concatenate((-qa.step_limit, qa.input_lo - offset))
    upper = np.concatenate((qa.step_limit, qa.input_hi - offset))
    return q, lower, upper


@njit(cache=True)
def next_commands(qa, u_prev, du):
    """(steer rad, drive kN): the first increment applied to the previous commands, within the limits."""
    return (clip(u_prev[0] + du[0], -qa.steer_limit_rad, qa.steer_limit_rad),
            clip(u_prev[1] + du[1], qa.drive_min_kn, qa.drive_max_kn))
