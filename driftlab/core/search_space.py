"""What a job's search space looks like to its models, for display: the GP's mean and uncertainty of J over two
theta coordinates (the others held at the best theta), the learned probability of failure there, and each
coordinate's importance.

The models are refit here from the stored history, the way the optimizer fits them (:mod:`driftlab.core.optimizer`):
the regression GP (ARD Matern 5/2, :mod:`driftlab.core.surrogate`) on the completed evaluations only, its
hyperparameters by maximum likelihood on at most ``HYPER_FIT_POINTS`` of them; the failure model a Laplace GP
classifier (ARD RBF) on completed against failed. They are not the optimizer's exact state at any ask (that one
holds its hyperparameters between refits and conditions on pending points), but the same models on the same data.

Importance: the ARD relevance of each coordinate, 1 / l_i^2 of the GP's length scale l_i on the unit cube,
normalized to sum to 1. A short length scale means J changes quickly along that coordinate. It measures local
sensitivity of the fitted surface, not a variance decomposition (fANOVA); a coordinate the data never varied
keeps a long length scale and shows as unimportant.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessClassifier
from sklearn.gaussian_process.kernels import RBF, ConstantKernel

from driftlab.core.errors import ConfigError
from driftlab.core.limits import MAX_GRID
from driftlab.core.surrogate import GaussianProcess, Hyperparameters, fit_hyperparameters

HYPER_FIT_POINTS = 80  # as the optimizer: hyperparameters from at most this many points
MAX_MODEL_POINTS = 400  # the GPs condition on at most this many evaluations (O(n^3)): the best half and a spread


@dataclass(frozen=True)
class SearchSpaceModels:
    """The regression GP and the failure classifier of a history, on the unit cube of ``bounds``."""

    names: tuple[str, ...]
    lo: np.ndarray
    hi: np.ndarray
    gp: GaussianProcess | None  # None: fewer than 2 completed evaluations
    classifier: GaussianProcessClassifier | None  # None: no failure, or no completion
    best_theta: dict[str, float] | None

    def to_unit(self, theta: Mapping[str, float]) -> np.ndarray:
        raw = np.array([float(theta[n]) for n in self.names])
        return np.clip((raw - self.lo) / (self.hi - self.lo), 0.0, 1.0)

    def importance(self) -> dict[str, float] | None:
        """ARD relevance 1 / l^2 per coordinate, summing to 1 (see the module docstring)."""
        if self.gp is None:
            return None
        relevance = 1.0 / np.asarray(self.gp.hp.length_scales) ** 2
        return {n: float(r) for n, r in zip(self.names, relevance / relevance.sum(), strict=True)}

    def length_scales(self) -> dict[str, float] | None:
        """The GP's length scales in theta's own units (unit-cube scale times the bound's span)."""
        if self.gp is None:
            return None
        spans = self.hi - self.lo
        return {n: float(ls * s) for n, ls, s in zip(self.names, self.gp.hp.length_scales, spans, strict=True)}


@dataclass(frozen=True)
class Surface:
    """J's GP mean and standard deviation, and P(failure), on a grid of two coordinates (rows: y, columns: x)."""

    x_key: str
    y_key: str
    x_values: np.ndarray
    y_values: np.ndarray
    held: dict[str, float]  # the other coordinates' values
    mean_J: np.ndarray | None
    std_J: np.ndarray | None
    p_failure: np.ndarray | None


def _subset(x: np.ndarray, y: np.ndarray, limit: int) -> np.ndarray:
    """At most ``limit`` rows: the best half by value, the rest evenly through the others (deterministic)."""
    if len(y) <= limit:
        return np.arange(len(y))
    order = np.argsort(y, kind="stable")
    keep, rest = order[: limit // 2], order[limit // 2:]
    picks = rest[np.linspace(0, len(rest) - 1, limit - len(keep)).astype(int)]
    return np.concatenate([keep, picks])


def fit_models(bounds: Mapping[str, Sequence[float]], thetas: Sequence[Mapping[str, float]],
               values: Sequence[float], completed: Sequence[bool]) -> SearchSpaceModels:
    """Fit the display models to a job's history.

    Args:
        bounds: theta name -> (lo, hi), the job's search box.
        thetas, values, completed: the evaluations, in order (a failed evaluation's value is its penalty and is
            not regressed on).

    Raises:
        ConfigError: lengths differ, or a bound is empty.
    """
    if not len(thetas) == len(values) == len(completed):
        raise ConfigError("thetas, values and completed must have the same length")
    names = tuple(bounds)
    lo = np.array([float(bounds[n][0]) for n in names])
    hi = np.array([float(bounds[n][1]) for n in names])
    if not np.all(hi > lo):
        raise ConfigError("bounds: every [lo, hi] needs lo < hi", field="bounds")
    if not thetas:
        return SearchSpaceModels(names, lo, hi, None, None, None)
    x = np.clip((np.array([[float(t.get(n, 0.0)) for n in names] for t in thetas]) - lo) / (hi - lo), 0.0, 1.0)
    y = np.asarray(values, dtype=float)
    ok = np.asarray(completed, dtype=bool) & np.isfinite(y)
    best_theta = None
    gp = None
    if ok.sum() >= 2:
        x_ok, y_ok = x[ok], y[ok]
        chosen = _subset(x_ok, y_ok, MAX_MODEL_POINTS)
        fit = _subset(x_ok, y_ok, HYPER_FIT_POINTS)
        y_fit = y_ok[fit]
        y_fit = (y_fit - y_fit.mean()) / (y_fit.std() if y_fit.std() > 1e-12 else 1.0)
        hp = fit_hyperparameters(x_ok[fit], y_fit, Hyperparameters.default(len(names)))
        gp = GaussianProcess(x_ok[chosen], y_ok[chosen], hp)
    if ok.any():
        i = int(np.flatnonzero(ok)[np.argmin(y[ok])])
        best_theta = {n: float(v) for n, v in zip(names, lo + x[i] * (hi - lo), strict=True)}
    return SearchSpaceModels(names, lo, hi, gp, _classifier(x, ok), best_theta)


def _classifier(x: np.ndarray, ok: np.ndarray) -> GaussianProcessClassifier | None:
    if ok.all() or not ok.any():
        return None
    chosen = np.linspace(0, len(ok) - 1, min(len(ok), MAX_MODEL_POINTS)).astype(int)
    if ok[chosen].all() or not ok[chosen].any():
        chosen = np.arange(len(ok))
    kernel = ConstantKernel(4.0, (1e-1, 1e3)) * RBF(np.full(x.shape[1], 0.3), (0.05, 5.0))
    classifier = GaussianProcessClassifier(kernel, random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return classifier.fit(x[chosen], ok[chosen].astype(int))


def surface(models: SearchSpaceModels, x_key: str, y_key: str, n_grid: int = 30,
            held: Mapping[str, float] | None = None) -> Surface:
    """The models on an ``n_grid`` x ``n_grid`` grid over (x_key, y_key), the other coordinates at ``held``
    (default: the best theta, or the box's middle before any completion).

    Raises:
        ConfigError: a key outside the job's parameters, the same key twice, or n_grid outside 2..MAX_GRID.
    """
    for field, key in (("x", x_key), ("y", y_key)):
        if key not in models.names:
            raise ConfigError(f"{field}: {key!r} is not a parameter of this job ({', '.join(models.names)})",
                              field=field)
    if x_key == y_key:
        raise ConfigError("y: choose two different parameters", field="y")
    if not 2 <= n_grid <= MAX_GRID:
        raise ConfigError(f"grid: must be in [2, {MAX_GRID}], got {n_grid}", field="grid")
    middle = {n: float(0.5 * (a + b)) for n, a, b in zip(models.names, models.lo, models.hi, strict=True)}
    base = {**middle, **(models.best_theta or {}), **(held or {})}
    ix, iy = models.names.index(x_key), models.names.index(y_key)
    xs = np.linspace(models.lo[ix], models.hi[ix], n_grid)
    ys = np.linspace(models.lo[iy], models.hi[iy], n_grid)
    unit = np.tile(models.to_unit(base), (n_grid * n_grid, 1))
    gx, gy = np.meshgrid(xs, ys)  # rows follow y
    unit[:, ix] = (gx.ravel() - models.lo[ix]) / (models.hi[ix] - models.lo[ix])
    unit[:, iy] = (gy.ravel() - models.lo[iy]) / (models.hi[iy] - models.lo[iy])
    mean = std = p_failure = None
    if models.gp is not None:
        m, s = models.gp.predict(unit)
        mean, std = m.reshape(n_grid, n_grid), s.reshape(n_grid, n_grid)
    if models.classifier is not None:
        p_failure = 1.0 - models.classifier.predict_proba(unit)[:, 1].reshape(n_grid, n_grid)
    held_out = {k: v for k, v in base.items() if k not in (x_key, y_key)}
    return Surface(x_key, y_key, xs, ys, held_out, mean, std, p_failure)
