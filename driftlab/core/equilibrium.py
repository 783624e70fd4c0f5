"""Drift equilibria of the single-track model, its Jacobians and local stability.

The drift family is parametrized by the sideslip beta at a given radius R (docs/reference.md, The car: at
R = 44 m, V = 19.1 m/s alone has six equilibria). Solving Vdot = betadot = rdot = 0 with r = V / R
(paper section II-B) for (V, delta, Fxr) from several starts, we keep the countersteer branch: delta
opposite to r, front tyre below its force peak, rear tyre beyond it.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numba import njit

from driftlab.core.errors import NoEquilibriumError
from driftlab.core.minpack import hybr
from driftlab.core.vehicle import (
    P_STEER_OFFSET,
    P_TYRE_B,
    P_TYRE_C,
    drift_derivatives,
    drift_derivatives_vec,
    slip_angles,
)

_RESIDUAL_TOL = 1e-9
_START_SPEEDS_MPS = (6.0, 12.0, 19.0, 26.0, 35.0)
_START_STEERS_RAD = (-0.5, -0.3, -0.15, -0.03)
_START_DRIVE_KN = (1.0, 4.0, 8.0)


@dataclass(frozen=True)
class Equilibrium:
    """A steady drift: constant V, beta, r under constant inputs delta, Fxr."""

    speed_mps: float
    sideslip_rad: float
    yaw_rate_radps: float
    steer_rad: float
    drive_force_n: float

    @property
    def state(self) -> np.ndarray:
        """[V, beta, r]."""
        return np.array([self.speed_mps, self.sideslip_rad, self.yaw_rate_radps])

    @property
    def inputs(self) -> np.ndarray:
        """[delta, Fxr]."""
        return np.array([self.steer_rad, self.drive_force_n])

    def mirrored(self) -> Equilibrium:
        """The opposite-hand drift: beta, r and delta flip sign; V and Fxr stay (paper eq. 9)."""
        return Equilibrium(self.speed_mps, -self.sideslip_rad, -self.yaw_rate_radps, -self.steer_rad,
                           self.drive_force_n)

    def as_dict(self) -> dict[str, float]:
        """The SI keys the CLI prints: V, beta, r, delta, Fxr."""
        return {"V": self.speed_mps, "beta": self.sideslip_rad, "r": self.yaw_rate_radps,
                "delta": self.steer_rad, "Fxr": self.drive_force_n}


@njit(cache=True)
def _residual(unknowns, radius_m, sideslip_rad, p):
    """(Vdot, betadot V, rdot) at unknowns (V, delta, Fxr kN), r = V / R. Compiled: the 60 starts of one
    equilibrium call it ~800 times, and a solve takes 3.4 ms instead of 5.1 ms in Python (the same floating-point
    operations, the same bits: tests/core/test_vehicle.py)."""
    speed = unknowns[0]
    if 0.1 > speed:  # max(speed, 0.1) as Python takes it: a NaN speed stays NaN
        speed = 0.1
    derivs = drift_derivatives(speed, sideslip_rad, speed / radius_m, unknowns[1], unknowns[2] * 1e3, p)
    # Scale each equation to ~O(1) at drift conditions so one tolerance fits all three.
    out = np.empty(3)
    out[0], out[1], out[2] = derivs[0], derivs[1] * speed, derivs[2]
    return out


def peak_slip_rad(p: np.ndarray) -> float:
    """Slip angle at which the simplified Pacejka force peaks: C atan(B alpha) = pi/2."""
    return math.tan(math.pi / (2.0 * p[P_TYRE_C])) / p[P_TYRE_B]


def _is_countersteer_drift(eq: Equilibrium, p: np.ndarray) -> bool:
    steer = eq.steer_rad + p[P_STEER_OFFSET]  # what the model's tyres see
    alpha_f, alpha_r = slip_angles(eq.speed_mps, eq.sideslip_rad, eq.yaw_rate_radps, steer, p)
    peak = peak_slip_rad(p)
    return (steer * eq.yaw_rate_radps < 0.0 and abs(alpha_f) < peak < abs(alpha_r)
            and abs(eq.steer_rad) < 1.0)


def drift_equilibrium(radius_m: float, sideslip_rad: float, p: np.ndarray) -> Equilibrium:
    """The countersteer drift equilibrium at radius R and sideslip beta.

    Args:
        radius_m: path radius R > 0 [m]; r = V / R.
        sideslip_rad: beta [rad]; beta < 0 gives a left-hand drift (r > 0), beta > 0 its mirror image.
        p: packed parameters (:func:`driftlab.core.vehicle.pack_params`): the model's or a plant's.

    Returns:
        The equilibrium with Vdot = betadot = rdot = 0 to 1e-9.

    Raises:
        NoEquilibriumError: no countersteer drift exists at this (R, beta) for these parameters.
    """
    if not (radius_m > 0.0 and math.isfinite(radius_m)):
        raise NoEquilibriumError(f"radius must be positive and finite, got radius={radius_m!r}")
    if not (0.0 < abs(sideslip_rad) < 1.2):
        raise NoEquilibriumError(f"a drift needs 0 < |beta| < 1.2 rad, got beta={sideslip_rad!r} "
                                 f"(radius={radius_m})")
    found = list(_countersteer_drifts(radius_m, -abs(sideslip_rad), p))
    if not found:
        raise NoEquilibriumError(f"no countersteer drift equilibrium at radius={radius_m} m, "
                                 f"beta={sideslip_rad} rad")
    # Distinct starts converge to the same branch; keep the slowest if several remain.
    best = min(found, key=lambda e: e.speed_mps)
    best = _polish(best, radius_m, p)
    return best if sideslip_rad < 0 else best.mirrored()


def has_drift_equilibrium(radius_m: float, sideslip_rad: float, p: np.ndarray) -> bool:
    """Whether :func:`drift_equilibrium` finds the drift (does not raise): its starts in its order, up to the first
    that converges to a countersteer drift (a feasible model answers after one or a few of the 60, ~0.2 ms)."""
    if not (radius_m > 0.0 and math.isfinite(radius_m) and 0.0 < abs(sideslip_rad) < 1.2):
        return False
    return next(_countersteer_drifts(radius_m, -abs(sideslip_rad), p), None) is not None


def _countersteer_drifts(radius_m: float, left_beta: float, p: np.ndarray) -> Iterator[Equilibrium]:
    """The countersteer drift each start converges to (left-hand form), in the starts' order."""
    for v0, d0, f0 in itertools.product(_START_SPEEDS_MPS, _START_STEERS_RAD, _START_DRIVE_KN):
        x, _ = hybr(_residual, np.array([v0, d0, f0]), (radius_m, left_beta, p))
        if not np.all(np.isfinite(x)) or np.max(np.abs(_residual(x, radius_m, left_beta, p))) > 1e-7:
            continue
        speed, steer, drive_kn = x
        if speed <= 0.5:
            continue
        eq = Equilibrium(speed, left_beta, speed / radius_m, steer, drive_kn * 1e3)
        if _is_countersteer_drift(eq, p):
            yield eq


