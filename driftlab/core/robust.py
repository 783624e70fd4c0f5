"""Robust evaluation: one theta scored over several seeded episodes (paper section III-C's objective, made to
hold on a car that never repeats an episode exactly).

Seeds. Tuning uses common random numbers: every evaluation of a job runs the same ``robust_samples`` seeds
(:func:`tuning_seeds`), so two thetas are compared on the same cars and noise, and the objective the GP sees
is a deterministic function of theta. Rescoring (:func:`rescore_seeds`) draws from a range tuning never
uses, so it measures how a learned theta generalizes, not how well it fits its tuning seeds.

Aggregate. J of an evaluation is the mean of its episodes' J, a failed episode counting with its failure
penalty (:func:`driftlab.core.episode.failure_penalty`). The evaluation counts as *completed* only when every
episode completed: a theta that fails one seed in four is a controller that fails one real run in four, so
the optimizer's failure model treats it as a failure (its classifier learns where all seeds complete) and the
GP regression never sees a penalty. The mean, not a tail measure such as CVaR: the failure constraint already
guards the tail, and among thetas that always complete the mean is the lower-variance estimate of what the
car does.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from driftlab.core.limits import MAX_ROBUST_SAMPLES
from driftlab.core.statuses import EpisodeStatus

# Tuning seeds of BO seed s are s * 64 + j (below 2^37 for s < 2^31); rescoring starts above them.
RESCORE_SEED_BASE = 2**40


def tuning_seeds(bo_seed: int, samples: int) -> list[int]:
    """The episode seeds every evaluation of a job with this BO seed runs."""
    return [bo_seed * MAX_ROBUST_SAMPLES + j for j in range(samples)]


def rescore_seeds(samples: int, offset: int = 0) -> list[int]:
    """Fresh episode seeds, never used by any tuning job."""
    return [RESCORE_SEED_BASE + offset + j for j in range(samples)]


@dataclass(frozen=True)
class SampleResult:
    """One episode of an evaluation."""

    seed: int
    status: str
    J: float
    completed_fraction: float
    mean_abs_e_m: float | None = None  # mean |lateral error| over the episode (as far as it got) [m]
    # A plant that reports where it leaves its model's validity (MB): the time a wheel was off the road (a tyre's
    # normal load below zero) and the time both wheels of one side were [s].
    negative_wheel_load_s: float | None = None
    one_side_off_s: float | None = None

    @property
    def completed(self) -> bool:
        return self.status == EpisodeStatus.COMPLETED

    def as_dict(self) -> dict:
        # Its fields by hand, not dataclasses.asdict (which deep-copies each value): a store writes 4-8 of these.
        out = {"seed": self.seed, "status": self.status, "J": self.J, "completed_fraction": self.completed_fraction,
               "mean_abs_e_m": self.mean_abs_e_m}
        if self.negative_wheel_load_s is not None:  # left out as stored before plants reported it
            out["negative_wheel_load_s"] = self.negative_wheel_load_s
        if self.one_side_off_s is not None:
            out["one_side_off_s"] = self.one_side_off_s
        return out


@dataclass(frozen=True)
class RobustScore:
    """The aggregate of an evaluation's episodes.

    Attributes:
        status: "completed" when every episode completed, else the status of the first failed one.
        J: mean J over the episodes (failed ones at their penalty).
        n_completed: episodes that completed.
        representative: index of the episode whose trajectory is kept: the worst (highest J), since a robust
            controller is judged by its worst run, and a failure is what a user wants to watch.
    """

    status: str
    J: float
    n_completed: int
    representative: int


def aggregate(samples: Sequence[SampleResult]) -> RobustScore:
    if not samples:
        raise ValueError("an evaluation needs at least one episode")
    failed = [s for s in samples if not s.completed]
    values = [s.J if math.isfinite(s.J) else math.inf for s in samples]
    mean_j = sum(values) / len(values)
    worst = max(range(len(samples)), key=lambda i: (values[i], -i))
    return RobustScore(status=failed[0].status if failed else EpisodeStatus.COMPLETED, J=mean_j,
                       n_completed=len(samples) - len(failed), representative=worst)


def summarize(samples: Sequence[SampleResult]) -> dict:
    """Completion and J over a theta's episodes (failed episodes at their penalty, as in tuning)."""
    values = [s.J for s in samples]
    completed = [s.J for s in samples if s.completed]
    n = len(values)
    mean = sum(values) / n
    return {"samples": n, "completed": len(completed), "completion_rate": len(completed) / n, "J_mean": mean,
            "J_std": math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1)) if n > 1 else 0.0,
            "J_worst": max(values),
            "J_mean_completed": sum(completed) / len(completed) if completed else None,
            "mean_abs_e_m": _mean([s.mean_abs_e_m for s in samples if s.completed and s.mean_abs_e_m is not None]),
            "statuses": {status: sum(s.status == status for s in samples)
                         for status in sorted({s.status for s in samples})},
            **_validity(samples)}


def _validity(samples: Sequence[SampleResult]) -> dict:
    """Where a plant that reports it (MB) left its model's validity: the episodes with any time with a wheel off the
    road (a negative tyre load) and with both wheels of one side off, and the mean and longest such time [s]. The
    episodes that ended for it are counted apart in ``statuses`` (``invalid``)."""
    out = {}
    for key, times in (("negative_wheel_load", [s.negative_wheel_load_s for s in samples]),
                       ("one_side_off", [s.one_side_off_s for s in samples])):
        known = [t for t in times if t is not None]
        if known:
            out[key] = {"episodes": sum(t > 0.0 for t in known), "of": len(known),
                        "mean_s": sum(known) / len(known), "max_s": max(known)}
    return out


def _mean(values: list[float]) -> float | None:
    return sum(values) / len(values) if values else None
