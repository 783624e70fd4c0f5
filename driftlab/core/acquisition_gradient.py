"""The constrained expected improvement and its exact gradient at one point, compiled: what the optimizer's local
searches (L-BFGS-B from the best candidates) evaluate a few dozen times an ask.

The value is :func:`driftlab.core.acquisition.constrained_ei` of the GP's prediction (driftlab.core.surrogate), the
classifier's P(success) (driftlab.core.failure_model) and the clearance from failures, as the batched path computes
it for the candidates (to rounding); the gradient is analytic:

- GP (Matern 5/2, R&W eq. 4.17): dk/du = -(5/3) s^2 (1 + sqrt5 r) exp(-sqrt5 r) (u - x) / l^2; the mean's gradient
  is alpha^T dk/du, the variance's -2 (K^-1 k)^T dk/du (R&W eq. 2.26).
- Classifier (Laplace, GPML Algorithm 3.2): the same for its RBF kernel, with (W^-1 + K)^-1 written as
  W^1/2 B^-1 W^1/2; P(success) is Williams & Barber's sum of error functions, which for a latent N(m, v) is
  sum_j c_j erf(lambda_j m / sqrt(1 + 2 lambda_j^2 v)) / 2 + sum_j c_j / 2, differentiated in m and v.
- EI (Jones et al. 1998): dEI/dmean = -Phi(z), dEI/dstd = phi(z); the clearance 1 - exp(-d^2 / rho^2) through its
  nearest failure.

One point costs two pairs of n x n triangular solves (LAPACK's dpotrs, called from the kernel through scipy's
``cython_lapack``), where a forward-difference gradient in d dimensions predicts d + 1 points through the batched
path (the two, measured: docs/benchmarks.md, "Exact gradients in the local searches").
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core.extending import intrinsic
from numba.extending import get_cython_function_address

from driftlab.core.failure_model import COEFS, LAMBDAS, SuccessProbability
from driftlab.core.surrogate import GaussianProcess, Hyperparameters

_SQRT5 = math.sqrt(5.0)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
_INV_SQRT_PI = 1.0 / math.sqrt(math.pi)
_UPPER = ord("U")


@cache  # looked up once a process: the address changes between processes, so it is an argument, never compiled in
def dpotrs_address() -> int:
    """The address of LAPACK's dpotrs in scipy's ``cython_lapack``."""
    return int(get_cython_function_address("scipy.linalg.cython_lapack", "dpotrs"))


@intrinsic
def _call8(typingctx, function, a1, a2, a3, a4, a5, a6, a7, a8):
    """``function(a1, ..., a8)``, a C function of eight pointers, by its address."""
    sig = types.void(types.int64, *([types.int64] * 8))

    def codegen(context, builder, signature, args):
        pointer = ir.IntType(8).as_pointer()
        callee = builder.inttoptr(args[0], ir.FunctionType(ir.VoidType(), [pointer] * 8).as_pointer())
        builder.call(callee, [builder.inttoptr(a, pointer) for a in args[1:]])
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True)
def _cho_solve(dpotrs, chol, b, scratch):
    """b := (L L^T)^-1 b in place; ``chol`` holds L in C order, whose memory is L^T in LAPACK's (Fortran) order;
    ``scratch`` an int32 buffer of 6."""
    n = chol.shape[0]
    scratch[0] = _UPPER
    scratch[1] = n
    scratch[2] = 1
    scratch[3] = n
    scratch[4] = n
    scratch[5] = 0
    _call8(dpotrs, scratch[0:].ctypes.data, scratch[1:].ctypes.data, scratch[2:].ctypes.data, chol.ctypes.data,
           scratch[3:].ctypes.data, b.ctypes.data, scratch[4:].ctypes.data, scratch[5:].ctypes.data)


@njit(cache=True)
def _scaled_squared_distances(u, x, length_scales):
    """|(u - x_i) / l|^2 for each row x_i of ``x``."""
    n, d = x.shape
    r2 = np.zeros(n)
    for i in range(n):
        for j in range(d):
            step = (u[j] - x[i, j]) / length_scales[j]
            r2[i] += step * step
    return r2


@njit(cache=True)
def _kernel_gradient(radial, u, x, length_scales):
    """dk_i/du for a stationary kernel whose derivative is ``radial[i]`` (u - x_i) / l^2."""
    n, d = x.shape
    dk = np.empty((n, d))
    for i in range(n):
        for j in range(d):
            dk[i, j] = radial[i] * (u[j] - x[i, j]) / (length_scales[j] * length_scales[j])
    return dk


@njit(cache=True)
def _moments(k, dk, weights, solved):
    """The posterior mean k^T weights, the explained variance k^T solved (solved = the kernel matrix's inverse times
    k), and their gradients (the second one's with the factor 2 of d(k^T A^-1 k) = 2 (A^-1 k)^T dk, negated)."""
    n, d = dk.shape
    mean, explained = 0.0, 0.0
    dmean, dvar = np.zeros(d), np.zeros(d)
    for i in range(n):
        mean += k[i] * weights[i]
        explained += k[i] * solved[i]
        for j in range(d):
            dmean[j] += weights[i] * dk[i, j]
            dvar[j] -= 2.0 * solved[i] * dk[i, j]
    return mean, explained, dmean, dvar


@njit(cache=True)
def _gp(dpotrs, u, x, alpha, chol, length_scales, signal_variance, y_mean, y_std, scratch):
    """The GP's posterior mean and standard deviation at ``u`` and their gradients in ``u``."""
    r2 = _scaled_squared_distances(u, x, length_scales)
    r = np.sqrt(r2)
    e = np.exp(-_SQRT5 * r)
    k = signal_variance * (1.0 + _SQRT5 * r + (5.0 / 3.0) * r2) * e
    dk = _kernel_gradient(-(5.0 / 3.0) * signal_variance * (1.0 + _SQRT5 * r) * e, u, x, length_scales)
    w = k.copy()
    _cho_solve(dpotrs, chol, w, scratch)
    mean, explained, dmean, dvar = _moments(k, dk, alpha, w)
    variance = signal_variance - explained
    if variance <= 1e-18:  # the batched prediction's floor: flat there
        return y_mean + y_std * mean, y_std * 1e-9, y_std * dmean, np.zeros(u.shape[0])
    std = math.sqrt(variance)
    return y_mean + y_std * mean, y_std * std, y_std * dmean, (y_std / (2.0 * std)) * dvar


@njit(cache=True)
def _success(dpotrs, u, x, coef, w_sr, chol, length_scales, constant, lambdas, coefs, scratch):
    """The classifier's P(success) at ``u`` and its gradient in ``u``."""
    k = constant * np.exp(-0.5 * _scaled_squared_distances(u, x, length_scales))
    dk = _kernel_gradient(-k, u, x, length_scales)
    w = w_sr * k
    _cho_solve(dpotrs, chol, w, scratch)
    w *= w_sr  # (W^-1 + K)^-1 k = W^1/2 B^-1 W^1/2 k
    mean, explained, dmean, dvar = _moments(k, dk, coef, w)
    variance = constant - explained
    p, dp_dmean, dp_dvar = 0.0, 0.0, 0.0
    for m in range(lambdas.shape[0]):
        spread = 1.0 + 2.0 * lambdas[m] * lambdas[m] * variance
        t = lambdas[m] * mean / math.sqrt(spread)
        p += coefs[m] * 0.5 * (math.erf(t) + 1.0)
        slope = coefs[m] * _INV_SQRT_PI * math.exp(-t * t)
        dp_dmean += slope * lambdas[m] / math.sqrt(spread)
        dp_dvar -= slope * lambdas[m] ** 3 * mean / spread**1.5
    return p, dp_dmean * dmean + dp_dvar * dvar


@njit(cache=True)
def _clearance(u, failed, radius):
    """1 - exp(-d^2 / radius^2) from the nearest failure, and its gradient in ``u``."""
    d = u.shape[0]
    nearest, best = -1, np.inf
    for i in range(failed.shape[0]):
        d2 = 0.0
        for j in range(d):
            step = u[j] - failed[i, j]
            d2 += step * step
        if d2 < best:
            nearest, best = i, d2
    if nearest < 0:
        return 1.0, np.zeros(d)
    e = math.exp(-best / (radius * radius))
    return 1.0 - e, (2.0 * e / (radius * radius)) * (u - failed[nearest])


@njit(cache=True)
def _negative_constrained_ei(dpotrs, u, gp_x, gp_alpha, gp_chol, gp_scales, gp_signal, y_mean, y_std,
                             best, xi, with_classifier, c_x, c_coef, c_w_sr, c_chol, c_scales, c_constant,
                             lambdas, coefs, failed, radius, min_probability, scratch):
    mean, std, dmean, dstd = _gp(dpotrs, u, gp_x, gp_alpha, gp_chol, gp_scales, gp_signal, y_mean, y_std, scratch)
    if std < 1e-12:  # expected_improvement's floor
        std, dstd = 1e-12, np.zeros(u.shape[0])
    gap = best - mean - xi
    z = gap / std
    cdf = 0.5 * math.erfc(-z / math.sqrt(2.0))
    pdf = _INV_SQRT_2PI * math.exp(-0.5 * z * z)
    ei = gap * cdf + std * pdf
    dei = -cdf * dmean + pdf * dstd
    if not with_classifier:
        return -ei, -dei
    p, dp = _success(dpotrs, u, c_x, c_coef, c_w_sr, c_chol, c_scales, c_constant, lambdas, coefs, scratch)
    if p < min_probability:
        return 0.0, np.zeros(u.shape[0])
    clear, dclear = _clearance(u, failed, radius)
    return -ei * p * clear, -(dei * p * clear + ei * dp * clear + ei * p * dclear)


def _c(values) -> np.ndarray:
    """A writable C-ordered float64 copy: the one array type the kernel is compiled for (a Fortran-ordered Cholesky
    factor included, whose C-ordered copy's memory is L^T in LAPACK's order)."""
    return np.array(values, dtype=float, order="C")


class NegativeConstrainedEI:
    """u -> (-constrained EI at u, its gradient), for ``scipy.optimize.minimize(..., jac=True)``: the acquisition the
    optimizer maximizes (driftlab.core.optimizer), EI alone without a classifier."""

    def __init__(self, gp: GaussianProcess, classifier: SuccessProbability | None, best: float, xi: float,
                 failed: np.ndarray, radius: float, min_probability: float) -> None:
        dim = gp.x.shape[1]
        self._gp = (_c(gp.x), _c(gp.alpha), _c(gp.chol), _c(gp.hp.length_scales), float(gp.hp.signal_variance),
                    gp.y_mean, gp.y_std)
        if classifier is not None:
            kernel = classifier.kernel
            self._classifier = (True, _c(classifier.x_train), _c(classifier.coef), _c(classifier.w_sr),
                                _c(classifier.chol_lower), _c(np.broadcast_to(kernel.length_scales, dim)),
                                float(kernel.constant))
        else:  # not read: EI alone
            self._classifier = (False, np.zeros((1, dim)), np.zeros(1), np.ones(1), np.eye(1), np.ones(dim), 1.0)
        self._rest = (_c(LAMBDAS[:, 0]), _c(COEFS[:, 0]), _c(failed).reshape(-1, dim), float(radius),
                      float(min_probability))
        self._best, self._xi = float(best), float(xi)
        self._scratch = np.zeros(6, dtype=np.int32)
        self._dpotrs = dpotrs_address()

    def __call__(self, u: np.ndarray) -> tuple[float, np.ndarray]:
        value, gradient = _negative_constrained_ei(self._dpotrs, np.ascontiguousarray(u, dtype=float), *self._gp,
                                                   self._best, self._xi, *self._classifier, *self._rest,
                                                   self._scratch)
        return float(value), gradient


def warm_up() -> None:
    """Compile the kernel (or load it from numba's cache) now, not in a job's first ask (~3 s once an install)."""
    x = np.array([[0.25, 0.5], [0.75, 0.5]])
    gp = GaussianProcess(x, np.array([0.0, 1.0]), Hyperparameters.default(2))
    NegativeConstrainedEI(gp, None, 0.0, 0.0, np.empty((0, 2)), 0.1, 0.5)(np.array([0.5, 0.5]))
