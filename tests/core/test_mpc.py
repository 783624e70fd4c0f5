"""The condensed MPC QP: exact against an independent solve, constraints respected."""

import numpy as np
import pytest
from scipy.optimize import Bounds, LinearConstraint, minimize

from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.mpc import MpcConfig, ReferenceQp, to_scaled
from driftlab.core.vehicle import VehicleParams, pack_params

P = pack_params(VehicleParams())
RIGHT = drift_equilibrium(44.0, 0.4, P)
LEFT = drift_equilibrium(44.0, -0.4, P)


def _independent_solution(qp: ReferenceQp, z_now, z_ref):
    """Minimize the uncondensed cost by simulating the linear model directly (SLSQP, tight tolerance)."""
    cfg = qp.config
    n_h = cfg.horizon
    weights = np.diag(cfg.state_weights)
    r_w = np.diag(cfg.input_weights)

    def cost(du_flat):
        du = du_flat.reshape(n_h, 2)
        x = z_now[:3] - qp.z_lin[:3]
        u = z_now[3:] - qp.z_lin[3:]
        total = 0.0
        for k in range(n_h):
            u = u + du[k]
            x = qp.ad @ x + qp.bd @ u
            err = np.concatenate([x, u]) - (z_ref - qp.z_lin)
            total += err @ weights @ err + du[k] @ r_w @ du[k]
        return total

    # The cost is quadratic: its gradient and Hessian by central differences are exact up to rounding.
    n = 2 * n_h
    eye = np.eye(n)
    grad0 = np.array([(cost(eye[i]) - cost(-eye[i])) / 2.0 for i in range(n)])
    hess = np.array([[(cost(eye[i] + eye[j]) - cost(eye[i] - eye[j]) - cost(-eye[i] + eye[j])
                       + cost(-eye[i] - eye[j])) / 4.0 for j in range(n)] for i in range(n)])
    u_prev = np.tile(z_now[3:], n_h)
    constraints = [LinearConstraint(qp.cumsum, qp.input_lo - u_prev, qp.input_hi - u_prev)]
    res = minimize(lambda d: 0.5 * d @ hess @ d + grad0 @ d, np.zeros(n), jac=lambda d: hess @ d + grad0,
                   hess=lambda d: hess, method="trust-constr", constraints=constraints,
                   bounds=Bounds(-qp.step_limit, qp.step_limit),
                   options={"gtol": 1e-12, "xtol": 1e-14, "maxiter": 5000})
    return res.x, cost


@pytest.mark.parametrize("discretization", ["euler", "zoh"])
def test_constrained_solution_matches_independent_solve(discretization):
    config = MpcConfig(discretization=discretization, osqp_eps=1e-9)
    qp = ReferenceQp(config, RIGHT, P)
    # Just after a left-to-right switch: the car is in the left drift, the reference is the right one.
    z_now = to_scaled(LEFT.state, LEFT.inputs)
    z_ref = to_scaled(RIGHT.state, RIGHT.inputs)
    sol = qp.solve(z_now, z_ref, np.zeros(3))
    assert sol.used_osqp and sol.ok
    expected, cost = _independent_solution(qp, z_now, z_ref)
    assert cost(sol.increments) == pytest.approx(cost(expected), rel=1e-6)
    np.testing.assert_allclose(sol.increments, expected, atol=2e-4)


def test_solution_respects_every_limit():
    config = MpcConfig()
    qp = ReferenceQp(config, RIGHT, P)
    z_now = to_scaled(LEFT.state, LEFT.inputs)
    sol = qp.solve(z_now, to_scaled(RIGHT.state, RIGHT.inputs), np.zeros(3))
    du = sol.increments
    tol = 1e-6
    assert np.all(np.abs(du) <= qp.step_limit + tol)
    cumulative = np.tile(z_now[3:], config.horizon) + qp.cumsum @ du
    assert np.all(cumulative <= qp.input_hi + tol) and np.all(cumulative >= qp.input_lo - tol)
    assert abs(sol.steer_rad - LEFT.steer_rad) <= config.steer_rate_radps * config.dt_s + tol


def test_unconstrained_shortcut_equals_the_qp_solution():
    config = MpcConfig(osqp_eps=1e-10)
    qp = ReferenceQp(config, LEFT, P)
    z_ref = to_scaled(LEFT.state, LEFT.inputs)
    z_now = z_ref + np.array([0.05, 0.002, -0.003, 0.0, 0.0])
    fast = qp.solve(z_now, z_ref, np.zeros(3))
    assert not fast.used_osqp
    expected, cost = _independent_solution(qp, z_now, z_ref)
    np.testing.assert_allclose(fast.increments, expected, atol=1e-5)


def test_at_the_reference_the_mpc_holds_the_equilibrium_inputs():
    qp = ReferenceQp(MpcConfig(), LEFT, P)
    z = to_scaled(LEFT.state, LEFT.inputs)
    sol = qp.solve(z, z, np.zeros(3))
    assert sol.steer_rad == pytest.approx(LEFT.steer_rad, abs=1e-12)
    assert sol.drive_force_n == pytest.approx(LEFT.drive_force_n, abs=1e-8)
