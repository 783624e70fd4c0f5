"""The local searches' compiled acquisition (driftlab.core.acquisition_gradient) against the batched one the candidates
are rated with (GaussianProcess.predict, SuccessProbability, constrained_ei): the same value, and a gradient that is
the batched value's derivative (central differences of the batched path, an independent implementation)."""

import numpy as np
import pytest

from driftlab.core.acquisition import constrained_ei, expected_improvement, failure_clearance
from driftlab.core.acquisition_gradient import NegativeConstrainedEI
from driftlab.core.failure_model import LabelKernel, SuccessProbability
from driftlab.core.surrogate import GaussianProcess, Hyperparameters

DIM, RADIUS, MIN_P = 4, 0.05, 0.5


def _models(pending: bool):
    rng = np.random.default_rng(3)
    x = rng.random((60, DIM))
    y = np.sin(3.0 * x[:, 0]) + (x[:, 1] - 0.4) ** 2 + 0.1 * x[:, 2] * x[:, 3]
    ok = x[:, 0] + 0.3 * x[:, 1] < 1.0  # a failing corner
    hp = Hyperparameters(np.array([0.3, 0.5, 0.8, 1.2]), 1.3, 1e-4)
    gp = GaussianProcess(x[ok], y[ok], hp)
    if pending:  # kriging believer: the factor is block-updated (C-ordered)
        x_pending = rng.random((2, DIM))
        gp = gp.with_observations(x_pending, gp.predict(x_pending, return_std=False)[0])
    kernel = LabelKernel(2.0, np.array([0.4, 0.6, 1.0, 1.0]))
    classifier = SuccessProbability.conditioned(kernel, x, ok.astype(int))
    return gp, classifier, x[~ok], float(y[ok].min())


def _batched(gp, classifier, failed, best, points):
    mean, std = gp.predict(points)
    ei = expected_improvement(mean, std, best)
    if classifier is None:
        return ei
    return constrained_ei(ei, classifier(points), failure_clearance(points, failed, RADIUS), MIN_P)


@pytest.mark.parametrize("pending", [False, True])
@pytest.mark.parametrize("with_classifier", [True, False])
def test_the_value_is_the_batched_acquisition_and_the_gradient_its_derivative(pending, with_classifier):
    gp, classifier, failed, best = _models(pending)
    classifier = classifier if with_classifier else None
    negative = NegativeConstrainedEI(gp, classifier, best, 0.0, failed, RADIUS, MIN_P)
    points = np.random.default_rng(5).random((40, DIM))
    reference = _batched(gp, classifier, failed, best, points)
    values = np.array([-negative(u)[0] for u in points])
    np.testing.assert_allclose(values, reference, rtol=1e-9, atol=1e-12 * reference.max())
    checked = 0
    h = 1e-6
    for u, value in zip(points, reference, strict=True):
        probes = np.vstack([u + h * np.eye(DIM), u - h * np.eye(DIM)])
        around = _batched(gp, classifier, failed, best, probes)
        if value <= 0.0 or np.any(around <= 0.0):  # at the success constraint's step: no derivative
            continue
        central = (around[:DIM] - around[DIM:]) / (2 * h)
        gradient = -negative(u)[1]
        np.testing.assert_allclose(gradient, central, rtol=1e-4, atol=1e-6 * np.abs(central).max())
        checked += 1
    assert checked >= 10  # most points are away from the constraint's edge


def test_a_point_likelier_to_fail_than_allowed_is_flat_zero():
    gp, classifier, failed, best = _models(False)
    negative = NegativeConstrainedEI(gp, classifier, best, 0.0, failed, RADIUS, MIN_P)
    corner = np.array([0.98, 0.9, 0.5, 0.5])  # deep in the failing corner
    assert classifier(corner[None])[0] < MIN_P
    value, gradient = negative(corner)
    assert value == 0.0 and not gradient.any()
