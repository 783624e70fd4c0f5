"""Batch BO: the cost of one proposal with q points pending (kriging believer), at n = 400 observations, 4-D,
on one core; median of several asks per q. With Dask a job keeps q = ceil(worker threads / robust_samples)
thetas in flight, so this is what one proposal costs on a cluster of that size.

Run: OMP_NUM_THREADS=1 python benchmarks/bench_batch.py [--n 400] [--q 1 2 4 8 16 32 64]
"""

import argparse
import os
import statistics
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from bench_optimizer import BOUNDS, objective  # noqa: E402  (run as a script: its folder is on sys.path)

from driftlab.core.optimizer import BayesianOptimizer  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--n", type=int, default=400)
    parser.add_argument("--q", type=int, nargs="+", default=[1, 2, 4, 8, 16, 32, 64])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    told = [{k: float(rng.uniform(*b)) for k, b in BOUNDS.items()} for _ in range(args.n)]
    for q in args.q:
        times = []
        for r in range(args.repeats):
            opt = BayesianOptimizer(BOUNDS, seed_points=20, active_set=400, seed=r)
            for theta in told:
                opt.tell(theta, objective(theta))
            opt.ask()  # the refit at this history size, paid once whatever q is
            opt.pending.clear()
            for _ in range(q - 1):
                opt.pending.append(rng.random(len(BOUNDS)))  # q - 1 points in flight, this ask makes q
            t0 = time.perf_counter()
            opt.ask()
            times.append(time.perf_counter() - t0)
        print(f"q = {q:3d} in flight: one proposal median {1e3 * statistics.median(times):7.1f} ms, "
              f"max {1e3 * max(times):7.1f} ms ({args.repeats} runs, n = {args.n})", flush=True)


if __name__ == "__main__":
    main()
