"""Convergence of tuning jobs: the best J so far after each evaluation, and the band of several jobs.

Best so far counts completed evaluations only (a failed one's J is a penalty, not a result): it is None until
the first completed evaluation.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def best_position(values: Sequence[float], completed: Sequence[bool]) -> int | None:
    """The job's best: the position of the lowest J among completed evaluations, the earliest on a tie (None
    before the first completed one). driftlab.db.storage.best_evaluation is the same rule in SQL."""
    done = [i for i, ok in enumerate(completed) if ok]
    return min(done, key=lambda i: (values[i], i)) if done else None


def best_so_far(values: Sequence[float], completed: Sequence[bool]) -> list[float | None]:
    """The lowest J among completed evaluations 0..i, for each i (None before the first completed one)."""
    out: list[float | None] = []
    best: float | None = None
    for value, ok in zip(values, completed, strict=True):
        if ok and (best is None or value < best):
            best = float(value)
        out.append(best)
    return out


def band(curves: Sequence[Sequence[float | None]]) -> dict[str, list]:
    """Median and quartiles of several best-so-far curves at each iteration (0-based), over the curves that
    have a value there (curves end where their job stopped; None before a first completed evaluation).

    Returns:
        {"iterations": [...], "median": [...], "q25": [...], "q75": [...], "n": [...]}: only iterations where
        at least one curve has a value.
    """
    out: dict[str, list] = {"iterations": [], "median": [], "q25": [], "q75": [], "n": []}
    length = max((len(c) for c in curves), default=0)
    for i in range(length):
        values = [c[i] for c in curves if i < len(c) and c[i] is not None]
        if not values:
            continue
        q25, median, q75 = np.percentile(np.asarray(values, dtype=float), [25.0, 50.0, 75.0])
        out["iterations"].append(i)
        out["median"].append(float(median))
        out["q25"].append(float(q25))
        out["q75"].append(float(q75))
        out["n"].append(len(values))
    return out
