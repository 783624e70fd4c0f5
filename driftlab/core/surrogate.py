"""The GP surrogate: ARD Matern 5/2 plus noise on the unit cube, outputs normalized (Rasmussen & Williams 2006,
ch. 2 and 5).

Written out in numpy rather than taken from scikit-learn because BO asks hundreds of times per job with the
same hyperparameters: what costs is conditioning (one Cholesky factor, reused), adding pending points (a block
update of that factor, O(n^2 q)) and batched prediction, none of which sklearn's estimator API exposes.
The hyperparameters are fit by L-BFGS-B on the log marginal likelihood with its analytic gradient (eq. 5.9).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, overload

import numpy as np
from scipy.optimize import minimize

from driftlab.core.lapack import cho_solve_lower, cholesky_lower, solve_lower

_SQRT5 = math.sqrt(5.0)
# Bounds of the log hyperparameters: length scales (unit cube), signal variance and noise variance (both on the
# normalized output).
LENGTH_SCALE_BOUNDS = (1e-2, 1e1)
SIGNAL_BOUNDS = (1e-3, 1e3)
NOISE_BOUNDS = (1e-8, 1e-1)


@dataclass(frozen=True)
class Hyperparameters:
    length_scales: np.ndarray  # per input dimension, on the unit cube
    signal_variance: float
    noise_variance: float

    @classmethod
    def default(cls, dim: int) -> Hyperparameters:
        return cls(np.full(dim, 0.3), 1.0, 1e-3)

    def as_log_vector(self) -> np.ndarray:
        return np.log(np.concatenate([self.length_scales, [self.signal_variance, self.noise_variance]]))

    @classmethod
    def from_log_vector(cls, v: np.ndarray) -> Hyperparameters:
        return cls(np.exp(v[:-2]), float(np.exp(v[-2])), float(np.exp(v[-1])))


def _scaled_distances(a: np.ndarray, b: np.ndarray, length_scales: np.ndarray) -> np.ndarray:
    """Length-scaled Euclidean distances between the rows of a and b, through one matrix product (the
    broadcast difference cost ten times more at n = 400)."""
    a_s, b_s = a / length_scales, b / length_scales
    sq = (a_s * a_s).sum(axis=1)[:, None] + (b_s * b_s).sum(axis=1)[None, :] - 2.0 * (a_s @ b_s.T)
    return np.sqrt(np.maximum(sq, 0.0))


def matern52(a: np.ndarray, b: np.ndarray, hp: Hyperparameters) -> np.ndarray:
    """k(a, b) = s^2 (1 + sqrt5 r + 5/3 r^2) exp(-sqrt5 r), r the length-scaled distance."""
    r = _scaled_distances(a, b, hp.length_scales)
    return hp.signal_variance * (1.0 + _SQRT5 * r + (5.0 / 3.0) * r * r) * np.exp(-_SQRT5 * r)


def log_marginal_likelihood(log_hp: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[float, np.ndarray]:
    """log p(y | x, theta) and its gradient in the log hyperparameters (R&W eq. 2.30 and 5.9)."""
    hp = Hyperparameters.from_log_vector(log_hp)
    n, dim = x.shape
    diff = (x[:, None, :] - x[None, :, :]) / hp.length_scales  # (n, n, d)
    sq = diff * diff
    r = np.sqrt(np.maximum(sq.sum(axis=2), 0.0))
    e = np.exp(-_SQRT5 * r)
    k_f = hp.signal_variance * (1.0 + _SQRT5 * r + (5.0 / 3.0) * r * r) * e
    k = k_f + hp.noise_variance * np.eye(n)
    try:
        chol = cholesky_lower(k)
    except np.linalg.LinAlgError:
        return -1e25, np.zeros_like(log_hp)
    alpha = cho_solve_lower(chol, y)
    lml = -0.5 * y @ alpha - np.log(np.diag(chol)).sum() - 0.5 * n * math.log(2.0 * math.pi)
    inner = np.outer(alpha, alpha) - cho_solve_lower(chol, np.eye(n))
    grad = np.empty(dim + 2)
    # d k / d log(l_i) = s^2 (5/3) (1 + sqrt5 r) exp(-sqrt5 r) (x_i - x'_i)^2 / l_i^2
    radial = hp.signal_variance * (5.0 / 3.0) * (1.0 + _SQRT5 * r) * e
    for i in range(dim):
        grad[i] = 0.5 * np.sum(inner * (radial * sq[:, :, i]))
    grad[dim] = 0.5 * np.sum(inner * k_f)
    grad[dim + 1] = 0.5 * hp.noise_variance * np.trace(inner)
    return float(lml), grad


def fit_hyperparameters(x: np.ndarray, y: np.ndarray, start: Hyperparameters, max_iter: int = 50) -> Hyperparameters:
    """Maximum-likelihood hyperparameters for normalized outputs ``y``, from ``start`` (deterministic)."""
    dim = x.shape[1]
    bounds = [tuple(np.log(LENGTH_SCALE_BOUNDS))] * dim + [tuple(np.log(SIGNAL_BOUNDS)), tuple(np.log(NOISE_BOUNDS))]

    def negative(v):
        value, grad = log_marginal_likelihood(v, x, y)
        return -value, -grad

    start_v = np.clip(start.as_log_vector(), [b[0] for b in bounds], [b[1] for b in bounds])
    result = minimize(negative, start_v, jac=True, method="L-BFGS-B", bounds=bounds, options={"maxiter": max_iter})
    best = result.x if np.all(np.isfinite(result.x)) and result.fun <= negative(start_v)[0] else start_v
    return Hyperparameters.from_log_vector(best)


class GaussianProcess:
    """A GP conditioned on (x, y) with fixed hyperparameters; y is normalized internally.

    Args:
        x: (n, d) inputs on the unit cube.
        y: (n,) outputs.
        hp: hyperparameters for the normalized outputs.
    """

    def __init__(self, x: np.ndarray, y: np.ndarray, hp: Hyperparameters) -> None:
        self.hp = hp
        self.y_mean = float(np.mean(y))
        std = float(np.std(y))
        self.y_std = std if std > 1e-12 else 1.0
        self.x = np.asarray(x, float)
        self.z = (np.asarray(y, float) - self.y_mean) / self.y_std
        k = matern52(self.x, self.x, hp) + (hp.noise_variance + 1e-10) * np.eye(len(self.x))
        self.chol = cholesky_lower(k)
        self.alpha = cho_solve_lower(self.chol, self.z)

    @overload
    def predict(self, xq: np.ndarray, return_std: Literal[True] = ...) -> tuple[np.ndarray, np.ndarray]: ...

    @overload
    def predict(self, xq: np.ndarray, return_std: Literal[False]) -> tuple[np.ndarray, None]: ...

    def predict(self, xq: np.ndarray, return_std: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Posterior mean and standard deviation (of the latent function) at the rows of ``xq``."""
        k_star = matern52(self.x, xq, self.hp)
        mean = k_star.T @ self.alpha
        if not return_std:
            return self.y_mean + self.y_std * mean, None
        v = solve_lower(self.chol, k_star)
        var = np.maximum(self.hp.signal_variance - np.einsum("ij,ij->j", v, v), 1e-18)
        return self.y_mean + self.y_std * mean, self.y_std * np.sqrt(var)

    def with_observations(self, x_new: np.ndarray, y_new: np.ndarray) -> GaussianProcess:
        """This GP also conditioned on (x_new, y_new), keeping the normalization: a block update of the Cholesky
        factor, O(n^2 q) instead of O((n + q)^3)."""
        hp = self.hp
        out = object.__new__(GaussianProcess)
        out.hp, out.y_mean, out.y_std = hp, self.y_mean, self.y_std
        out.x = np.vstack([self.x, x_new])
        out.z = np.concatenate([self.z, (np.asarray(y_new, float) - self.y_mean) / self.y_std])
        cross = solve_lower(self.chol, matern52(self.x, x_new, hp))
        corner = matern52(x_new, x_new, hp) + (hp.noise_variance + 1e-10) * np.eye(len(x_new)) - cross.T @ cross
        n, q = len(self.x), len(x_new)
        chol = np.zeros((n + q, n + q))
        chol[:n, :n] = self.chol
        chol[n:, :n] = cross.T
        chol[n:, n:] = cholesky_lower(corner + 1e-12 * np.eye(q))
        out.chol = chol
        out.alpha = cho_solve_lower(chol, out.z)
        return out
