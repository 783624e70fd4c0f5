"""Seconds per proposal (ask + tell) at n = 20, 100, 400 observations, 4-D, on one core: the first ask after the
optimizer is rebuilt from n told evaluations (as on resume: both hyperparameter fits at once), then the median
and worst of 31 consecutive asks (three refits of each model among them).

Run: OMP_NUM_THREADS=1 python benchmarks/bench_optimizer.py
"""

import os
import statistics
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from driftlab.core.optimizer import BayesianOptimizer  # noqa: E402

BOUNDS = {"c_lr": (0.0, 0.05), "c_rl": (0.0, 0.05), "dV": (-0.5, 0.5), "k": (0.0, 0.1)}


def objective(theta: dict[str, float]) -> float | None:
    """A smooth bowl with a failing corner, shaped like the drift objective's scale."""
    x = np.array([theta["c_lr"] / 0.05, theta["c_rl"] / 0.05, theta["dV"] + 0.5, theta["k"] / 0.1])
    if x[0] + x[3] > 1.6:
        return None
    return float(np.log(0.4 + np.sum((x - 0.4) ** 2)) + 0.05 * np.sin(9 * x).sum())


def main() -> None:
    rng = np.random.default_rng(0)
    for n in (20, 100, 400):
        opt = BayesianOptimizer(BOUNDS, seed_points=20, active_set=400, seed=0)
        for _ in range(n):
            theta = {k: float(rng.uniform(*b)) for k, b in BOUNDS.items()}
            opt.tell(theta, objective(theta))
        t0 = time.perf_counter()
        theta = opt.ask()
        opt.tell(theta, objective(theta))
        first = time.perf_counter() - t0
        times = []
        for _ in range(31):  # spans three hyperparameter refits (every 10 observations)
            t0 = time.perf_counter()
            theta = opt.ask()
            opt.tell(theta, objective(theta))
            times.append(time.perf_counter() - t0)
        print(f"n = {n:3d}: first ask+tell after a resume {first:.3f} s; then median {statistics.median(times):.3f} s, "
              f"max {max(times):.3f} s (31 proposals)")


if __name__ == "__main__":
    main()
