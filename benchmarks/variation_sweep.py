"""How much per-episode variation the closed loop survives: for a set of theta (4 known ones and random ones in
the default bounds), the share of seeds that complete the 8 on the default plant, at a chosen variation level.

Run: OMP_NUM_THREADS=1 python benchmarks/variation_sweep.py [--seeds 20] [--random 24]
     [--set plant.noise_sideslip_rad=0.001 ...]
Prints the best theta by completion and how many reach 95%.
"""

import argparse
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from driftlab.core.config import EpisodeConfig, Theta
from driftlab.core.configure import apply_overrides
from driftlab.core.episode import run_episode
from driftlab.core.tuning import DEFAULT_BOUNDS

KNOWN = [(0.02, 0.02, 0.0, 0.05), (0.0225, 0.0218, -0.064, 0.057), (0.0237, 0.0221, -0.029, 0.117),
         (0.02, 0.02, 0.0, 0.02)]


def _one(args):
    theta, seed, overrides = args
    r = run_episode(Theta(*theta), apply_overrides(EpisodeConfig(), overrides), seed=seed)
    return theta, r.status, r.J


def main() -> None:
    os.environ["OMP_NUM_THREADS"] = "1"
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--random", type=int, default=24)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    overrides = dict(item.split("=", 1) for item in args.set)
    rng = np.random.default_rng(1)
    lo, hi = (np.array([DEFAULT_BOUNDS[k][i] for k in ("c_lr", "c_rl", "dV", "k")]) for i in (0, 1))
    thetas = KNOWN + [tuple(float(v) for v in rng.uniform(lo, hi)) for _ in range(args.random)]
    with ProcessPoolExecutor(2) as pool:
        results = list(pool.map(_one, [(t, s, overrides) for t in thetas for s in range(args.seeds)], chunksize=8))
    rows = []
    for theta in thetas:
        mine = [r for r in results if r[0] == theta]
        done = [r[2] for r in mine if r[1] == "completed"]
        rows.append((len(done), float(np.mean(done)) if done else float("nan"), theta))
    rows.sort(key=lambda r: (-r[0], r[1]))
    print(f"variation: {overrides or 'the default plant'}; {args.seeds} seeds per theta")
    for n_done, mean_j, theta in rows[:8]:
        print(f"  {n_done}/{args.seeds} completed, mean J {mean_j:.3f}, theta {np.round(theta, 4).tolist()}")
    print(f"theta completing >= 95%: {sum(r[0] >= 0.95 * args.seeds for r in rows)} of {len(rows)}")


if __name__ == "__main__":
    main()
