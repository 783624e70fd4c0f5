"""A job's stop rules besides its budget: a time budget, and no improvement (Optuna's ``timeout``, MATLAB
``bayesopt``'s ``MaxTime``; the "has not improved by X in N evaluations" rule of W&B and Ray Tune)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from driftlab.core.errors import ConfigError

TIME_BUDGET_LIMITS_S = (0.1, 1e7)
NO_IMPROVEMENT_EVALUATIONS = (1, 5000)
NO_IMPROVEMENT_BY = (0.0, 100.0)


@dataclass(frozen=True)
class StopRules:
    """Attributes:
        time_budget_s: the job finishes once its runs have taken this long in all [s] (wall time from a runner
            claiming it to releasing it, summed over its runs; None: no limit).
        no_improvement_evaluations, no_improvement_by: the job finishes once its best J has not fallen by more
            than ``by`` over its last ``evaluations`` evaluations (None: no such rule). A job with no completed
            evaluation yet has no best to improve: the rule waits for one.
    """

    time_budget_s: float | None = None
    no_improvement_evaluations: int | None = None
    no_improvement_by: float = 0.0

    def __post_init__(self) -> None:
        lo, hi = TIME_BUDGET_LIMITS_S
        budget = self.time_budget_s
        if budget is not None and (isinstance(budget, bool) or not isinstance(budget, (int, float))
                                   or not lo <= budget <= hi):
            raise ConfigError(f"stop.time_budget_s must be a number in [{lo:g}, {hi:g}] s, got {budget!r}",
                              field="stop.time_budget_s")
        n, (n_lo, n_hi) = self.no_improvement_evaluations, NO_IMPROVEMENT_EVALUATIONS
        if n is not None and (isinstance(n, bool) or not isinstance(n, int) or not n_lo <= n <= n_hi):
            raise ConfigError(f"stop.no_improvement_evaluations must be an integer in [{n_lo}, {n_hi}], got {n!r}",
                              field="stop.no_improvement_evaluations")
        by, (by_lo, by_hi) = self.no_improvement_by, NO_IMPROVEMENT_BY
        if isinstance(by, bool) or not isinstance(by, (int, float)) or not by_lo <= by <= by_hi:
            raise ConfigError(f"stop.no_improvement_by must be a number in [{by_lo:g}, {by_hi:g}], got {by!r}",
                              field="stop.no_improvement_by")

    @property
    def any(self) -> bool:
        return self.time_budget_s is not None or self.no_improvement_evaluations is not None

    def to_dict(self) -> dict[str, Any]:
        return {"time_budget_s": self.time_budget_s, "no_improvement_evaluations": self.no_improvement_evaluations,
                "no_improvement_by": self.no_improvement_by}

    @classmethod
    def from_dict(cls, data: Any) -> StopRules:
        if not isinstance(data, dict):
            raise ConfigError("stop must be an object {time_budget_s, no_improvement_evaluations, "
                              "no_improvement_by}", field="stop")
        unknown = set(data) - {"time_budget_s", "no_improvement_evaluations", "no_improvement_by"}
        if unknown:
            raise ConfigError(f"unknown field stop.{sorted(unknown)[0]}; allowed: time_budget_s, "
                              "no_improvement_evaluations, no_improvement_by", field=f"stop.{sorted(unknown)[0]}")
        return cls(**data)

    def reason(self, run_s: float, best_so_far: Sequence[float | None]) -> str | None:
        """Why the job stops now, after ``run_s`` seconds of running in all and with its best J after each of its
        evaluations (None before the first completed one), or None: it goes on."""
        if self.time_budget_s is not None and run_s >= self.time_budget_s:
            return f"time budget: ran {run_s:.1f} s of {self.time_budget_s:g} s"
        n = self.no_improvement_evaluations
        if n is None or len(best_so_far) <= n or best_so_far[-1] is None:
            return None
        before = best_so_far[-1 - n]
        if before is not None and math.isfinite(before) and before - best_so_far[-1] <= self.no_improvement_by:
            return (f"no improvement: the best J fell by {before - best_so_far[-1]:.4g} in the last {n} evaluations "
                    f"(the rule asks more than {self.no_improvement_by:g})")
        return None
