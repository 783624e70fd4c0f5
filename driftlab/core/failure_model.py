"""The optimizer's failure model: the probability that a theta completes, from a Laplace GP classifier fitted on
the evaluations told (which completed, which failed)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve
from scipy.optimize import minimize
from scipy.spatial.distance import cdist, pdist, squareform
from scipy.special import erf, expit

from driftlab.core.lapack import cho_solve_lower, cholesky_lower, solve_lower

CLASSIFIER_FIT_ITERATIONS = 20
# Williams & Barber's approximation of the logistic by five error functions, as sklearn's predict_proba takes it
# (GPML section 3.9): the erf scales, and the weights of the least-squares fit of logistic(x) by (erf(lambda x) + 1) / 2
# at x = 0, 0.6, 2, 3.5, 4.5, inf, as sklearn rounded them (tests/core/test_optimizer.py fits them again and compares
# with sklearn's). Copied, not imported: importing sklearn's _gpc module took ~0.45 s more in every process that asks.
LAMBDAS = np.array([0.41, 0.4, 0.37, 0.44, 0.39])[:, np.newaxis]
COEFS = np.array([-1854.8214151, 3516.89893646, 221.29346712, 128.12323805, -2010.49422654])[:, np.newaxis]
_NEWTON_ITERATIONS = 100  # sklearn's max_iter_predict
_NEWTON_TOLERANCE = 1e-10  # on the log marginal likelihood, as sklearn's posterior mode search stops
# The label kernel before any fit, and the box its fit searches (unit-cube inputs).
_START_CONSTANT, _START_LENGTH_SCALE = 4.0, 0.3
_CONSTANT_BOUNDS, _LENGTH_SCALE_BOUNDS = (1e-1, 1e3), (0.05, 5.0)


def bounded_lbfgs(obj_func, initial_theta, bounds):
    """sklearn's default classifier optimizer (L-BFGS-B on the log marginal likelihood) with at most 20
    iterations: run to convergence it took 20-60 ms at a refit, and the hyperparameters move little after."""
    result = minimize(obj_func, initial_theta, method="L-BFGS-B", jac=True, bounds=bounds,
                      options={"maxiter": CLASSIFIER_FIT_ITERATIONS})
    return result.x, result.fun


@dataclass(frozen=True)
class LabelKernel:
    """k(a, b) = c exp(-|a - b|^2_l / 2): sklearn's ``ConstantKernel(c) * RBF(l)`` (ARD), evaluated with the same
    operations (the same bits) without its per-call parameter handling."""

    constant: float
    length_scales: np.ndarray

    @classmethod
    def start(cls, dim: int) -> LabelKernel:
        """The kernel before any fit."""
        return cls(_START_CONSTANT, np.squeeze(np.full(dim, _START_LENGTH_SCALE)).astype(float))

    @property
    def log_parameters(self) -> np.ndarray:
        """sklearn's theta: log c, then the log length scales."""
        return np.log(np.hstack([self.constant, self.length_scales]))

    @classmethod
    def from_log_parameters(cls, theta: np.ndarray) -> LabelKernel:
        return cls(float(np.exp(theta[0])), np.squeeze(np.exp(theta[1:])).astype(float))

    def fitted(self, x: np.ndarray, labels: np.ndarray) -> LabelKernel:
        """The kernel that maximizes the Laplace log marginal likelihood of (x, labels 0/1), from this one, c in
        [0.1, 1000] and each length scale in [0.05, 5]: what sklearn's ``GaussianProcessClassifier(ConstantKernel(c,
        (1e-1, 1e3)) * RBF(l, (0.05, 5.0)), optimizer=bounded_lbfgs).fit(x, labels)`` learns, to the bit
        (tests/core/test_optimizer.py), without its estimator's per-call overhead."""
        log_bounds = np.log(np.vstack([_CONSTANT_BOUNDS] + [_LENGTH_SCALE_BOUNDS] * np.size(self.length_scales)))
        theta, _ = bounded_lbfgs(lambda t: _negative_lml(t, x, labels), self.log_parameters, log_bounds)
        return LabelKernel.from_log_parameters(theta)

    def round_tripped(self) -> LabelKernel:
        """The kernel as sklearn rebuilds it from its log-parameters (``clone_with_theta(theta)``): its likelihood
        pass evaluates this one, which can differ from the kernel itself in the last bit."""
        return LabelKernel.from_log_parameters(self.log_parameters)

    def gram(self, x: np.ndarray) -> np.ndarray:
        return self.constant * _rbf_gram(x, self.length_scales)[1]

    def cross(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return self.constant * np.exp(-0.5 * cdist(a / self.length_scales, b / self.length_scales,
                                                   metric="sqeuclidean"))


def _posterior_mode(k: np.ndarray, labels: np.ndarray, f: np.ndarray) -> _Mode:
    """Newton's search for the Laplace mode of a binary GP classifier (GPML Algorithm 3.1), as sklearn runs it."""
    lml_before = -np.inf
    for _ in range(_NEWTON_ITERATIONS):
        pi = expit(f)
        w = pi * (1 - pi)
        w_sr = np.sqrt(w)
        w_sr_k = w_sr[:, np.newaxis] * k
        chol = cholesky_lower(np.eye(w.shape[0]) + w_sr_k * w_sr)
        b = w * f + (labels - pi)
        a = b - w_sr * cho_solve_lower(chol, w_sr_k.dot(b))
        f = k.dot(a)
        lml = -0.5 * a.T.dot(f) - np.log1p(np.exp(-(labels * 2 - 1) * f)).sum() - np.log(np.diag(chol)).sum()
        if lml - lml_before < _NEWTON_TOLERANCE:
            break
        lml_before = lml
    return _Mode(lml_before, f, pi, w_sr, chol, a)


@dataclass(frozen=True)
class _Mode:
    """A mode search's outcome: the approximate log marginal likelihood (the step before the last, as sklearn
    reports it), the mode f, and pi, sqrt(W), L and a of the last step."""

    lml: float
    f: np.ndarray
    pi: np.ndarray
    w_sr: np.ndarray
    chol: np.ndarray
    a: np.ndarray


def _rbf_gram(x: np.ndarray, length_scales: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The squared scaled distances (condensed) and the unit RBF Gram matrix, as sklearn's RBF computes them."""
    dists = pdist(x / length_scales, metric="sqeuclidean")
    k = squareform(np.exp(-0.5 * dists))
    np.fill_diagonal(k, 1)
    return dists, k


def _kernel_and_gradient(theta: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """K and dK/dtheta of ``ConstantKernel * RBF`` at log-parameters theta, as sklearn's Product computes them."""
    kernel = LabelKernel.from_log_parameters(theta)
    constant, length_scales = kernel.constant, kernel.length_scales
    dists, k_rbf = _rbf_gram(x, length_scales)
    if length_scales.ndim == 0:  # one dimension: sklearn's isotropic gradient
        rbf_gradient = (k_rbf * squareform(dists))[:, :, np.newaxis]
    else:
        rbf_gradient = (x[:, np.newaxis, :] - x[np.newaxis, :, :]) ** 2 / (length_scales**2)
        rbf_gradient *= k_rbf[..., np.newaxis]
    # sklearn multiplies by an array full of c: the same products as by c itself
    gradient = np.dstack((constant * k_rbf[:, :, np.newaxis], rbf_gradient * constant))
    return constant * k_rbf, gradient


def _negative_lml(theta: np.ndarray, x: np.ndarray, labels: np.ndarray) -> tuple[float, np.ndarray]:
    """-log p(labels | x, theta) under the Laplace approximation and its gradient (GPML Algorithm 5.1), the
    objective sklearn's classifier fit minimizes."""
    k, k_gradient = _kernel_and_gradient(theta, x)
    mode = _posterior_mode(k, labels, np.zeros(len(labels)))
    pi, w_sr, chol, a = mode.pi, mode.w_sr, mode.chol, mode.a
    r = w_sr[:, np.newaxis] * cho_solve_lower(chol, np.diag(w_sr))
    c = solve(chol, w_sr[:, np.newaxis] * k)
    s_2 = -0.5 * (np.diag(k) - np.einsum("ij, ij -> j", c, c)) * (pi * (1 - pi) * (1 - 2 * pi))
    gradient = np.empty(theta.shape[0])
    for j in range(gradient.shape[0]):
        c = k_gradient[:, :, j]
        s_1 = 0.5 * a.T.dot(c).dot(a) - 0.5 * r.T.ravel().dot(c.ravel())
        b = c.dot(labels - pi)
        s_3 = b - k.dot(r.dot(b))
        gradient[j] = s_1 + s_2.T.dot(s_3)
    return -mode.lml, -gradient


class SuccessProbability:
    """P(success) of a binary Laplace GP classifier, as sklearn's ``predict_proba`` computes it (GPML Algorithm 3.2,
    Williams & Barber's erf approximation), but with a triangular solve against the stored Cholesky factor: sklearn
    solves it as a general matrix (an LU factorization of n x n per call), which made the acquisition's many small
    calls cost ~2 ms each at n = 400. Conditioned here rather than through sklearn's estimator, whose per-fit
    validation, kernel objects and wrapped solves were most of an ask's classifier time (its kernel is learnt the
    same way, :meth:`LabelKernel.fitted`)."""

    def __init__(self, kernel: LabelKernel, x_train: np.ndarray, coef: np.ndarray, w_sr: np.ndarray,
                 chol_lower: np.ndarray) -> None:
        self.kernel, self.x_train, self.coef, self.w_sr, self.chol_lower = kernel, x_train, coef, w_sr, chol_lower

    @classmethod
    def conditioned(cls, kernel: LabelKernel, x: np.ndarray, labels: np.ndarray) -> SuccessProbability:
        """Conditioned on (x, labels 0/1) with the kernel held, as sklearn's ``GaussianProcessClassifier(kernel,
        optimizer=None, warm_start=True).fit(x, labels)`` conditions it (the same bits: tests/core/test_optimizer.py):
        the mode of the likelihood pass (its kernel rebuilt from the log-parameters), then the search again from
        that mode, whose last step's factors predict."""
        first = _posterior_mode(kernel.round_tripped().gram(x), labels, np.zeros(len(labels)))
        last = _posterior_mode(kernel.gram(x), labels, first.f)
        return cls(kernel, x, labels - last.pi, last.w_sr, last.chol)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        k_star = self.kernel.cross(self.x_train, x)
        mean = k_star.T @ self.coef
        v = solve_lower(self.chol_lower, self.w_sr[:, None] * k_star)
        var = np.full(len(x), self.kernel.constant) - np.einsum("ij,ij->j", v, v)
        alpha = 1.0 / (2.0 * var)
        gamma = LAMBDAS * mean
        integrals = (np.sqrt(np.pi / alpha) * erf(gamma * np.sqrt(alpha / (alpha + LAMBDAS**2)))
                     / (2.0 * np.sqrt(var * 2.0 * np.pi)))
        return (COEFS * integrals).sum(axis=0) + 0.5 * COEFS.sum()
