"""The condensed MPC QP: exact against an independent solve, constraints respected."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import Bounds, LinearConstraint, minimize

from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.mpc import MpcConfig, QpSession, ReferenceQp, to_scaled
from driftlab.core.vehicle import VehicleParams, pack_params

P = pack_params(VehicleParams())
RIGHT = drift_equilibrium(44.0, 0.4, P)
LEFT = drift_equilibrium(44.0, -0.4, P)


def _independent_solution(qp: ReferenceQp, z_now, z_ref):
    """Minimize the uncondensed cost by simulating the linear model directly (trust-constr, tight tolerance)."""
    cfg = qp.config
    n_h = cfg.horizon
    n_x = qp.ad.shape[0]  # model states, plus actuator states when the lag is modelled
    held = [np.zeros(2)] if qp.models_lag else []
    weights = np.diag(np.concatenate([cfg.state_weights, cfg.actuator_weights, *held]))
    r_w = np.diag(cfg.input_weights)
    z_ref = qp.augmented_reference(z_ref)

    def cost(du_flat):
        du = du_flat.reshape(n_h, 2)
        x = z_now[:n_x] - qp.z_lin[:n_x]
        u = z_now[n_x:] - qp.z_lin[n_x:]
        total = 0.0
        for k in range(n_h):
            u = u + du[k]
            x = qp.ad @ x + qp.bd @ u
            err = np.concatenate([x, u]) - (z_ref - qp.z_lin)
            total += err @ weights @ err + du[k] @ r_w @ du[k]
        return total

    # The cost is quadratic: its gradient and Hessian by finite differences are exact up to rounding.
    n = 2 * n_h
    eye = np.eye(n)
    at_zero = cost(np.zeros(n))
    plus = np.array([cost(eye[i]) for i in range(n)])
    grad0 = (plus - np.array([cost(-eye[i]) for i in range(n)])) / 2.0
    hess = np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            hess[i, j] = hess[j, i] = cost(eye[i] + eye[j]) - plus[i] - plus[j] + at_zero
    u_prev = np.tile(z_now[n_x:], n_h)
    constraints = [LinearConstraint(qp.cumsum, qp.input_lo - u_prev, qp.input_hi - u_prev)]
    res = minimize(lambda d: 0.5 * d @ hess @ d + grad0 @ d, np.zeros(n), jac=lambda d: hess @ d + grad0,
                   hess=lambda d: hess, method="trust-constr", constraints=constraints,
                   bounds=Bounds(-qp.step_limit, qp.step_limit),
                   options={"gtol": 1e-12, "xtol": 1e-14, "maxiter": 5000})
    return res.x, cost


@pytest.mark.parametrize("config", [
    replace(MpcConfig.paper(), osqp_eps=1e-9),
    replace(MpcConfig.paper(), osqp_eps=1e-9, discretization="zoh"),
    replace(MpcConfig(), osqp_eps=1e-9, terminal_cost=False),  # path states and actuator lags
    replace(MpcConfig.paper(), qp_solver="daqp"),
    replace(MpcConfig(), qp_solver="osqp", osqp_eps=1e-9, terminal_cost=False),
], ids=["paper-euler", "paper-zoh", "default", "paper-daqp", "default-osqp"])
def test_constrained_solution_matches_independent_solve(config):
    qp = ReferenceQp(config, RIGHT, P)
    # Just after a left-to-right switch: the car is in the left drift, the reference is the right one.
    z_left = to_scaled(LEFT.state, LEFT.inputs)
    z_now = qp.pack_state(z_left[:3], np.array([0.4, -0.05]), z_left[3:], z_left[3:])
    z_ref = to_scaled(RIGHT.state, RIGHT.inputs)
    sol = QpSession(qp).solve(z_now, z_ref, np.zeros(3))
    assert sol.used_osqp and sol.ok
    expected, cost = _independent_solution(qp, z_now, z_ref)
    assert cost(sol.increments) == pytest.approx(cost(expected), rel=1e-6)
    np.testing.assert_allclose(sol.increments, expected, atol=2e-4)


def _packed(qp, eq, path_errors=(0.0, 0.0)):
    z = to_scaled(eq.state, eq.inputs)
    return qp.pack_state(z[:3], np.array(path_errors), z[3:], z[3:])


def test_solution_respects_every_limit():
    config = MpcConfig()
    qp = ReferenceQp(config, RIGHT, P)
    z_now = _packed(qp, LEFT, (0.5, 0.02))
    sol = QpSession(qp).solve(z_now, to_scaled(RIGHT.state, RIGHT.inputs), np.zeros(3))
    du = sol.increments
    # OSQP's primal feasibility tolerance: eps_abs + eps_rel * |bound| (the applied input is clipped exactly).
    tol = config.osqp_eps * (1.0 + np.max(np.abs(qp.input_lo)))
    assert np.all(np.abs(du) <= qp.step_limit + tol)
    cumulative = np.tile(z_now[-2:], config.horizon) + qp.cumsum @ du
    assert np.all(cumulative <= qp.input_hi + tol) and np.all(cumulative >= qp.input_lo - tol)
    assert abs(sol.steer_rad - LEFT.steer_rad) <= config.steer_rate_radps * config.dt_s + tol
    assert abs(sol.steer_rad) <= config.steer_limit_rad


def test_unconstrained_shortcut_equals_the_qp_solution():
    config = MpcConfig(osqp_eps=1e-10, terminal_cost=False)
    qp = ReferenceQp(config, LEFT, P)
    z_ref = to_scaled(LEFT.state, LEFT.inputs)
    z_now = _packed(qp, LEFT, (0.1, -0.01))
    z_now[:3] += np.array([0.05, 0.002, -0.003])
    fast = QpSession(qp).solve(z_now, z_ref, np.zeros(3))
    assert not fast.used_osqp
    expected, cost = _independent_solution(qp, z_now, z_ref)
    np.testing.assert_allclose(fast.increments, expected, atol=1e-5)


def test_at_the_reference_the_mpc_holds_the_equilibrium_inputs():
    qp = ReferenceQp(MpcConfig(), LEFT, P)
    z = to_scaled(LEFT.state, LEFT.inputs)
    sol = QpSession(qp).solve(_packed(qp, LEFT), z, np.zeros(3))
    assert sol.steer_rad == pytest.approx(LEFT.steer_rad, abs=1e-12)
    assert sol.drive_force_n == pytest.approx(LEFT.drive_force_n, abs=1e-8)


def test_terminal_cost_makes_the_unconstrained_mpc_the_lqr():
    """With the Riccati cost-to-go as the last stage's weight, the MPC's first move is the infinite-horizon LQR
    gain (dynamic programming), whatever the horizon; without it a 20-step MPC's gain differs."""
    import scipy.linalg

    for terminal, horizon in ((True, 20), (True, 5), (False, 20)):
        qp = ReferenceQp(replace(MpcConfig(), terminal_cost=terminal, horizon=horizon), LEFT, P)
        n_sys, n_z = qp.ad.shape[0], qp.n_z
        aa = np.zeros((n_z, n_z))
        aa[:n_sys, :n_sys], aa[:n_sys, n_sys:], aa[n_sys:, n_sys:] = qp.ad, qp.bd, np.eye(2)
        ba = np.vstack([qp.bd, np.eye(2)])
        cfg = qp.config
        q_mat = np.diag(np.concatenate([cfg.state_weights, cfg.actuator_weights, np.zeros(2)]))
        r_mat = np.diag(cfg.input_weights)
        p_mat = scipy.linalg.solve_discrete_are(aa, ba, q_mat + 1e-9 * np.eye(n_z), r_mat)
        k_lqr = np.linalg.solve(r_mat + ba.T @ p_mat @ ba, ba.T @ p_mat @ aa)
        k_mpc = qp.gain_state[:2]
        if terminal:
            np.testing.assert_allclose(k_mpc, k_lqr, rtol=1e-5, atol=1e-6 * np.abs(k_lqr).max())
            assert np.abs(np.linalg.eigvals(aa - ba @ k_mpc)).max() < 1.0
        else:
            assert np.abs(k_mpc - k_lqr).max() > 1e-3 * np.abs(k_lqr).max()
