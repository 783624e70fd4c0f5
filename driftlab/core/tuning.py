"""A tuning job's specification: budget, optimizer settings, bounds on theta and the episode config.

One validated document, stored as the job's configuration and accepted alike by `driftlab tune` and
``POST /api/jobs``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

from driftlab.core.config import MODEL_FIT, THETA_KEYS, THETA_LIMITS, EpisodeConfig, Theta, config_to_dict
from driftlab.core.configure import config_from_document, fitted
from driftlab.core.errors import ConfigError
from driftlab.core.limits import (  # noqa: F401  # the defaults re-exported: callers take them from the job spec
    DEFAULT_CONFIRM_SAMPLES,
    DEFAULT_ROBUST_SAMPLES,
    JOB_LIMITS,
    MAX_ROBUST_SAMPLES,
    check_int,
)
from driftlab.core.plants import entry_of
from driftlab.core.pruning import PruneRule
from driftlab.core.robust import tuning_seeds
from driftlab.core.stopping import StopRules
from driftlab.core.warm_start import WarmStart

# Around the band where the default controller completes the 8 on the default plant (benchmarks/mismatch_sweep.py:
# c outside [0.005, 0.04] or k above 0.12 fail nearly always).
DEFAULT_BOUNDS: dict[str, tuple[float, float]] = {
    "c_lr": (0.005, 0.04), "c_rl": (0.005, 0.04), "dV": (-0.3, 0.3), "k": (0.0, 0.12)}
# The model corrections a job learns by default (TuningSpec.model_correction). Their spans cover the grid of
# benchmarks/envelope.py: with the untuned theta, the plants that fail with the model as configured complete
# with the model's C x 0.9 (nominal plant, C x 0.9) to x 1.25 (default plant, C x 1.3), or mu x 0.85 to x 1.15.
MODEL_BOUNDS: dict[str, tuple[float, float]] = {"model_mu_scale": (0.85, 1.2), "model_c_scale": (0.85, 1.3)}
BOUND_LIMITS = THETA_LIMITS  # what a bound may span: theta's own validity range
MAX_ITERATIONS = JOB_LIMITS["iterations"][1]
# Space-filling evaluations before the GP takes over. 12 (3 per theta dimension) by default: against the paper's
# 20 the best J after 25 evaluations is lower (median of 6 seeds -1.62 against -1.42) and level at 100
# (benchmarks/peers.py). The paper's 500-run with its 20 is the `paper` preset.
DEFAULT_SEED_POINTS = 12
# The local phase of a job that learns the model corrections (TuningSpec.local_phase; benchmarks/peers.py, six
# dimensions, default plant, medians of 6 BO seeds): after the untuned theta, LOCAL_POINTS of the seed points
# spread the paper's four parameters over their whole bounds with the model corrections within LOCAL_MODEL_RADIUS
# (unit widths of their bounds) of the uncorrected model, and the GP's proposals stay in that box, grown to the
# whole over LOCAL_GROWTH evaluations. Best J after 25 evaluations -1.49 against -0.78 without it (the four-
# dimensional run: -1.62): the corrections' box is mostly failure, and a space-filling design spent on it
# learns where the car fails before where it drifts well. Off by default on any other plant (CommonRoad's, a
# registered car): its drift family is not the model's, the corrections it needs may lie further out, and on
# CommonRoad's the same jobs did worse with it (STD, job seed 0: 37 of 40 fresh seeds against 40; MB, seed 0: no
# evaluation completed in 150, against a best completed evaluation at iteration 70 without it).
LOCAL_POINTS = 11
LOCAL_MODEL_RADIUS = 0.05
LOCAL_GROWTH = 15
# The job document's version (TuningSpec.to_dict). 2: it states whether its config is fitted to its plant ("fitted";
# version 1 said so by the keys it lacked, driftlab.core.config.config_to_dict). A posted document without one is of
# this release; the documents stored before it were stamped 1 (migration 0017). 3: it holds its prune rule
# (driftlab.core.pruning); one of version 1 or 2 was written before the rule existed and runs every seed of every
# evaluation, as it did (a resumed job goes on as it began).
JOB_DOCUMENT_VERSION = 3
# The paper's 500-run learns the paper's four parameters only.
PAPER_PRESET = {"iterations": 500, "seed_points": 20, "active_set": 400, "model_correction": False}


def validate_bounds(bounds: dict[str, Any], model_correction: bool = True,
                    plant_bounds: dict[str, tuple[float, float]] | None = None) -> dict[str, tuple[float, float]]:
    """Bounds for a subset of theta's keys (others take DEFAULT_BOUNDS with the plant's own box on top,
    ``plant_bounds``: driftlab.core.plants.PlantType.theta_bounds, and MODEL_BOUNDS with ``model_correction``;
    without it the model corrections stay at 1 and may not be given bounds)."""
    if not isinstance(bounds, dict):
        raise ConfigError("bounds must be an object {name: [lo, hi]}")
    out = {**DEFAULT_BOUNDS, **(plant_bounds or {}), **(MODEL_BOUNDS if model_correction else {})}
    allowed = THETA_KEYS if model_correction else tuple(DEFAULT_BOUNDS)
    for name, pair in bounds.items():
        if name in MODEL_BOUNDS and not model_correction:
            raise ConfigError(f"bounds.{name}: a model correction is learned only with model_correction true",
                              field=f"bounds.{name}")
        if name not in allowed:
            raise ConfigError(f"bounds.{name} is not a theta key; allowed: {', '.join(allowed)}")
        if not isinstance(pair, (list, tuple)) or len(pair) != 2:
            raise ConfigError(f"bounds.{name} must be [lo, hi]")
        try:
            lo, hi = float(pair[0]), float(pair[1])
        except (TypeError, ValueError):
            raise ConfigError(f"bounds.{name} must be two numbers, got {pair!r}") from None
        lim_lo, lim_hi = BOUND_LIMITS[name]
        if not (math.isfinite(lo) and math.isfinite(hi) and lim_lo <= lo < hi <= lim_hi):
            raise ConfigError(f"bounds.{name} must satisfy {lim_lo} <= lo < hi <= {lim_hi}, got [{lo}, {hi}]")
        out[name] = (lo, hi)
    return out


@dataclass(frozen=True)
class TuningSpec:
    """What a tuning job runs.

    Attributes:
        iterations: episodes to evaluate in total (1..5000).
        seed_points: space-filling proposals before the GP (1..1000).
        active_set: most observations the GP is fit on (10..5000).
        seed: optimizer seed (also picks the episode seeds, :func:`driftlab.core.robust.tuning_seeds`).
        robust_samples: seeded episodes per evaluation (1..64), aggregated by :mod:`driftlab.core.robust`.
        confirm_samples: more seeded episodes an evaluation runs when it would become the best so far
            (0..64, robust_samples + confirm_samples <= 64); it is stored with all of them.
        bounds: theta name -> (lo, hi).
        model_correction: also learn theta's model corrections (model_mu_scale, model_c_scale), in MODEL_BOUNDS
            unless bounded otherwise. Off: the paper's four parameters (jobs stored before revision 8).
        local_phase: with the model corrections, start near the uncorrected model (LOCAL_POINTS, LOCAL_GROWTH);
            off: the seed points fill the whole box (jobs stored before revision 10). None (the default): on for
            DriftLab's own plants, off for any other (see LOCAL_POINTS); stored as what it resolved to.
        stop: stop rules besides the budget, a time budget and no improvement (driftlab.core.stopping).
        prune: the early stop of a theta whose first seeds are worse than the best's with confidence
            (driftlab.core.pruning; on by default, ``{"enabled": false}`` runs every seed of every evaluation).
            A posted document without it takes the default; a stored one of version 1 or 2 (before the rule
            existed) runs with it off, as it ran.
        warm_start: what the job takes from other jobs' evaluations before its own (driftlab.core.warm_start):
            evaluations of its own config told first, or other configs' best thetas asked first. None: a cold start.
        deterministic: the next theta is asked only once every evaluation asked before is stored and told, so the
            sequence of thetas is a function of the seed and the settings whatever the number of workers or
            their speed. Off (the default): a new theta is asked as soon as a worker is free, and the order in
            which parallel episodes complete changes what the optimizer has seen (two runs of a job with the
            same seed agree on the first evaluation, then may differ).
        config: the episode configuration (plant, controller, scenario ...).
        version: the job document's version it was read from (:data:`JOB_DOCUMENT_VERSION` for a new job; 1 for
            one stored before versions), written back as it was.
    """

    iterations: int = 500
    seed_points: int = DEFAULT_SEED_POINTS
    active_set: int = 400
    seed: int = 0
    robust_samples: int = DEFAULT_ROBUST_SAMPLES
    confirm_samples: int = DEFAULT_CONFIRM_SAMPLES
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    config: EpisodeConfig = field(default_factory=EpisodeConfig)
    model_correction: bool = True
    local_phase: bool | None = None
    deterministic: bool = False
    warm_start: WarmStart | None = None
    stop: StopRules = field(default_factory=StopRules)
    prune: PruneRule = field(default_factory=PruneRule)
    version: int = JOB_DOCUMENT_VERSION

    def __post_init__(self) -> None:
        for name in ("iterations", "seed_points", "active_set", "seed", "robust_samples"):
            check_int(name, getattr(self, name))
        # The confirmation seeds follow the evaluation seeds in the job's block of MAX_ROBUST_SAMPLES.
        check_int("confirm_samples", self.confirm_samples, 0, MAX_ROBUST_SAMPLES - self.robust_samples)
        if not isinstance(self.model_correction, bool):
            raise ConfigError(f"model_correction must be true or false, got {self.model_correction!r}",
                              field="model_correction")
        if self.local_phase is None:
            object.__setattr__(self, "local_phase", entry_of(self.config.plant).local_phase)
        if not isinstance(self.local_phase, bool):
            raise ConfigError(f"local_phase must be true or false, got {self.local_phase!r}", field="local_phase")
        if not isinstance(self.stop, StopRules):
            raise ConfigError("stop must be the job's stop rules", field="stop")
        if not isinstance(self.prune, PruneRule):
            raise ConfigError("prune must be the job's prune rule", field="prune")
        if not isinstance(self.deterministic, bool):
            raise ConfigError(f"deterministic must be true or false, got {self.deterministic!r}",
                              field="deterministic")
        object.__setattr__(self, "bounds", validate_bounds(dict(self.bounds), self.model_correction,
                                                           entry_of(self.config.plant).theta_bounds))
        if self.warm_start is not None:
            self.warm_start.check(self.bounds)
        if self.model_correction and MODEL_FIT not in self.config.to_fit:
            # every corner of the box must be a valid car, or every episode would raise (checked again once fitted)
            (mu_lo, mu_hi), (c_lo, c_hi) = self.bounds["model_mu_scale"], self.bounds["model_c_scale"]
            for mu, c in ((mu_lo, c_lo), (mu_hi, c_hi)):
                try:
                    Theta(model_mu_scale=mu, model_c_scale=c).model_vehicle(self.config.vehicle)
                except ConfigError as exc:
                    raise ConfigError(f"bounds.model_mu_scale / bounds.model_c_scale reach a model outside the "
                                      f"vehicle's range ({exc})", field="bounds") from None

    def fitted(self) -> TuningSpec:
        """This job with its config fitted to its plant (driftlab.core.configure.fitted: a runner does it when it claims
        the job, and stores it), validated again."""
        return self if not self.config.to_fit else replace(self, config=fitted(self.config))

    def to_dict(self) -> dict[str, Any]:
        """The job document: what is stored, what ``GET /api/jobs/{id}`` shows as ``spec``, and what
        :meth:`from_dict` reads back. ``fitted``: the config is fitted to its plant (the controller's model and the
        plant's start, driftlab.core.configure.fitted); false until a runner first claims the job."""
        out = {"version": self.version, "fitted": not self.config.to_fit,
               "iterations": self.iterations, "seed_points": self.seed_points, "active_set": self.active_set,
               "seed": self.seed, "robust_samples": self.robust_samples, "confirm_samples": self.confirm_samples,
               "bounds": {k: list(v) for k, v in self.bounds.items()}, "model_correction": self.model_correction,
               "local_phase": self.local_phase, "deterministic": self.deterministic,
               "prune": self.prune.to_dict(),  # stored whole: a job keeps its rule if the defaults change
               "config": config_to_dict(self.config)}
        if self.warm_start is not None:  # a cold job's document stays what it was
            out["warm_start"] = self.warm_start.to_dict()
        if self.stop.any:
            out["stop"] = self.stop.to_dict()
        return out

    @property
    def initial_points(self) -> list[dict[str, float]]:
        """What the job asks first: with the model corrections, the untuned theta (the model as configured).
        Most of the corrections' box fails on a plant the configured model already drives (default plant with
        50 ms steering lag: 3 of 100 evaluations completed), and a job that never met the working point could
        end worse than not tuning at all. Without them (the paper's BO, jobs stored before revision 8): none."""
        start = Theta().as_dict()
        if not self.model_correction or any(not lo <= start[k] <= hi for k, (lo, hi) in self.bounds.items()):
            return []
        return [{k: start[k] for k in self.bounds}]

    @property
    def optimizer_options(self) -> dict[str, Any]:
        """The optimizer's settings for this job (:class:`driftlab.core.optimizer.BayesianOptimizer`'s keywords)."""
        warm = list(self.warm_start.initial_points) if self.warm_start is not None else []
        options: dict[str, Any] = {"seed_points": self.seed_points, "active_set": self.active_set, "seed": self.seed,
                                   "initial_points": warm + self.initial_points}
        if self.local_phase and self.model_correction:
            options.update(local_points=min(LOCAL_POINTS, self.seed_points - 1), local_growth=LOCAL_GROWTH,
                           local_radius={name: LOCAL_MODEL_RADIUS for name in MODEL_BOUNDS})
        if self.model_correction:  # a theta whose corrected model has no drift is refused before it is asked
            from driftlab.core.episode import runs

            options["feasible"] = partial(runs, self.config)
        return options

    def picked_theta(self, values: Any, field_name: str = "theta") -> dict[str, float]:
        """A hand-picked theta for this job (enqueued): any of the keys it learns, each inside its box; the keys not
        given take the untuned values (which must be inside the box too).

        Raises:
            ConfigError: naming the key and its box.
        """
        if not isinstance(values, dict) or not values:
            raise ConfigError(f"{field_name} must be an object of theta values, e.g. {{\"k\": 0.05}}", field=field_name)
        unknown = sorted(set(values) - set(self.bounds))
        if unknown:
            raise ConfigError(f"{field_name}.{unknown[0]}: this job learns {', '.join(self.bounds)}",
                              field=f"{field_name}.{unknown[0]}")
        theta = {**{k: Theta().as_dict()[k] for k in self.bounds}, **values}
        for key, value in theta.items():
            lo, hi = self.bounds[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
                raise ConfigError(f"{field_name}.{key} must be a number in the job's box [{lo:g}, {hi:g}], got "
                                  f"{value!r}", field=f"{field_name}.{key}")
        return {k: float(v) for k, v in theta.items()}

    @property
    def episode_seeds(self) -> list[int]:
        """The seeds every evaluation of this job runs (common random numbers)."""
        return tuning_seeds(self.seed, self.robust_samples)

    @property
    def confirm_seeds(self) -> list[int]:
        """The further seeds a would-be best evaluation runs."""
        return tuning_seeds(self.seed, self.robust_samples + self.confirm_samples)[self.robust_samples:]

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TuningSpec:
        """From a stored or posted document. ``config`` may be nested sections or flat dotted keys.

        Raises:
            ConfigError: naming the field (a document of a newer release names its version).
        """
        allowed = {"version", "fitted", "iterations", "seed_points", "active_set", "seed", "robust_samples",
                   "confirm_samples", "bounds",
                   "model_correction", "local_phase", "deterministic", "config", "warm_start", "stop",
                   "prune"}
        unknown = set(data) - allowed
        if unknown:
            raise ConfigError(f"unknown field {sorted(unknown)[0]!r}; allowed: {', '.join(sorted(allowed))}")
        version = data.get("version", JOB_DOCUMENT_VERSION)
        if isinstance(version, bool) or version not in range(1, JOB_DOCUMENT_VERSION + 1):
            raise ConfigError(f"version must be 1 to {JOB_DOCUMENT_VERSION} (a job document of this release or an "
                              f"earlier one), got {version!r}", field="version")
        config = config_from_document(data.get("config"))
        if data.get("fitted", False) is True and config.to_fit:
            lacking = ", ".join(sorted(config.to_fit))
            raise ConfigError(f"fitted: the document says its config is fitted, but it lacks {lacking} (drop "
                              "fitted, or give them)", field="fitted")
        scalars = ("iterations", "seed_points", "active_set", "seed", "robust_samples", "confirm_samples")
        kwargs = {k: data[k] for k in scalars if k in data}
        return cls(**kwargs, bounds=data.get("bounds") or {}, config=config,
                   model_correction=data.get("model_correction", True), local_phase=data.get("local_phase"),
                   deterministic=data.get("deterministic", False),
                   warm_start=None if data.get("warm_start") is None else WarmStart.from_dict(data["warm_start"]),
                   stop=StopRules() if data.get("stop") is None else StopRules.from_dict(data["stop"]),
                   prune=_prune_rule(data.get("prune"), version),
                   version=version)


def _prune_rule(data: Any, version: int) -> PruneRule:
    """A document's prune rule: as it states it; else the default for a new document, off for one written before
    the rule existed (version 1 or 2)."""
    if data is not None:
        return PruneRule.from_dict(data)
    return PruneRule() if version >= 3 else PruneRule(enabled=False)
