"""Classical fourth-order Runge-Kutta, the one integrator of every model DriftLab steps: the plants' substeps
(:mod:`driftlab.core.plant`, :mod:`driftlab.core.commonroad.plant`, :mod:`driftlab.core.commonroad.mb_plant`, and the
pure-Python reference :mod:`driftlab.core.commonroad.reference`) and the estimator's one-step prediction
(:func:`driftlab.core.controller.predict_one_step`).

Each model calls its own derivatives (their arguments differ: held commands, actuator lags, inputs that move during
the step), so what is shared is the method's arithmetic: the stage points ``z + c h k`` and the update
``z + (h / 6)(k1 + 2 k2 + 2 k3 + k4)``, each in one order of operations, so that every model integrates the same
floating-point way (an episode's bits depend on it). Numba functions, callable from Python as they are; the ``_into``
forms write into a buffer, for a model whose substep must allocate nothing (MB).
"""

from __future__ import annotations

from numba import njit


@njit(cache=True, inline="always")
def rk4_stage(z, step_s, k):
    """The point ``z + step_s k`` where the next stage's derivatives are taken (``step_s``: h/2 or h)."""
    return z + step_s * k


@njit(cache=True, inline="always")
def rk4_update(z, h_s, k1, k2, k3, k4):
    """The state after one step of ``h_s``: ``z + (h_s / 6)(k1 + 2 k2 + 2 k3 + k4)``."""
    return z + (h_s / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


@njit(cache=True, inline="always")
def rk4_stage_into(out, z, step_s, k):
    """:func:`rk4_stage` written into ``out``."""
    for i in range(z.shape[0]):
        out[i] = z[i] + step_s * k[i]


@njit(cache=True, inline="always")
def rk4_update_into(z, h_s, k1, k2, k3, k4):
    """:func:`rk4_update` in place, in ``z``."""
    sixth = h_s / 6.0
    for i in range(z.shape[0]):
        z[i] = z[i] + sixth * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
