"""The optimizer's failure model: the probability that a theta completes, from a Laplace GP classifier fitted on
the evaluations told (which completed, which failed)."""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular
from scipy.optimize import minimize
from scipy.special import erf
from sklearn.gaussian_process import GaussianProcessClassifier
from sklearn.gaussian_process._gpc import COEFS, LAMBDAS

CLASSIFIER_FIT_ITERATIONS = 20


def bounded_lbfgs(obj_func, initial_theta, bounds):
    """sklearn's default classifier optimizer (L-BFGS-B on the log marginal likelihood) with at most 20
    iterations: run to convergence it took 20-60 ms at a refit, and the hyperparameters move little after."""
    result = minimize(obj_func, initial_theta, method="L-BFGS-B", jac=True, bounds=bounds,
                      options={"maxiter": CLASSIFIER_FIT_ITERATIONS})
    return result.x, result.fun


class SuccessProbability:
    """P(success) of a fitted binary Laplace GP classifier, as sklearn's ``predict_proba`` computes it (GPML
    Algorithm 3.2, Williams & Barber's erf approximation), but with a triangular solve against the stored
    Cholesky factor: sklearn solves it as a general matrix (an LU factorization of n x n per call), which
    made the acquisition's many small calls cost ~2 ms each at n = 400."""

    def __init__(self, classifier: GaussianProcessClassifier) -> None:
        fitted = classifier.base_estimator_
        self.kernel = fitted.kernel_
        self.x_train = fitted.X_train_
        self.coef = fitted.y_train_ - fitted.pi_
        self.w_sr = fitted.W_sr_
        self.chol_lower = fitted.L_

    def __call__(self, x: np.ndarray) -> np.ndarray:
        k_star = self.kernel(self.x_train, x)
        mean = k_star.T @ self.coef
        v = solve_triangular(self.chol_lower, self.w_sr[:, None] * k_star, lower=True, check_finite=False)
        var = self.kernel.diag(x) - np.einsum("ij,ij->j", v, v)
        alpha = 1.0 / (2.0 * var)
        gamma = LAMBDAS * mean
        integrals = (np.sqrt(np.pi / alpha) * erf(gamma * np.sqrt(alpha / (alpha + LAMBDAS**2)))
                     / (2.0 * np.sqrt(var * 2.0 * np.pi)))
        return (COEFS * integrals).sum(axis=0) + 0.5 * COEFS.sum()
