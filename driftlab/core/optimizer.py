"""Bayesian optimization with an ask/tell interface (paper section III-C), minimizing.

Surrogate (:mod:`driftlab.core.surrogate`): a GP (ARD Matern 5/2 plus noise) on inputs scaled to the unit cube and
normalized outputs. Acquisition (:mod:`driftlab.core.acquisition`): expected improvement times the probability of
success when some evaluations failed (as MATLAB bayesopt's error constraint does), so a failed evaluation never
enters the regression as an invented number. P(success) comes from a Laplace GP classifier (scikit-learn's
arithmetic, :mod:`driftlab.core.failure_model`; a least-squares label GP, tried, let twice as many proposals into a
failing region) conditioned on at most ``_CLASSIFIER_POINTS`` evaluations: every failure and a spread of the
successes. The candidates are rated in one batched prediction; the local searches from the best of them
(L-BFGS-B) read the acquisition and its exact gradient at one point, compiled
(:mod:`driftlab.core.acquisition_gradient`). Seed points: a scrambled Latin hypercube.

Determinism and resume: every proposal is a function of (seed, told history, pending points) only. The GP's
hyperparameters are refit from a fixed starting point at history sizes that are multiples of ``refit_every``
plus half a period (the classifier's at the multiples, so that no ask pays for both; below 4 periods, where fits
are cheap and move most, every half period), on that prefix of the
history and on at most ``_HYPER_FIT_POINTS`` of its points (~30 ms each); between refits both models are
conditioned with those hyperparameters held. A resumed optimizer therefore rebuilds the same state from
``tell`` calls alone (``tell`` only records; fitting happens lazily in ``ask``, the first one fitting both).

Active set: the GP sees at most ``active_set`` successful observations: the best half by value, and a
space-filling spread of the rest (greedy farthest-point order from the best), so that the surrogate stays
accurate near the optimum and still knows the landscape (the cost is O(active_set^3) per ask).

Batch: points asked and not yet told are pending; the next ask treats them as observed at the GP mean
("kriging believer", Ginsbourger et al. 2010), so two workers get two different points.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from scipy.optimize import minimize
from scipy.stats import qmc

from driftlab.core.acquisition import constrained_ei, expected_improvement, failure_clearance
from driftlab.core.acquisition_gradient import NegativeConstrainedEI
from driftlab.core.errors import ConfigError
from driftlab.core.failure_model import LabelKernel, SuccessProbability
from driftlab.core.limits import check_int
from driftlab.core.nearest import farthest_point_order, nearest_squared_distances
from driftlab.core.surrogate import GaussianProcess, Hyperparameters, fit_hyperparameters

_CANDIDATES = 256
_LOCAL_CANDIDATES = 128
_LOCAL_STARTS = 2
_LOCAL_ITERATIONS = 10
# A local search also stops after this many evaluations of the acquisition: where it steps (P(success) crossing
# _MIN_SUCCESS_PROBABILITY) no gradient sees the step, and the line search spent up to 133 evaluations (median 14) on
# a 500-run's asks (measured with the forward-difference gradient the searches had then); capped, a replay of 480 of
# them proposed the same theta in 440 and an acquisition value within 1 % of the uncapped one in all but 20.
_LOCAL_EVALUATIONS = 30
_HYPER_FIT_POINTS = 80  # hyperparameters from at most this many points; the GPs then condition on all
_EI_XI = 0.0
_MIN_SUCCESS_PROBABILITY = 0.5
_FAILURE_CLEARANCE = 0.015  # unit-cube distance over which a failure suppresses proposals
_CLASSIFIER_POINTS = 150  # the classifier conditions on every failure and a spread of successes, this many
# After this many failed evaluations in a row, propose near the best success instead (see _retreat).
_FAILURE_STREAK = 5
MAX_REFUSED_PER_ASK = 50  # proposals a known constraint may refuse in one ask before the last is asked anyway
_RETREAT_SPREAD = 0.05  # unit-cube standard deviation of the first retreat; halved every _FAILURE_STREAK more


class BayesianOptimizer:
    """GP + EI minimizer over a box.

    Args:
        bounds: name -> (lo, hi), lo < hi; proposals are dicts with these names.
        seed_points: proposals before the GP takes over: ``initial_points`` first, then ``local_points`` of them
            around the first initial point, then a Latin hypercube of the box.
        initial_points: points to ask first (e.g. the configuration known to work); each inside the box.
        local_points: of the seed points, how many a Latin hypercube spreads over a box of half-width
            ``local_radius`` (unit-cube widths; one for all, or per name, absent names 1: their whole range)
            around the first initial point, cut to the bounds (none without an initial point).
        local_growth: after the seed points, the GP's proposals stay in that local box, which grows linearly to
            the whole box over this many evaluations (0: the whole box at once): a trust region around the
            configuration known to work, widened as the models learn where the rest of the box fails.
        active_set: most successful observations the GP is fit on.
        seed: random seed (Latin hypercube, candidate sets).
        refit_every: hyperparameter refit period in observations.
        feasible: a known constraint, cheap to evaluate (theta -> whether it can be evaluated at all; a theta whose
            controller model has no drift, driftlab.core.episode.runs). A proposal it refuses is never asked: it
            is kept as a failure the classifier learns from (so the next proposals keep away from it), and the
            next proposal is made, up to ``MAX_REFUSED_PER_ASK`` times in one ask.
    """

    def __init__(self, bounds: Mapping[str, tuple[float, float]], *, seed_points: int = 20, active_set: int = 400,
                 seed: int = 0, refit_every: int = 10, initial_points: Sequence[Mapping[str, float]] = (),
                 local_points: int = 0, local_radius: float | Mapping[str, float] = 0.15,
                 local_growth: int = 0, feasible: Callable[[dict[str, float]], bool] | None = None) -> None:
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
        initial = [self._to_unit(p, clip=False) for p in initial_points][:seed_points]
        if any(((u < 0.0) | (u > 1.0)).any() for u in initial):
            raise ConfigError("initial_points must lie inside the bounds")
        check_int("local_points", local_points, 0, seed_points)
        local = min(local_points, seed_points - len(initial)) if initial else 0
        design = qmc.LatinHypercube(d=self.dim, seed=seed).random(seed_points - len(initial) - local)
        self._radius = (np.array([float(local_radius.get(n, 1.0)) for n in self.names])
                        if isinstance(local_radius, Mapping) else np.full(self.dim, float(local_radius)))
        self._centre = initial[0] if initial and (local or local_growth) else None
        self.local_growth = local_growth
        if local:  # its own stream: the global design stays what it was without a local phase
            around = qmc.LatinHypercube(d=self.dim, seed=np.random.default_rng([seed, 1])).random(local)
            low, high = self._region(self._radius)
            design = np.vstack([low + around * (high - low), design])  # scaled into the box, not piled on its faces
        self._seed_design = np.vstack([*initial, design]) if initial else design
        self.x: list[np.ndarray] = []  # unit-cube inputs, told
        self.y: list[float | None] = []  # None: failed evaluation
        self.pending: list[np.ndarray] = []
        self.failure_scores: list[float] = []  # per told evaluation: a failure's score, inf otherwise
        self.feasible = feasible
        self.refused: list[np.ndarray] = []  # unit-cube proposals ``feasible`` refused: failures never asked
        self._hyper_at = -1  # no fit yet: the defaults until the first boundary
        self._regression_hp = Hyperparameters.default(self.dim)
        self._clf_at = -1
        self._label_kernel = LabelKernel.start(self.dim)

    # -- public interface -------------------------------------------------------------------------------
    def ask(self) -> dict[str, float]:
        """The next point to evaluate (it stays pending until told)."""
        for _ in range(MAX_REFUSED_PER_ASK):
            unit = self._next()
            if self.feasible is None or self.feasible(self._to_theta(unit)):
                break
            self.refused.append(unit)
        self.pending.append(unit)
        return self._to_theta(unit)

    def _next(self) -> np.ndarray:
        n_issued = len(self.x) + len(self.pending)
        unused = [d for d in self._seed_design if not self._is_repeat(d)] if n_issued < self.seed_points else []
        # The first design point not yet told, pending or refused: after a crash, a later design point may have
        # been stored while an earlier one was lost in flight, and design[n_issued] would then run a point twice.
        return unused[0] if unused else self._propose()

    def tell(self, theta: Mapping[str, float], value: float | None, failure_score: float | None = None) -> None:
        """Record an evaluation: its value, or None for a failed one (with ``failure_score``, lower for one that got
        further: where to look while nothing has succeeded). Cheap: no fitting here."""
        self.failure_scores.append(failure_score if value is None and failure_score is not None
                                   and math.isfinite(failure_score) else math.inf)
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

    def _to_unit(self, theta: Mapping[str, float], clip: bool = True) -> np.ndarray:
        missing = [n for n in self.names if n not in theta]
        if missing:
            raise ConfigError(f"theta is missing {', '.join(missing)}")
        raw = np.array([float(theta[n]) for n in self.names])
        unit = (raw - self.lo) / (self.hi - self.lo)
        return np.clip(unit, 0.0, 1.0) if clip else unit

    def _region(self, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The unit box of half-width ``radius`` around the local centre, cut to [0, 1]."""
        return np.clip(self._centre - radius, 0.0, 1.0), np.clip(self._centre + radius, 0.0, 1.0)

    def _search_box(self) -> tuple[np.ndarray, np.ndarray]:
        """Where the GP's proposals may go now: the growing trust region, or the whole unit box."""
        if self._centre is None or self.local_growth <= 0:
            return np.zeros(self.dim), np.ones(self.dim)
        grown = min(max(len(self.x) - self.seed_points, 0) / self.local_growth, 1.0)
        return self._region(self._radius + (1.0 - self._radius) * grown)

    def _rng(self) -> np.random.Generator:
        return np.random.default_rng([self.seed, len(self.x), len(self.pending)])

    def _propose(self) -> np.ndarray:
        # What was refused counts as failed: the classifier and the clearance from failures keep away from it.
        x_all = np.array(self.x + self.refused) if self.x or self.refused else np.empty((0, self.dim))
        ok = np.array([v is not None for v in self.y] + [False] * len(self.refused), dtype=bool)
        x_ok = x_all[ok]
        y_ok = np.array([v for v in self.y if v is not None])
        streak = self._failure_streak()
        if ok.any() and streak >= _FAILURE_STREAK:
            return self._retreat(x_ok[int(np.argmin(y_ok))], x_all[~ok], streak)
        if (not ok.any() and streak >= _FAILURE_STREAK and streak % 2 == 0
                and min(self.failure_scores, default=math.inf) < math.inf):
            # Nothing has succeeded: every other proposal searches near the failure that got furthest, the others
            # keep filling space (on CommonRoad's STD a job whose first theta failed one confirmation seed found no
            # completion in 150 space-filling evaluations; searching only near it, a job at 0.55 rad found none).
            nearest = int(np.argmin(self.failure_scores))
            return self._retreat(x_all[nearest], np.delete(x_all, nearest, axis=0), streak)
        if ok.sum() < 2:
            # Nothing to model yet: keep filling space, away from what was tried.
            return self._farthest_candidate(x_all)
        active = self._active_indices(x_ok, y_ok, self.active_set)
        gp = GaussianProcess(x_ok[active], y_ok[active], self._regression_hyperparameters())
        if self.pending:  # kriging believer: pending points observed at the GP mean
            x_pend = np.array(self.pending)
            gp = gp.with_observations(x_pend, gp.predict(x_pend, return_std=False)[0])
        classifier = self._classifier(x_all, ok) if not ok.all() else None
        best = float(y_ok.min())
        return self._maximize(gp, classifier, best, x_ok[int(np.argmin(y_ok))], x_all[~ok])

    def _failure_streak(self) -> int:
        """Failed evaluations told in a row, up to the latest."""
        streak = 0
        for value in reversed(self.y):
            if value is not None:
                break
            streak += 1
        return streak

    def _retreat(self, x_best: np.ndarray, failed: np.ndarray, streak: int) -> np.ndarray:
        """A point near the best success, as far from every failure as such a point gets; the neighbourhood
        halves with every further run of failures (TuRBO's failure counter, Eriksson et al. 2019). Where the
        feasible region is a small island (on some mismatched plants 2 of 100 evaluations complete), the
        classifier smooths it away, rates every candidate below ``_MIN_SUCCESS_PROBABILITY`` and the search
        would otherwise spend the rest of its budget on failures far from the island."""
        rng = self._rng()
        spread = max(_RETREAT_SPREAD * 0.5 ** ((streak - _FAILURE_STREAK) // _FAILURE_STREAK), 1e-3)
        candidates = np.clip(x_best + rng.normal(0.0, spread, (_LOCAL_CANDIDATES, self.dim)), 0.0, 1.0)
        return candidates[int(np.argmax(nearest_squared_distances(candidates, failed)))]

    def _active_indices(self, x: np.ndarray, y: np.ndarray, limit: int) -> np.ndarray:
        n = len(y)
        if n <= limit:
            return np.arange(n)
        order = np.argsort(y, kind="stable")
        keep = list(order[: limit // 2])
        rest = order[limit // 2:]
        return np.array(keep + self._spread(x[rest], x[keep], limit - len(keep), rest))

    @staticmethod
    def _spread(candidates: np.ndarray, chosen: np.ndarray, count: int, ids: np.ndarray) -> list[int]:
        """``count`` of ``ids`` (rows of ``candidates``) in greedy farthest-point order from ``chosen``."""
        return [int(ids[j]) for j in farthest_point_order(candidates, chosen, count)]

    def _boundary(self, offset: int = 0) -> int:
        """The history size whose prefix the hyperparameters are fit on: the last multiple of refit_every, plus
        ``offset`` (the regressor refits half a period after the classifier, so that no ask pays for both)."""
        n = len(self.x) - offset
        return 0 if n < 0 else (n // self.refit_every) * self.refit_every + offset

    def _regression_boundary(self) -> int:
        """The regressor refits every half period while the history is short (fits are cheap there and its
        hyperparameters move most), then half a period after the classifier."""
        half = max(self.refit_every // 2, 1)
        if len(self.x) < 4 * self.refit_every:
            return (len(self.x) // half) * half
        return self._boundary(half)

    def _regression_hyperparameters(self) -> Hyperparameters:
        boundary = self._regression_boundary()
        if self._hyper_at != boundary:
            prefix = [(xi, yi) for xi, yi in zip(self.x[:boundary], self.y[:boundary], strict=True) if yi is not None]
            hp = Hyperparameters.default(self.dim)
            if len(prefix) >= 2:  # else the defaults: a fit on data past the prefix would not replay on resume
                xp = np.array([p[0] for p in prefix])
                yp = np.array([p[1] for p in prefix])
                chosen = self._active_indices(xp, yp, min(self.active_set, _HYPER_FIT_POINTS))
                y_fit = yp[chosen]
                y_fit = (y_fit - y_fit.mean()) / (y_fit.std() if y_fit.std() > 1e-12 else 1.0)
                hp = fit_hyperparameters(xp[chosen], y_fit, hp)
            self._regression_hp = hp
            self._hyper_at = boundary
        return self._regression_hp

    def _classifier_indices(self, x: np.ndarray, ok: np.ndarray, limit: int) -> np.ndarray:
        """At most ``limit`` evaluations for the classifier: the failures (a spread of them beyond half the
        limit), then a spread of the successes away from them."""
        failed, succeeded = np.flatnonzero(~ok), np.flatnonzero(ok)
        if len(failed) > limit // 2:
            failed = np.array(self._spread(x[failed], np.empty((0, self.dim)), limit // 2, failed), dtype=int)
        room = limit - len(failed)
        if len(succeeded) > room:
            succeeded = np.array(self._spread(x[succeeded], x[failed], room, succeeded), dtype=int)
        return np.sort(np.concatenate([failed, succeeded]).astype(int))

    def _classifier(self, x: np.ndarray, ok: np.ndarray) -> SuccessProbability | None:
        """P(success) from a GP classifier; its kernel is learnt on the regressor's schedule, on at most
        ``_HYPER_FIT_POINTS`` of the prefix's evaluations."""
        if ok.sum() == 0:
            return None
        boundary = self._boundary()
        if self._clf_at != boundary:
            ok_prefix = ok[:boundary]
            self._label_kernel = LabelKernel.start(self.dim)
            if 0 < ok_prefix.sum() < boundary:
                chosen = self._classifier_indices(x[:boundary], ok_prefix, _HYPER_FIT_POINTS)
                self._label_kernel = self._label_kernel.fitted(x[chosen], ok_prefix[chosen].astype(int))
            self._clf_at = boundary
        chosen = self._classifier_indices(x, ok, _CLASSIFIER_POINTS)
        return SuccessProbability.conditioned(self._label_kernel, x[chosen], ok[chosen].astype(int))

    def _acquisition(self, gp: GaussianProcess, classifier: SuccessProbability | None, best: float,
                     failed: np.ndarray, x: np.ndarray) -> np.ndarray:
        mean, std = gp.predict(x)
        ei = expected_improvement(mean, std, best, _EI_XI)
        if classifier is None:
            return ei
        p_success = classifier(x)
        return constrained_ei(ei, p_success, failure_clearance(x, failed, _FAILURE_CLEARANCE),
                              _MIN_SUCCESS_PROBABILITY)

    def _maximize(self, gp: GaussianProcess, classifier: SuccessProbability | None, best: float,
                  x_best: np.ndarray, failed: np.ndarray) -> np.ndarray:
        rng = self._rng()
        low, high = self._search_box()
        local = np.clip(x_best + rng.normal(0.0, 0.05, (_LOCAL_CANDIDATES, self.dim)), low, high)
        candidates = np.vstack([low + rng.random((_CANDIDATES, self.dim)) * (high - low), local])
        values = self._acquisition(gp, classifier, best, failed, candidates)
        if values.max() <= 0.0 and classifier is not None:
            # Success looks unlikely everywhere: try where it is likeliest.
            return candidates[int(np.argmax(classifier(candidates)))]
        starts = candidates[np.argsort(-values)[:_LOCAL_STARTS]]
        best_x, best_v = starts[0], float(values.max())
        negative = NegativeConstrainedEI(gp, classifier, best, _EI_XI, failed, _FAILURE_CLEARANCE,
                                         _MIN_SUCCESS_PROBABILITY)
        for start in starts:
            res = minimize(negative, start, jac=True, method="L-BFGS-B",
                           bounds=list(zip(low, high, strict=True)),
                           options={"maxiter": _LOCAL_ITERATIONS, "maxfun": _LOCAL_EVALUATIONS})
            if np.all(np.isfinite(res.x)) and -res.fun > best_v:
                best_x, best_v = np.clip(res.x, low, high), -float(res.fun)
        if self._is_repeat(best_x):
            return low + rng.random(self.dim) * (high - low)
        return best_x

    def _is_repeat(self, unit: np.ndarray) -> bool:
        tried = self.x + self.pending + self.refused
        return bool(tried) and float(np.min(np.abs(np.array(tried) - unit).max(axis=1))) < 1e-6

    def _farthest_candidate(self, x_all: np.ndarray) -> np.ndarray:
        candidates = self._rng().random((_CANDIDATES, self.dim))
        taken = np.vstack([x_all, np.array(self.pending).reshape(-1, self.dim)])
        if len(taken) == 0:
            return candidates[0]
        return candidates[int(np.argmax(np.sqrt(nearest_squared_distances(candidates, taken))))]