def _polish(eq: Equilibrium, radius_m: float, p: np.ndarray) -> Equilibrium:
    """A few Newton steps with tight tolerance so residuals sit below _RESIDUAL_TOL."""
    x0 = np.array([eq.speed_mps, eq.steer_rad, eq.drive_force_n * 1e-3])
    (speed, steer, drive_kn), _ = hybr(_residual, x0, (radius_m, eq.sideslip_rad, p), xtol=1e-14)
    return Equilibrium(speed, eq.sideslip_rad, speed / radius_m, steer, drive_kn * 1e3)


@njit(cache=True)
def jacobians(state, inputs, p):
    """Jacobians A = df/dx (3x3) and B = df/du (3x2) of the drift model at (x, u).

    Fourth-order central differences on the compiled dynamics: steps of 1e-3 relative for V and Fxr,
    1e-4 rad for the angles and the yaw rate (checked against finite differences in the tests).
    """
    a_mat = np.empty((3, 3))
    b_mat = np.empty((3, 2))
    for j in range(5):
        if j == 0:
            h = 1e-3 * max(1.0, abs(state[0]))
        elif j == 4:
            h = 1e-3 * max(1.0, abs(inputs[1]))
        else:
            h = 1e-4
        col = np.zeros(3)
        for k, w in ((-2.0, 1.0), (-1.0, -8.0), (1.0, 8.0), (2.0, -1.0)):
            x = state.copy()
            u = inputs.copy()
            if j < 3:
                x[j] += k * h
            else:
                u[j - 3] += k * h
            col += w * drift_derivatives_vec(x, u, p)
        col /= 12.0 * h
        if j < 3:
            a_mat[:, j] = col
        else:
            b_mat[:, j - 3] = col
    return a_mat, b_mat


def eigenvalues(eq: Equilibrium, p: np.ndarray) -> np.ndarray:
    """Eigenvalues [1/s] of the linearization with inputs held: a drift equilibrium is a saddle."""
    a_mat, _ = jacobians(eq.state, eq.inputs, p)
    return np.linalg.eigvals(a_mat)
