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

By phase. An episode's mean |e| hides where it is off: the drift after a flick can sit far from its circle while the
whole episode's mean looks fine. Each sample also carries its errors over two groups of planner phases
(:data:`PHASE_GROUPS`): ``drift``, the sustained drifts, and ``flick``, the inertia drifts between them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from driftlab.core.limits import MAX_ROBUST_SAMPLES
from driftlab.core.planner import Phase
from driftlab.core.statuses import EpisodeStatus

# Tuning seeds of BO seed s are s * 64 + j (below 2^37 for s < 2^31); rescoring starts above them.
RESCORE_SEED_BASE = 2**40


def tuning_seeds(bo_seed: int, samples: int) -> list[int]:
    """The episode seeds every evaluation of a job with this BO seed runs."""
    return [bo_seed * MAX_ROBUST_SAMPLES + j for j in range(samples)]


def rescore_seeds(samples: int, offset: int = 0) -> list[int]:
    """Fresh episode seeds, never used by any tuning job."""
    return [RESCORE_SEED_BASE + offset + j for j in range(samples)]


# The planner's phases (driftlab.core.metrics.phase_segments names them) grouped as the summaries report them.
PHASE_GROUPS: dict[str, tuple[Phase, ...]] = {
    "drift": tuple(p for p in Phase if p.is_sustained),
    "flick": (Phase.INERTIA_LEFT_TO_RIGHT, Phase.INERTIA_RIGHT_TO_LEFT),
}


@dataclass(frozen=True)
class PhaseError:
    """An episode's errors over one group of its phases, every step of the group weighing the same (a short flick
    counts for its few steps, not as much as a lap of drift).

    Attributes:
        mean_abs_e_m: mean |lateral error| over the group's steps [m].
        max_abs_e_m: largest |lateral error| in the group [m].
        rms_beta_err_rad: RMS of beta - beta_ref over the group's steps [rad].
    """

    mean_abs_e_m: float
    max_abs_e_m: float
    rms_beta_err_rad: float

    @classmethod
    def over(cls, segments: Sequence[Mapping[str, Any]]) -> PhaseError | None:
        """The group's errors from its phase segments (driftlab.core.metrics.phase_segments: each a run of one
        phase with its step count, mean and max |e| and RMS sideslip error); None without a step or where the
        episode diverged (a NaN error is no figure, and JSON would store it as null)."""
        steps = sum(s["steps"] for s in segments)
        if steps == 0:
            return None
        error = cls(mean_abs_e_m=sum(s["mean_abs_e_m"] * s["steps"] for s in segments) / steps,
                    max_abs_e_m=max(s["max_abs_e_m"] for s in segments),
                    rms_beta_err_rad=math.sqrt(sum(s["rms_beta_err_rad"] ** 2 * s["steps"] for s in segments) / steps))
        figures = (error.mean_abs_e_m, error.max_abs_e_m, error.rms_beta_err_rad)
        return error if all(math.isfinite(v) for v in figures) else None


def phase_errors(segments: Sequence[Mapping[str, Any]]) -> dict[str, PhaseError]:
    """An episode's :class:`PhaseError` of each group of :data:`PHASE_GROUPS` it drove."""
    out = {}
    for group, phases in PHASE_GROUPS.items():
        names = {p.name.lower() for p in phases}
        error = PhaseError.over([s for s in segments if s["phase"] in names])
        if error is not None:
            out[group] = error
    return out


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
    # The errors over the sustained drifts and over the flicks (PHASE_GROUPS), as far as the episode got; None for a
    # group it never drove, and for samples stored before they were measured.
    drift: PhaseError | None = None
    flick: PhaseError | None = None

    @property
    def completed(self) -> bool:
        return self.status == EpisodeStatus.COMPLETED

    def phase_error(self, group: str) -> PhaseError | None:
        """The sample's errors over a group of PHASE_GROUPS."""
        return {"drift": self.drift, "flick": self.flick}[group]

    def as_dict(self) -> dict:
        # Its fields by hand, not dataclasses.asdict (which deep-copies each value): a store writes 4-8 of these.
        out: dict[str, Any] = {"seed": self.seed, "status": self.status, "J": self.J,
                               "completed_fraction": self.completed_fraction, "mean_abs_e_m": self.mean_abs_e_m}
        if self.negative_wheel_load_s is not None:  # left out as stored before plants reported it
            out["negative_wheel_load_s"] = self.negative_wheel_load_s
        if self.one_side_off_s is not None:
            out["one_side_off_s"] = self.one_side_off_s
        by_phase = {group: {"mean_abs_e_m": e.mean_abs_e_m, "max_abs_e_m": e.max_abs_e_m,
                            "rms_beta_err_rad": e.rms_beta_err_rad}
                    for group in PHASE_GROUPS if (e := self.phase_error(group)) is not None}
        if by_phase:  # left out as stored before phases were reported
            out["by_phase"] = by_phase
        return out

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> SampleResult:
        """A stored sample (:meth:`as_dict`), those stored before a field existed included."""
        fields = {k: v for k, v in doc.items() if k != "by_phase"}
        groups = {group: PhaseError(**error) for group, error in (doc.get("by_phase") or {}).items()}
        return cls(**fields, drift=groups.get("drift"), flick=groups.get("flick"))


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
    """Completion and J over a theta's episodes (failed episodes at their penalty, as in tuning); the path and
    sideslip errors over the completed ones, of the whole episode and by phase (:func:`_by_phase`)."""
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
            "by_phase": _by_phase(samples),
            **_validity(samples)}


def _by_phase(samples: Sequence[SampleResult]) -> dict:
    """Each group of PHASE_GROUPS over the completed episodes that carry it: the mean of the episodes' mean |e| and
    the largest |e| [m], the RMS over the episodes of their RMS sideslip error [rad], and how many episodes. A
    failed episode is left out as from ``mean_abs_e_m``: its phases end where it left the track."""
    out = {}
    for group in PHASE_GROUPS:
        errors = [e for s in samples if s.completed and (e := s.phase_error(group)) is not None]
        if errors:
            out[group] = {"mean_abs_e_m": sum(e.mean_abs_e_m for e in errors) / len(errors),
                          "max_abs_e_m": max(e.max_abs_e_m for e in errors),
                          "rms_beta_err_rad": math.sqrt(sum(e.rms_beta_err_rad ** 2 for e in errors) / len(errors)),
                          "episodes": len(errors)}
    return out


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
