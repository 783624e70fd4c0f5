"""Share of 50 random theta (c in [0, 0.05], dV in [-0.5, 0.5], k in [0, 0.1]) completing the 8 for each
plant mismatch alone and for the default plant, with the best J.

Run: OMP_NUM_THREADS=1 python benchmarks/mismatch_sweep.py [--set key=value ...]
"""

import sys

import numpy as np

from driftlab.core.config import EpisodeConfig, Theta, apply_overrides
from driftlab.core.episode import run_episode

NOMINAL_PLANT = {"plant.friction_scale": 1.0, "plant.tyre_c_scale": 1.0, "plant.friction_circle": False,
                 "plant.load_transfer": False, "plant.steer_lag_s": 0.0, "plant.drive_lag_s": 0.0}
MISMATCHES = {
    "nominal": {},
    "mu +15%": {"plant.friction_scale": 1.15},
    "mu -5%": {"plant.friction_scale": 0.95},
    "tyre C +20%": {"plant.tyre_c_scale": 1.2},
    "friction circle": {"plant.friction_circle": True},
    "load transfer h=0.45": {"plant.load_transfer": True, "plant.cg_height_m": 0.45},
    "steer lag 30 ms": {"plant.steer_lag_s": 0.03},
    "drive lag 50 ms": {"plant.drive_lag_s": 0.05},
}


def main() -> None:
    extra = dict(a.split("=", 1) for a in sys.argv[1:] if "=" in a)
    rng = np.random.default_rng(0)
    thetas = [Theta(c_lr=rng.uniform(0, 0.05), c_rl=rng.uniform(0, 0.05), dV=rng.uniform(-0.5, 0.5),
                    k=rng.uniform(0, 0.1)) for _ in range(50)]
    cases = {name: {**NOMINAL_PLANT, **change} for name, change in MISMATCHES.items()}
    cases["default plant"] = {}
    print("| plant | completed / 50 | best J | mean completed fraction |")
    print("|---|---|---|---|")
    for name, overrides in cases.items():
        config = apply_overrides(EpisodeConfig(), {**overrides, **extra})
        results = [run_episode(theta, config) for theta in thetas]
        done = [r for r in results if r.completed]
        best = min(r.J for r in results)
        frac = np.mean([r.metrics.completed_fraction for r in results])
        print(f"| {name} | {len(done)} | {best:.3f} | {frac:.2f} |", flush=True)


if __name__ == "__main__":
    main()
