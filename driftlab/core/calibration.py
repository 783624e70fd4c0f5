"""Calibration: the default controller's MPC weights for one car, found by DriftLab's own optimizer over several
points of the car's drift window, robust over seeded episodes, never by hand.

A point is a drift the car should hold: a sideslip and a circle radius (both circles of the 8 the same). Each
weight set runs the untuned theta (driftlab.core.config.Theta's defaults) on every point under ``seeds`` episode
seeds (the plant's per-episode variation: friction, mass, lag, start state, sensor noise), and scores the mean of
their J (the paper's J, a failed episode at its failure penalty, driftlab.core.episode.failure_penalty): a set
that completes everywhere always beats one that fails anywhere, and among those that complete the one that tracks
best wins. The weights are searched in log space, a decade either side of the car's current set, by the same GP +
expected improvement that tunes theta (driftlab.core.optimizer), warm-started from that set so that a calibration
never returns a set worse on its own points than the one it started from.

Bayesian optimization of MPC weights over closed-loop episodes: Marco et al., "Automatic LQR tuning based on
Gaussian process global optimization" (ICRA 2016); Edwards et al., "Automatic tuning for data-driven model
predictive control" (ICRA 2021).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from driftlab.core.config import EpisodeConfig, Theta, config_to_dict
from driftlab.core.configure import apply_overrides, fitted
from driftlab.core.drivability import drift_window, drivable_reason
from driftlab.core.episode import failure_penalty
from driftlab.core.errors import ConfigError
from driftlab.core.mpc_config import MpcConfig
from driftlab.core.pruning import PruneRule
from driftlab.core.statuses import EpisodeStatus
from driftlab.core.track import TILED_RADIUS_SHARES

# The weights searched (the cost terms of driftlab.core.mpc_config.MpcConfig and the disturbance estimator's gain),
# in log10, within LOG_SPAN_DECADES of the car's current set and inside these limits; the steering rate limit
# [rad/s] and the estimator's hold after a flick [s] linearly within their ranges.
LOG_WEIGHT_LIMITS: dict[str, tuple[float, float]] = {
    "q_sideslip": (0.5, 4.0), "q_yaw_rate": (-2.0, 3.0), "q_steer": (-2.0, 3.0), "q_drive_kn": (-3.0, 1.5),
    "r_steer_step": (-1.0, 3.5), "r_drive_step_kn": (-5.0, 0.5), "q_speed": (-2.0, 1.5),
    "q_lateral_error": (-2.5, 2.0), "q_course_error": (-2.5, 2.0), "disturbance_gain": (-4.0, 0.0)}
LOG_SPAN_DECADES = 1.0
LINEAR_LIMITS: dict[str, tuple[float, float]] = {"steer_rate_radps": (2.0, 25.0), "estimator_hold_s": (0.0, 2.5)}
# Episode seeds of calibration: a block no tuning job (seed x 64 + j) or rescore (2^40 + j) reaches.
CALIBRATION_SEED_BASE = 2**41


@dataclass(frozen=True)
class CalibrationPoint:
    """A drift to hold: |sideslip| [rad] on two circles of ``radius_m`` [m]."""

    sideslip_rad: float
    radius_m: float

    def overrides(self) -> dict[str, float]:
        return {"scenario.sideslip_rad": self.sideslip_rad, "scenario.left_radius_m": self.radius_m,
                "scenario.right_radius_m": self.radius_m}

    def label(self) -> str:
        return f"{self.sideslip_rad:g} rad @ R {self.radius_m:g} m"


# The default points' spacing across the window: a job's drift lies less than one step (driftlab.core.car_profile:
# 0.05 rad) from one of them, so a profile applies to every drift of the window on the scenario's circle.
POINT_SPACING_RAD = 0.05


def default_points(config: EpisodeConfig) -> list[CalibrationPoint]:
    """The scenario's drift and every POINT_SPACING_RAD either side of it across the car's drift window on its
    circle (:func:`window_sideslips`), and its sideslip on circles 30/44 and 52/44 the size."""
    s = config.scenario
    beta, radius = s.sideslip_rad, s.left_radius_m
    return [*(CalibrationPoint(b, radius) for b in window_sideslips(config)),
            *(CalibrationPoint(beta, round(radius * share, 2)) for share in TILED_RADIUS_SHARES)]


def window_sideslips(config: EpisodeConfig) -> list[float]:
    """The scenario's sideslip and every POINT_SPACING_RAD either side of it inside the run of the drift window
    (driftlab.core.drivability.drift_window, the one `driftlab equilibrium --window` prints) that holds it, and the
    run's edge where it lies half a spacing or more beyond the last of them: every sideslip of the run is then less
    than half a spacing from one. Only the scenario's own where it is outside the window (split_drivable sets it
    aside)."""
    beta, radius = config.scenario.sideslip_rad, config.scenario.left_radius_m
    runs = drift_window(config, radius).ranges_rad
    low, high = next(((lo, hi) for lo, hi in runs if lo - 1e-9 <= beta <= hi + 1e-9), (beta, beta))
    below = math.floor((beta - low) / POINT_SPACING_RAD + 1e-9)
    above = math.floor((high - beta) / POINT_SPACING_RAD + 1e-9)
    sideslips = [round(beta + k * POINT_SPACING_RAD, 4) for k in range(-below, above + 1)]
    if sideslips[0] - low >= POINT_SPACING_RAD / 2 - 1e-9:
        sideslips.insert(0, round(low, 4))
    if high - sideslips[-1] >= POINT_SPACING_RAD / 2 - 1e-9:
        sideslips.append(round(high, 4))
    return sideslips


def point_config(base: EpisodeConfig, point: CalibrationPoint) -> EpisodeConfig:
    """``base`` driving ``point``, its controller's model to be fitted there (its plant's catalog entry decides how):
    each worker fits it once, with the point's first episode (driftlab.core.configure.fitted), not the calibration's
    thread before any episode runs (an MB fit is seconds a point, and a server that stops waits for that thread)."""
    return apply_overrides(base, point.overrides())


def split_drivable(base: EpisodeConfig, points: Sequence[CalibrationPoint]
                   ) -> tuple[list[tuple[CalibrationPoint, EpisodeConfig]], list[tuple[CalibrationPoint, str]]]:
    """The points the car can drift (with their configs), and the others with the reason."""
    inside, outside = [], []
    for point in points:
        try:
            config = point_config(base, point)
        except ConfigError as exc:
            outside.append((point, str(exc)))
            continue
        reason = drivable_reason(config)  # where the model cannot be fitted, the reason names the window
        if reason is None:
            inside.append((point, config))
        else:
            outside.append((point, reason))
    return inside, outside


def unfittable(points: Sequence[tuple[CalibrationPoint, EpisodeConfig]]) -> list[tuple[CalibrationPoint, str]]:
    """The points at which the controller's model cannot be fitted (driftlab.core.configure.fitted raises), with the
    reason. :func:`split_drivable`'s check (PlantType.check_fit) does not fit: inside the car's window a model
    structure can still miss the car's drift (the VW Vanagon's coupled rear model at 0.69 rad, 44 m: no friction of
    it reaches the car's speed), and the worker that fits it with the point's first episode raises. Each fit
    costs 0.3-10 s (the coupled model's drive answer is simulated), so this runs only after such a failure."""
    unfit = []
    for point, config in points:
        try:
            fitted(config)
        except ConfigError as exc:
            unfit.append((point, str(exc)))
    return unfit


def search_bounds(start: MpcConfig) -> dict[str, tuple[float, float]]:
    """The box searched around the car's current weights ``start``."""
    bounds = {}
    for name, (lo, hi) in LOG_WEIGHT_LIMITS.items():
        centre = math.log10(getattr(start, name))
        bounds[f"log10_{name}"] = (max(lo, centre - LOG_SPAN_DECADES), min(hi, centre + LOG_SPAN_DECADES))
    return {**bounds, **LINEAR_LIMITS}


def weights_of(x: dict[str, float]) -> dict[str, float]:
    """A point of the search space as ``mpc.*`` values."""
    out = {name: 10.0 ** x[f"log10_{name}"] for name in LOG_WEIGHT_LIMITS}
    out.update({name: x[name] for name in LINEAR_LIMITS})
    return out


def search_point(mpc: MpcConfig, bounds: dict[str, tuple[float, float]] | None = None) -> dict[str, float]:
    """``mpc``'s weights as a point of the search space, clipped into ``bounds`` (default: the limits)."""
    x = {f"log10_{name}": math.log10(getattr(mpc, name)) for name in LOG_WEIGHT_LIMITS}
    x.update({name: getattr(mpc, name) for name in LINEAR_LIMITS})
    box = bounds or {**{f"log10_{name}": limits for name, limits in LOG_WEIGHT_LIMITS.items()}, **LINEAR_LIMITS}
    return {name: min(max(value, box[name][0]), box[name][1]) for name, value in x.items()}


def with_weights(config: EpisodeConfig, weights: dict[str, Any]) -> EpisodeConfig:
    return replace(config, mpc=replace(config.mpc, **weights))


@dataclass(frozen=True)
class EpisodeScore:
    """One calibration episode as it came back."""

    point: int
    seed: int
    status: str
    J: float
    completed_fraction: float
    mean_abs_e_m: float | None

    @property
    def completed(self) -> bool:
        return self.status == EpisodeStatus.COMPLETED

    @property
    def penalized_J(self) -> float:
        return self.J if self.completed and math.isfinite(self.J) else failure_penalty(self.completed_fraction)


def mean_penalized_J(episodes: Sequence[EpisodeScore]) -> float:
    """How a calibration scores a set of episodes: their mean J, a failed one at its failure penalty."""
    return sum(e.penalized_J for e in episodes) / len(episodes)


@dataclass
class WeightSetResult:
    """A weight set's episodes; ``pruned``: it stopped after its first seeds, clearly worse than the best set on the
    same seeds (:func:`calibrate`), and is scored on those."""

    weights: dict[str, float]
    episodes: list[EpisodeScore]
    pruned: bool = False

    @property
    def score(self) -> float:
        """Mean J over every point and seed, failed episodes at their penalty (lower is better)."""
        return mean_penalized_J(self.episodes)

    @property
    def completed(self) -> int:
        return sum(e.completed for e in self.episodes)

    def per_point(self, points: Sequence[CalibrationPoint]) -> list[dict[str, Any]]:
        out = []
        for i, point in enumerate(points):
            mine = [e for e in self.episodes if e.point == i]
            errors = [e.mean_abs_e_m for e in mine if e.completed and e.mean_abs_e_m is not None]
            out.append({"sideslip_rad": point.sideslip_rad, "radius_m": point.radius_m,
                        "completed": sum(e.completed for e in mine), "episodes": len(mine),
                        "mean_abs_e_m": sum(errors) / len(errors) if errors else None})
        return out


# Runs a batch of (theta, config document, seed) episodes, returning for each (status, J, completed fraction,
# mean |e|), in order: the caller's executor (local processes, a Dask cluster).
RunBatch = Callable[[list[tuple[dict[str, float], dict[str, Any], int]]], list[tuple[str, float, float, float | None]]]


@dataclass
class Calibration:
    """A calibration's state: the points, every weight set tried with its episodes, the best so far."""

    points: list[CalibrationPoint]
    seeds: list[int]
    tried: list[WeightSetResult] = field(default_factory=list)
    known_tried: list[int] = field(default_factory=list)  # per known weight set, its index in ``tried``

    def known_results(self) -> list[WeightSetResult | None]:
        """What each known weight set did (None: not reached within the iterations)."""
        return [self.tried[i] if i < len(self.tried) else None for i in self.known_tried]

    @property
    def best(self) -> WeightSetResult | None:
        return min(self.tried, key=lambda r: (r.score, -r.completed)) if self.tried else None


def calibrate(base: EpisodeConfig, points: Sequence[tuple[CalibrationPoint, EpisodeConfig]], run_batch: RunBatch, *,
              iterations: int = 150, seeds: int = 3, seed: int = 0, known: Sequence[MpcConfig] = (),
              theta: Theta | None = None, on_progress: Callable[[Calibration], None] | None = None,
              prune: PruneRule | None = None) -> Calibration:
    """Search the MPC weights for ``points`` (the drivable ones, with their configs, :func:`split_drivable`).

    The first weight set is ``base``'s own (the warm start); then each of ``known`` (weight sets that drive other
    cars: what a calibration of a similar car found is a better guess than a random one), clipped into the box
    around ``base``'s; the next of the optimizer's ``seed_points`` start near ``base``'s (its local phase), then the
    GP and expected improvement take over. Every set drives ``theta`` (default: the untuned one); a theta a job
    learned at the point lets the weights be searched for the flick that job found. With ``prune`` a set runs its
    first ``min_seeds`` seeds at each point, and stops there when it is clearly worse than the best set on those
    seeds (driftlab.core.pruning, as a job's robust evaluation): it is told to the optimizer as its mean over them.
    """
    calibration = Calibration([p for p, _ in points], [CALIBRATION_SEED_BASE + j for j in range(seeds)])
    bounds = search_bounds(base.mpc)
    starts = [search_point(base.mpc, bounds)]
    for mpc in known:  # a set tried already (clipped into the same point) is not tried twice
        x = search_point(mpc, bounds)
        if x not in starts:
            starts.append(x)
        calibration.known_tried.append(starts.index(x))
    seed_points = min(max(20, len(starts)), iterations)
    from driftlab.core.optimizer import BayesianOptimizer  # here: the server validates calibrations with this module

    optimizer = BayesianOptimizer(bounds, seed_points=seed_points, seed=seed, initial_points=starts[:seed_points],
                                  local_points=min(10, seed_points - min(len(starts), seed_points)),
                                  local_radius=0.15, local_growth=max(iterations // 2, 1))
    documents = [config_to_dict(config) for _, config in points]
    theta_values = (theta or Theta()).as_dict()
    for _ in range(iterations):
        x = optimizer.ask()
        weights = weights_of(x)
        batch = [(point, (theta_values, {**doc, "mpc": {**doc["mpc"], **weights}}, s))
                 for point, doc in enumerate(documents) for s in calibration.seeds]
        result = _scored(weights, batch, run_batch, calibration.best, prune or PruneRule(enabled=False),
                         calibration.seeds)
        calibration.tried.append(result)
        optimizer.tell(x, result.score, result.score)
        if on_progress is not None:
            on_progress(calibration)
    return calibration


def _scored(weights: dict[str, float], batch: list[tuple[int, tuple[dict[str, float], dict[str, Any], int]]],
            run_batch: RunBatch, best: WeightSetResult | None, prune: PruneRule, seeds: list[int]
            ) -> WeightSetResult:
    """A weight set's episodes (``batch``: (point, episode)): all at once, or with ``prune`` and a best set to pair
    with, the first seeds at every point first, the rest only when the paired test does not stop it."""
    first_seeds = set(seeds[:prune.min_seeds])
    if not prune.enabled or best is None or len(seeds) <= prune.min_seeds:
        return WeightSetResult(weights, _run(batch, run_batch))
    head = _run([b for b in batch if b[1][2] in first_seeds], run_batch)
    incumbent = {(e.point, e.seed): e.penalized_J for e in best.episodes}
    if prune.stops({(e.point, e.seed): e.penalized_J for e in head}, incumbent, best.score):
        return WeightSetResult(weights, head, pruned=True)
    tail = _run([b for b in batch if b[1][2] not in first_seeds], run_batch)
    order = {(point, episode[2]): i for i, (point, episode) in enumerate(batch)}
    return WeightSetResult(weights, sorted(head + tail, key=lambda e: order[e.point, e.seed]))


def _run(batch: list[tuple[int, tuple[dict[str, float], dict[str, Any], int]]],
         run_batch: RunBatch) -> list[EpisodeScore]:
    outcomes = run_batch([episode for _, episode in batch])
    return [EpisodeScore(point, episode[2], *outcome) for (point, episode), outcome in zip(batch, outcomes,
                                                                                           strict=True)]


# Fresh seeds the chosen weights are checked on at their points (a block neither the search's seeds nor any job's or
# rescore's reach): the 3 seeds a search scores on say which set is best, not how often it completes; the profiles'
# window is the drifts where they complete at least VERIFIED_SHARE of these.
VERIFY_SEED_BASE = CALIBRATION_SEED_BASE + 2**32
VERIFY_SEEDS = 10
VERIFIED_SHARE = 0.9


def verify(points: Sequence[tuple[CalibrationPoint, EpisodeConfig]], weights: dict[str, float], run_batch: RunBatch,
           *, theta: Theta | None = None, seeds: int = VERIFY_SEEDS) -> list[dict[str, Any]]:
    """Each point's record of ``weights`` driving ``theta`` on ``seeds`` fresh seeds: how many episodes completed,
    how many ended outside the plant's model (``invalid``), and the completed ones' mean |e| [m]."""
    seed_list = [VERIFY_SEED_BASE + j for j in range(seeds)]
    theta_values = (theta or Theta()).as_dict()
    batch = []
    for _, config in points:
        document = config_to_dict(config)
        batch += [(theta_values, {**document, "mpc": {**document["mpc"], **weights}}, s) for s in seed_list]
    outcomes = run_batch(batch)
    records = []
    for i in range(len(points)):
        mine = [EpisodeScore(i, s, *outcome) for s, outcome in zip(seed_list, outcomes[i * seeds:(i + 1) * seeds],
                                                                    strict=True)]
        errors = [e.mean_abs_e_m for e in mine if e.completed and e.mean_abs_e_m is not None]
        records.append({"seeds": seeds, "completed": sum(e.completed for e in mine),
                        "invalid": sum(e.status == EpisodeStatus.INVALID for e in mine),
                        "mean_abs_e_m": sum(errors) / len(errors) if errors else None})
    return records


def learn_theta(config: EpisodeConfig, run_batch: RunBatch, *, iterations: int, seeds: int = 3, seed: int = 0,
                on_progress: Callable[[int, float | None], None] | None = None) -> tuple[Theta, float]:
    """The theta a job of the job default would learn at ``config``'s drift with its weights (its bounds, start and
    optimizer settings, driftlab.core.tuning.TuningSpec), in a search of ``iterations`` thetas scored on
    ``seeds`` calibration seeds as a weight set is (mean J, failures at their penalty). Returns the best theta and
    its score. A calibration's next round searches the weights again for it: the flick a job finds there is not
    the untuned one, and at the edge of a car's window the weights for the untuned flick complete nothing."""
    from driftlab.core.optimizer import BayesianOptimizer
    from driftlab.core.tuning import TuningSpec

    spec = TuningSpec(iterations=iterations, config=config, seed=seed)
    optimizer = BayesianOptimizer(spec.bounds, **spec.optimizer_options)
    document, seed_list = config_to_dict(config), [CALIBRATION_SEED_BASE + j for j in range(seeds)]
    best: tuple[float, dict[str, float]] | None = None
    for n in range(iterations):
        x = optimizer.ask()
        theta = Theta.filled(x)
        outcomes = run_batch([(theta, document, s) for s in seed_list])
        episodes = [EpisodeScore(0, s, *outcome) for s, outcome in zip(seed_list, outcomes, strict=True)]
        score = mean_penalized_J(episodes)
        optimizer.tell(x, score if all(e.completed for e in episodes) else None, score)
        if best is None or score < best[0]:
            best = (score, theta)
        if on_progress is not None:
            on_progress(n + 1, best[0])
    assert best is not None
    return Theta.from_mapping(best[1]), best[0]
