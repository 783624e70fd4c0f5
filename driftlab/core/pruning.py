"""Stopping a losing theta early across its seeds (Optuna's ``WilcoxonPruner``, made to decide within a handful of
seeds).

A robust evaluation runs one episode per seed of the job, the same seeds for every theta (common random numbers,
:mod:`driftlab.core.robust`), so a candidate's J on a seed and the incumbent's J on the same seed are paired: the same
car and noise, differing only by theta. Once the candidate's first seeds are worse than the incumbent's on those
seeds with confidence, its other seeds would only refine how bad it is, which the optimizer does not need to steer
away from it. Such a theta stops: it is scored on the seeds it ran and told to the optimizer as that mean (a
completed value, marked pruned; driftlab.worker.job_loop).

The test: a one-sided paired t-test (``scipy.stats.ttest_rel``, alternative "greater", as :func:`paired_t_pvalue`)
on the differences candidate - incumbent. Not Wilcoxon's signed-rank test nor a sign test, as Optuna's pruner uses:
both rank the differences, so with n paired seeds their smallest one-sided p-value is 1 / 2^n, 0.25 at 2 seeds and
0.0625 at 4: within the job default's 4 seeds they could never stop a theta at any usual confidence. The t-test
reads the size of the differences, which common random numbers keep small for two thetas that drive alike and
consistent for one that drives worse; with 2 seeds (one degree of freedom) it stops only a theta worse by far more
than the spread of its differences.

The defaults (:data:`DEFAULT_CONFIDENCE`, :data:`DEFAULT_MIN_SEEDS`) are measured: see docs/benchmarks.md, "Stopping a
losing theta early".
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from driftlab.core.errors import ConfigError

# Measured on the job default's 500-run (docs/benchmarks.md, "Stopping a losing theta early"): 0.95 and 2 seeds ran
# 2.3 episodes an evaluation against 3.0 without pruning, with a best J and a best theta on fresh seeds within the
# spread of the runs without it; 0.99 stops few thetas at 2 seeds (one degree of freedom: t > 31.8), 2.8; 0.90, 2.1,
# stops a theta as good as the best up to one time in ten at each prefix it tests. With 4 seeds a theta stopped at 3
# saves 1 episode, at 2 saves 2.
DEFAULT_CONFIDENCE = 0.95
DEFAULT_MIN_SEEDS = 2
CONFIDENCE_LIMITS = (0.5, 0.9999)
MIN_SEEDS_LIMITS = (2, 64)  # a paired t-test needs two pairs (one degree of freedom)


def clearly_worse(candidate_J: Mapping[Any, float], incumbent_J: Mapping[Any, float], *, best_J: float,
                  confidence: float = DEFAULT_CONFIDENCE, min_seeds: int = DEFAULT_MIN_SEEDS) -> bool:
    """Whether the candidate is worse than the incumbent with ``confidence``, on the seeds both ran.

    Args:
        candidate_J: J of each seed the candidate has completed, by seed (a calibration's: by (point, seed)).
        incumbent_J: J of each seed the incumbent (the best evaluation so far) ran, by the same key.
        best_J: the incumbent's J as stored (its mean over all its seeds, its confirmation seeds included).
        confidence: 1 - the p-value below which the test decides "worse".
        min_seeds: paired seeds before anything is decided.

    True only when at least ``min_seeds`` seeds are paired, every J is finite (a failed seed is the failure rule's
    business, not this one's), the one-sided paired t-test gives p < 1 - confidence, and the candidate's mean over
    the paired seeds is above ``best_J``: a pruned evaluation is stored as a completed one with that mean, and must
    never become the job's best (the lowest completed J) on seeds that happened to be easy.
    """
    seeds = sorted(set(candidate_J) & set(incumbent_J))
    if len(seeds) < max(min_seeds, MIN_SEEDS_LIMITS[0]):
        return False
    ours, theirs = [candidate_J[s] for s in seeds], [incumbent_J[s] for s in seeds]
    if not all(math.isfinite(v) for v in ours + theirs) or sum(ours) / len(ours) <= best_J:
        return False
    p = paired_t_pvalue(ours, theirs)
    return p < 1.0 - confidence  # nan (no difference at all) is never below


def paired_t_pvalue(ours: list[float], theirs: list[float]) -> float:
    """The p-value of the one-sided paired t-test that ``ours`` is greater than ``theirs`` (at least two pairs):
    ``scipy.stats.ttest_rel(ours, theirs, alternative="greater").pvalue`` in scipy's own arithmetic (its
    ``ttest_1samp`` of the differences: the mean, the variance as the mean squared deviation times n / (n - 1), the
    t distribution's survival function ``special.stdtr(n - 1, -t)``), to the bit, without its array-API dispatch and
    nan-policy wrapper: ~1 µs of the ~250 µs a call took, and a job tests its evaluations' seed prefixes at every
    episode that returns. Equal differences give t = ±inf (p 0 or 1) or nan (no difference at all), as scipy does."""
    from scipy import special  # here: scipy's import is not paid by every job document parse, which imports this

    d = np.asarray(ours, dtype=float) - np.asarray(theirs, dtype=float)
    n = d.shape[0]
    mean = np.mean(d)
    variance = np.mean((d - mean) ** 2) * (n / (n - 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.divide(mean, np.sqrt(variance / n))
    return float(special.stdtr(float(n - 1), -t))


@dataclass(frozen=True)
class PruneRule:
    """A job's early stop of a losing theta (:func:`clearly_worse`).

    Attributes:
        enabled: off, every evaluation runs every seed (the behaviour of jobs before pruning).
        confidence: how sure the paired test must be that the candidate is worse (0.5..0.9999).
        min_seeds: paired seeds before a theta may stop (2..64; at least 2 for the t-test, and at most
            ``robust_samples - 1`` saves anything).
    """

    enabled: bool = True
    confidence: float = DEFAULT_CONFIDENCE
    min_seeds: int = DEFAULT_MIN_SEEDS

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise ConfigError(f"prune.enabled must be true or false, got {self.enabled!r}", field="prune.enabled")
        lo, hi = CONFIDENCE_LIMITS
        c = self.confidence
        if isinstance(c, bool) or not isinstance(c, (int, float)) or not lo <= c <= hi:
            raise ConfigError(f"prune.confidence must be a number in [{lo:g}, {hi:g}], got {c!r}",
                              field="prune.confidence")
        n, (n_lo, n_hi) = self.min_seeds, MIN_SEEDS_LIMITS
        if isinstance(n, bool) or not isinstance(n, int) or not n_lo <= n <= n_hi:
            raise ConfigError(f"prune.min_seeds must be an integer in [{n_lo}, {n_hi}], got {n!r}",
                              field="prune.min_seeds")

    def stops(self, candidate_J: Mapping[Any, float], incumbent_J: Mapping[Any, float] | None,
              best_J: float | None) -> bool:
        """Whether the candidate stops now (never without an incumbent, nor when the rule is off)."""
        if not self.enabled or incumbent_J is None or best_J is None:
            return False
        return clearly_worse(candidate_J, incumbent_J, best_J=best_J, confidence=self.confidence,
                             min_seeds=self.min_seeds)

    def to_dict(self) -> dict[str, Any]:
        return {"enabled": self.enabled, "confidence": self.confidence, "min_seeds": self.min_seeds}

    @classmethod
    def from_dict(cls, data: Any) -> PruneRule:
        """From a job document's ``prune`` block; the keys not given take the defaults."""
        if not isinstance(data, dict):
            raise ConfigError("prune must be an object {enabled, confidence, min_seeds}", field="prune")
        unknown = set(data) - {"enabled", "confidence", "min_seeds"}
        if unknown:
            raise ConfigError(f"unknown field prune.{sorted(unknown)[0]}; allowed: enabled, confidence, min_seeds",
                              field=f"prune.{sorted(unknown)[0]}")
        return cls(**data)
