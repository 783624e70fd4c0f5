"""Bayesian optimization with an ask/tell interface (paper section III-C), minimizing.

Surrogate: a scikit-learn GP (ARD Matern 5/2 plus a noise term) on inputs scaled to the unit cube and
normalized outputs. Acquisition: expected improvement times the probability of success from a GP
classifier when some evaluations failed (as MATLAB bayesopt's error constraint does), so a failed
evaluation never enters the regression as an invented number. Seed points: a scrambled Latin hypercube.

Determinism and resume: every proposal is a function of (seed, told history, pending points) only. The
kernel hyperparameters are refit from a fixed starting point at history sizes that are multiples of
``refit_every``, on that prefix of the history; between refits the GP is conditioned on the whole history
with those hyperparameters held (~ms). A resumed optimizer therefore rebuilds the same state from
``tell`` calls alone (``tell`` only records; fitting happens lazily in ``ask``).

Hyperparameters are fit on at most 200 of those points (the same selection rule), which keeps a refit near
0.5 s at n = 400; the GP then conditions on the whole active set.

Active set: the GP sees at most ``active_set`` successful observations: the best half by value, and a
space-filling spread of the rest (greedy farthest-point order from the best), so that the surrogate stays
accurate near the optimum and still knows the landscape (the cost is O(active_set^3) per fit).

Batch: points asked and not yet told are pending; the next ask treats them as observed at the GP mean
("kriging believer", Ginsbourger et al. 2010), so two workers get two different points.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping

import numpy as np
from scipy.linalg import solve_triangular
from scipy.optimize import minimize
from scipy.special import erf
from scipy.stats import norm, qmc
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessClassifier, GaussianProcessRegressor
from sklearn.gaussian_process._gpc import COEFS, LAMBDAS
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Matern, WhiteKernel

from driftlab.core.errors import ConfigError
from driftlab.core.limits import check_int

_CANDIDATES = 1000
_LOCAL_STARTS = 2
_HYPER_FIT_POINTS = 200  # hyperparameters from at most this many points; the GP then conditions on all
_EI_XI = 0.0
_MIN_SUCCESS_PROBABILITY = 0.5
_FAILURE_CLEARANCE = 0.015  # unit-cube distance over which a failure suppresses proposals


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


class BayesianOptimizer:
    """GP + EI minimizer over a box.

    Args:
        bounds: name -> (lo, hi), lo < hi; proposals are dicts with these names.
        seed_points: proposals from the Latin hypercube before the GP takes over.
        active_set: most successful observations the GP is fit on.
        seed: random seed (Latin hypercube, candidate sets).
        refit_every: hyperparameter refit period in observations.
    """

    def __init__(self, bounds: Mapping[str, tuple[float, float]], *, seed_points: int = 20, active_set: int = 400,
                 seed: int = 0, refit_every: int = 10) -> None:
        if not bounds:
            raise ConfigError("bounds must name at least one parameter")
        for name, pair in bounds.items():
            lo, hi = (float(v) for v in pair)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ConfigError(f"bounds.{name} must be [lo, hi] with finite lo < hi, got {list(pair)}")
        check_int("seed_points", seed_points)
        check_int("active_set", active_set)
        self.names = list(bounds)
        self.lo = np.array([float(bounds[n][0]) for n in self.names])
        self.hi = np.array([float(bounds[n][1]) for n in self.names])
        self.seed_points = seed_points
        self.active_set = active_set
        self.seed = seed
        self.refit_every = refit_every
        self.dim = len(self.names)
        self._seed_design = qmc.LatinHypercube(d=self.dim, seed=seed).random(seed_points)
        self.x: list[np.ndarray] = []  # unit-cube inputs, told
        self.y: list[float | None] = []  # None: failed evaluation
        self.pending: list[np.ndarray] = []
        self._hyper_at = -1
        self._kernel = None
        self._clf_at = -1
        self._clf_kernel = None

    # -- public interface -------------------------------------------------------------------------------
    def ask(self) -> dict[str, float]:
        """The next point to evaluate (it stays pending until told)."""
        n_issued = len(self.x) + len(self.pending)
        unused = [d for d in self._seed_design if not self._is_repeat(d)] if n_issued < self.seed_points else []
        # The first design point not yet told or pending: after a crash, a later design point may have been
        # stored while an earlier one was lost in flight, and design[n_issued] would then run a point twice.
        unit = unused[0] if unused else self._propose()
        self.pending.append(unit)
        return self._to_theta(unit)

    def tell(self, theta: Mapping[str, float], value: float | None) -> None:
        """Record an evaluation: its value, or None for a failed one. Cheap: no fitting here."""
        unit = self._to_unit(theta)
        if value is not None and not math.isfinite(value):
            value = None
        if self.pending:
            nearest = int(np.argmin([np.abs(p - unit).max() for p in self.pending]))
            if np.abs(self.pending[nearest] - unit).max() < 1e-9:
                self.pending.pop(nearest)
        self.x.append(unit)
        self.y.append(None if value is None else float(value))

    @property
    def best(self) -> tuple[dict[str, float], float] | None:
        """The best successful (theta, value) told so far."""
        ok = [(v, i) for i, v in enumerate(self.y) if v is not None]
        if not ok:
            return None
        value, i = min(ok)
        return self._to_theta(self.x[i]), value

    # -- internals --------------------------------------------------------------------------------------
    def _to_theta(self, unit: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, self.lo + unit * (self.hi - self.lo), strict=True)}

    def _to_unit(self, theta: Mapping[str, float]) -> np.ndarray:
        missing = [n for n in self.names if n not in theta]
        if missing:
            raise ConfigError(f"theta is missing {', '.join(missing)}")
        raw = np.array([float(theta[n]) for n in self.names])
        return np.clip((raw - self.lo) / (self.hi - self.lo), 0.0, 1.0)

    def _rng(self) -> np.random.Generator:
        return np.random.default_rng([self.seed, len(self.x), len(self.pending)])

    def _propose(self) -> np.ndarray:
        x_all = np.array(self.x) if self.x else np.empty((0, self.dim))
        ok = np.array([v is not None for v in self.y], dtype=bool)
        if ok.sum() < 2:
            # Nothing to model yet: keep filling space, away from what was tried.
            return self._farthest_candidate(x_all)
        x_ok = x_all[ok]
        y_ok = np.array([v for v in self.y if v is not None])
        active = self._active_indices(x_ok, y_ok, self.active_set)
        gp = self._regressor(x_ok[active], y_ok[active])
        if self.pending:  # kriging believer: pending points observed at the GP mean
            x_pend = np.array(self.pending)
            x_fit = np.vstack([x_ok[active], x_pend])
            y_fit = np.concatenate([y_ok[active], gp.predict(x_pend)])
            gp = self._conditioned(x_fit, y_fit)
        classifier = self._classifier(x_all, ok) if not ok.all() else None
        best = float(y_ok.min())
        return self._maximize(gp, classifier, best, x_ok[int(np.argmin(y_ok))])

    def _active_indices(self, x: np.ndarray, y: np.ndarray, limit: int) -> np.ndarray:
        n = len(y)
        if n <= limit:
            return np.arange(n)
        order = np.argsort(y, kind="stable")
        keep = list(order[: limit // 2])
        rest = order[limit // 2:]
        # Farthest-point spread of the rest, starting from the kept set.
        dist = np.min(np.linalg.norm(x[rest][:, None, :] - x[keep][None, :, :], axis=2), axis=1)
        chosen = []
        for _ in range(limit - len(keep)):
            j = int(np.argmax(dist))
            chosen.append(rest[j])
            dist = np.minimum(dist, np.linalg.norm(x[rest] - x[rest[j]], axis=1))
            dist[j] = -1.0
        return np.array(keep + chosen)

    def _base_kernel(self):
        return (ConstantKernel(1.0, (1e-3, 1e3)) * Matern(length_scale=np.full(self.dim, 0.3),
                                                           length_scale_bounds=(1e-2, 1e1), nu=2.5)
                + WhiteKernel(1e-3, (1e-8, 1e-1)))

    def _regressor(self, x: np.ndarray, y: np.ndarray) -> GaussianProcessRegressor:
        """GP with hyperparameters refit at the last multiple of refit_every told (deterministic on resume)."""
        boundary = (len(self.x) // self.refit_every) * self.refit_every
        if self._kernel is None or self._hyper_at != boundary:
            ok_prefix = [(xi, yi) for xi, yi in zip(self.x[:boundary], self.y[:boundary], strict=True)
                         if yi is not None]
            if len(ok_prefix) < 2:
                ok_prefix = list(zip(x, y, strict=True))
            xp = np.array([p[0] for p in ok_prefix])
            yp = np.array([p[1] for p in ok_prefix])
            active = self._active_indices(xp, yp, min(self.active_set, _HYPER_FIT_POINTS))
            gp = GaussianProcessRegressor(self._base_kernel(), normalize_y=True, n_restarts_optimizer=0,
                                          random_state=self.seed)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                gp.fit(xp[active], yp[active])
            self._kernel = gp.kernel_
            self._hyper_at = boundary
        return self._conditioned(x, y)

    def _conditioned(self, x: np.ndarray, y: np.ndarray) -> GaussianProcessRegressor:
        gp = GaussianProcessRegressor(self._kernel, normalize_y=True, optimizer=None)
        return gp.fit(x, y)

    def _classifier(self, x: np.ndarray, ok: np.ndarray) -> SuccessProbability | None:
        """P(success) from a GP classifier; its kernel is learnt on the same schedule as the regressor's."""
        if ok.sum() == 0:
            return None
        boundary = (len(self.x) // self.refit_every) * self.refit_every
        if self._clf_kernel is None or self._clf_at != boundary:
            ok_prefix = ok[:boundary]
            if 0 < ok_prefix.sum() < boundary:
                kernel = ConstantKernel(4.0, (1e-1, 1e3)) * RBF(np.full(self.dim, 0.3), (0.05, 5.0))
                clf = GaussianProcessClassifier(kernel, random_state=self.seed)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", ConvergenceWarning)
                    clf.fit(x[:boundary], ok_prefix.astype(int))
                self._clf_kernel = clf.kernel_
            else:
                self._clf_kernel = ConstantKernel(4.0) * RBF(np.full(self.dim, 0.3))
            self._clf_at = boundary
        # warm_start: sklearn searches the Laplace mode twice in one fit (for the likelihood, then for
        # prediction); the second search starts from the first one's mode. Nothing carries over between fits.
        classifier = GaussianProcessClassifier(self._clf_kernel, optimizer=None, warm_start=True)
        return SuccessProbability(classifier.fit(x, ok.astype(int)))

    def _acquisition(self, gp, classifier, best: float, x: np.ndarray) -> np.ndarray:
        mean, std = gp.predict(x, return_std=True)
        std = np.maximum(std, 1e-12)
        z = (best - mean - _EI_XI) / std
        ei = (best - mean - _EI_XI) * norm.cdf(z) + std * norm.pdf(z)
        if classifier is not None:
            # EI weighted by P(success), and zero where success is less likely than not (a probabilistic
            # constraint, Gelbart, Snoek & Adams 2014): where the regressor has no data its EI is large, and
            # a soft weight alone lets it keep probing the failing region.
            p_success = classifier(x)
            ei = ei * p_success * (p_success >= _MIN_SUCCESS_PROBABILITY) * self._failure_clearance(x)
        return ei

    def _failure_clearance(self, x: np.ndarray) -> np.ndarray:
        """1 - exp(-(d / r)^2), d the distance to the nearest failed point: where the failure boundary runs
        close past the optimum, the classifier still says "likely success" right next to a failure, and EI
        would propose the same failing point again and again."""
        failed = np.array([xi for xi, yi in zip(self.x, self.y, strict=True) if yi is None])
        if len(failed) == 0:
            return np.ones(len(x))
        d2 = np.min(((x[:, None, :] - failed[None, :, :]) ** 2).sum(axis=2), axis=1)
        return 1.0 - np.exp(-d2 / _FAILURE_CLEARANCE**2)

    def _maximize(self, gp, classifier, best: float, x_best: np.ndarray) -> np.ndarray:
        rng = self._rng()
        local = np.clip(x_best + rng.normal(0.0, 0.05, (_CANDIDATES // 4, self.dim)), 0.0, 1.0)
        candidates = np.vstack([rng.random((_CANDIDATES, self.dim)), local])
        values = self._acquisition(gp, classifier, best, candidates)
        if values.max() <= 0.0 and classifier is not None:
            # Success looks unlikely everywhere: try where it is likeliest.
            return candidates[int(np.argmax(classifier(candidates)))]
        starts = candidates[np.argsort(-values)[:_LOCAL_STARTS]]
        best_x, best_v = starts[0], float(values.max())

        step = 1e-5

        def negative_with_gradient(u):
            # Value and forward-difference gradient in one batched prediction (one GP solve, not d + 1).
            probes = np.vstack([u, u + step * np.eye(self.dim)])
            values = -self._acquisition(gp, classifier, best, probes)
            return float(values[0]), (values[1:] - values[0]) / step

        for start in starts:
            res = minimize(negative_with_gradient, start, jac=True, method="L-BFGS-B",
                           bounds=[(0.0, 1.0)] * self.dim, options={"maxiter": 15})
            if np.all(np.isfinite(res.x)) and -res.fun > best_v:
                best_x, best_v = np.clip(res.x, 0.0, 1.0), -float(res.fun)
        if self._is_repeat(best_x):
            return rng.random(self.dim)
        return best_x

    def _is_repeat(self, unit: np.ndarray) -> bool:
        tried = self.x + self.pending
        return bool(tried) and float(np.min(np.abs(np.array(tried) - unit).max(axis=1))) < 1e-6

    def _farthest_candidate(self, x_all: np.ndarray) -> np.ndarray:
        candidates = self._rng().random((_CANDIDATES, self.dim))
        taken = np.vstack([x_all, np.array(self.pending).reshape(-1, self.dim)])
        if len(taken) == 0:
            return candidates[0]
        dist = np.min(np.linalg.norm(candidates[:, None, :] - taken[None, :, :], axis=2), axis=1)
        return candidates[int(np.argmax(dist))]
