"""Nearest distances between point sets on the unit cube, for the optimizer's space-filling choices
(:meth:`driftlab.core.optimizer.BayesianOptimizer._spread`) and its clearance from failures
(:func:`driftlab.core.acquisition.failure_clearance`).

Compiled loops that add the same squares in the same order as NumPy's broadcast form
(``((a[:, None] - b[None]) ** 2).sum(axis=2)``; up to 128 dimensions), so the results are the same to the
bit, without the (n, m, d) temporaries and the per-call overhead that made these ~13 % of the asks' time in
the job default's 500-run.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _squared_distance(a: np.ndarray, i: int, b: np.ndarray, j: int) -> float:
    """Sum of (a[i] - b[j])^2 in NumPy's order: one by one below 8 terms; from 8 (up to 128), eight running sums
    combined pairwise, then the rest one by one (numpy's pairwise_sum)."""
    d = a.shape[1]
    if d < 8:
        total = 0.0
        for k in range(d):
            step = a[i, k] - b[j, k]
            total += step * step
        return total
    partial = np.empty(8)
    for k in range(8):
        step = a[i, k] - b[j, k]
        partial[k] = step * step
    whole = d - d % 8
    for start in range(8, whole, 8):
        for k in range(8):
            step = a[i, start + k] - b[j, start + k]
            partial[k] += step * step
    total = ((partial[0] + partial[1]) + (partial[2] + partial[3])) + ((partial[4] + partial[5])
                                                                       + (partial[6] + partial[7]))
    for k in range(whole, d):
        step = a[i, k] - b[j, k]
        total += step * step
    return total


@njit(cache=True)
def nearest_squared_distances(points: np.ndarray, others: np.ndarray) -> np.ndarray:
    """For each row of ``points`` (n, d), its squared Euclidean distance to the nearest row of ``others`` (m, d);
    inf where ``others`` is empty."""
    out = np.full(points.shape[0], np.inf)
    for i in range(points.shape[0]):
        for j in range(others.shape[0]):
            d2 = _squared_distance(points, i, others, j)
            if d2 < out[i]:
                out[i] = d2
    return out


@njit(cache=True)
def farthest_point_order(candidates: np.ndarray, chosen: np.ndarray, count: int) -> np.ndarray:
    """``count`` rows of ``candidates`` (their positions), each the farthest from ``chosen`` and the rows picked
    before it (greedy farthest-point order; the first of equals wins, as ``np.argmax``)."""
    n = candidates.shape[0]
    dist = np.sqrt(nearest_squared_distances(candidates, chosen))
    picked = np.empty(min(count, n), dtype=np.int64)
    for p in range(picked.shape[0]):
        j = 0
        for i in range(1, n):
            if dist[i] > dist[j]:
                j = i
        picked[p] = j
        for i in range(n):
            d = np.sqrt(_squared_distance(candidates, i, candidates, j))
            if d < dist[i]:
                dist[i] = d
        dist[j] = -1.0
    return picked
