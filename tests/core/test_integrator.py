"""The one RK4 (driftlab.core.integrator) against what the method is: on z' = lambda z one step multiplies z by RK4's
stability polynomial, the error over a fixed time falls as h^4, and the buffered form gives the same bits."""

import numpy as np

from driftlab.core.integrator import rk4_stage, rk4_stage_into, rk4_update, rk4_update_into


def _step(z, h, lam):
    k1 = lam * z
    k2 = lam * rk4_stage(z, 0.5 * h, k1)
    k3 = lam * rk4_stage(z, 0.5 * h, k2)
    k4 = lam * rk4_stage(z, h, k3)
    return rk4_update(z, h, k1, k2, k3, k4)


def test_one_step_on_a_linear_system_is_the_stability_polynomial():
    lam = np.array([-1.0, -400.0, 2.5])  # decaying, stiff like a wheel-speed mode, growing
    h = 2e-3
    x = h * lam
    expected = 1.0 + x + x**2 / 2 + x**3 / 6 + x**4 / 24
    np.testing.assert_allclose(_step(np.ones(3), h, lam), expected, rtol=1e-15, atol=0.0)


def test_the_error_over_a_second_falls_as_the_fourth_power_of_the_step():
    lam = np.array([-3.0])
    errors = []
    for n in (20, 40, 80):
        z = np.ones(1)
        for _ in range(n):
            z = _step(z, 1.0 / n, lam)
        errors.append(abs(z[0] - np.exp(-3.0)))
    orders = [np.log2(errors[i] / errors[i + 1]) for i in range(2)]
    assert all(3.9 < o < 4.1 for o in orders), orders


def test_the_buffered_form_gives_the_same_bits():
    rng = np.random.default_rng(7)
    z, k1, k2, k3, k4 = (rng.normal(size=27) for _ in range(5))
    h = 1.7e-3
    stage = np.empty(27)
    rk4_stage_into(stage, z, 0.5 * h, k2)
    assert np.array_equal(stage, rk4_stage(z, 0.5 * h, k2))
    updated = z.copy()
    rk4_update_into(updated, h, k1, k2, k3, k4)
    assert np.array_equal(updated, rk4_update(z, h, k1, k2, k3, k4))
