"""The acquisition functions on their own: expected improvement's closed form against Monte Carlo and its limits,
the failure clearance and the success constraint (driftlab.core.acquisition)."""

import numpy as np
import pytest

from driftlab.core.acquisition import constrained_ei, expected_improvement, failure_clearance


@pytest.mark.parametrize(("mean", "std", "best", "xi"), [(0.0, 1.0, 0.0, 0.0), (1.3, 0.4, 1.0, 0.0),
                                                        (-2.0, 0.1, -1.5, 0.0), (0.5, 2.5, 0.2, 0.1),
                                                        (3.0, 0.5, 0.0, 0.0)])
def test_expected_improvement_is_the_mean_of_the_improvement_over_the_gaussian(mean, std, best, xi):
    rng = np.random.default_rng(11)
    f = mean + std * rng.standard_normal(2_000_000)
    monte_carlo = np.maximum(best - xi - f, 0.0)
    closed = expected_improvement(np.array([mean]), np.array([std]), best, xi)[0]
    # Four standard errors of the sample mean; far in the tail (z = -6) the sample sees no improvement at all.
    tolerance = max(4 * monte_carlo.std() / np.sqrt(len(f)), 1e-9)
    assert abs(closed - monte_carlo.mean()) <= tolerance


def test_expected_improvement_without_uncertainty_is_the_plain_improvement_and_grows_with_std():
    mean = np.array([0.5, 1.0, 1.5])
    np.testing.assert_allclose(expected_improvement(mean, np.zeros(3), best=1.0), [0.5, 0.0, 0.0], atol=1e-12)
    stds = np.linspace(0.1, 3.0, 50)
    ei = expected_improvement(np.full(50, 1.5), stds, best=1.0)
    assert np.all(np.diff(ei) > 0) and np.all(ei > 0)
    lower_mean = expected_improvement(np.linspace(2.0, -2.0, 50), np.full(50, 0.3), best=0.0)
    assert np.all(np.diff(lower_mean) > 0)  # minimization: a lower predicted mean improves more


def test_the_clearance_is_zero_on_a_failure_and_one_far_from_all():
    failed = np.array([[0.2, 0.2], [0.8, 0.5]])
    x = np.array([[0.2, 0.2], [0.8, 0.5], [0.2 + 0.05, 0.2], [5.0, 5.0]])
    clearance = failure_clearance(x, failed, radius=0.05)
    np.testing.assert_allclose(clearance, [0.0, 0.0, 1.0 - np.exp(-1.0), 1.0], atol=1e-12)
    np.testing.assert_array_equal(failure_clearance(x, np.zeros((0, 2)), radius=0.05), np.ones(4))


def test_the_success_constraint_zeroes_what_is_too_likely_to_fail_and_weights_the_rest():
    ei = np.array([1.0, 1.0, 2.0, 2.0])
    p = np.array([0.9, 0.05, 0.5, 0.2])
    out = constrained_ei(ei, p, np.array([1.0, 1.0, 0.5, 1.0]), min_probability=0.25)
    np.testing.assert_allclose(out, [0.9, 0.0, 0.5, 0.0])
