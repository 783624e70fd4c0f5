"""Offset-free MPC's disturbance estimate (not in the paper; Maeder, Borrelli & Morari 2009): a constant additive
disturbance on (Vdot, betadot, rdot), from the measured state against the model's one-step prediction."""

from __future__ import annotations

from numba import njit

from driftlab.core.mpc.kernels import clip
from driftlab.core.mpc_config import N_X


@njit(cache=True)
def update_estimate(estimate, n_updates, innovation, gain, start_gain, dt_s, limit):
    """Offset-free MPC's disturbance estimate d on (Vdot, betadot, rdot), a first-order filter; ``estimate`` and
    the count ``n_updates[0]`` change in place (a frozen estimate is simply not updated).

    The measurement d_meas = innovation / dt = (x_meas - x_pred) / dt, x_pred being the controller model's
    one-step prediction without disturbance; d follows it through d += g (d_meas - d), clipped to ``limit``. The
    gain starts as a running mean capped at ``start_gain``, g = max(gain, min(start_gain, 1 / n)) over the first
    n measurements: the episode starts at the *model's* drift, so the mismatch matters most then, and a plain
    small gain leaves the car metres off its circle; an uncapped running mean takes the first, transient,
    measurements at full weight and throws the car out of the drift.
    """
    if gain > 0.0:
        n_updates[0] += 1
        step_gain = max(gain, min(start_gain, 1.0 / n_updates[0]))
        measured = innovation / dt_s
        value = estimate + step_gain * (measured - estimate)
        for i in range(N_X):
            estimate[i] = clip(value[i], -limit[i], limit[i])
    return estimate
