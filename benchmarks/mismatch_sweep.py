"""Share of 50 random theta (c in [0, 0.05], dV in [-0.5, 0.5], k in [0, 0.1]) completing the 8 for each
plant mismatch alone and for the default plant, with the best J, for both controllers.

Run: OMP_NUM_THREADS=1 python benchmarks/mismatch_sweep.py [key=value ...]   (two processes, ~2 min)
"""

import os
import sys
from multiprocessing import Pool

import numpy as np

from driftlab.core.config import Theta
from driftlab.core.configure import apply_overrides, preset_config
from driftlab.core.episode import run_episode

NOMINAL_PLANT = {"plant.friction_scale": 1.0, "plant.tyre_c_scale": 1.0, "plant.friction_circle": False,
                 "plant.load_transfer": False, "plant.steer_lag_s": 0.0, "plant.drive_lag_s": 0.0}
MISMATCHES = {
    "nominal": {},
    "mu +10%": {"plant.friction_scale": 1.1},
    "mu -5%": {"plant.friction_scale": 0.95},
    "tyre C +10%": {"plant.tyre_c_scale": 1.1},
    "friction circle": {"plant.friction_circle": True},
    "load transfer h=0.45 m, C +10%": {"plant.load_transfer": True, "plant.tyre_c_scale": 1.1},
    "steer lag 30 ms": {"plant.steer_lag_s": 0.03},
    "drive lag 50 ms": {"plant.drive_lag_s": 0.05},
}
HARD_PLANT = {"plant.friction_scale": 1.15, "plant.tyre_c_scale": 1.2}


def _thetas() -> list[Theta]:
    rng = np.random.default_rng(0)
    return [Theta(c_lr=rng.uniform(0, 0.05), c_rl=rng.uniform(0, 0.05), dV=rng.uniform(-0.5, 0.5),
                  k=rng.uniform(0, 0.1)) for _ in range(50)]


def _run(job):
    config, theta = job
    r = run_episode(theta, config)
    return r.status, r.J, r.metrics.completed_fraction, r.metrics.mean_abs_e_m, r.metrics.max_abs_e_m


def main() -> None:
    os.environ["OMP_NUM_THREADS"] = "1"
    extra = dict(a.split("=", 1) for a in sys.argv[1:] if "=" in a)
    cases = {name: {**NOMINAL_PLANT, **change} for name, change in MISMATCHES.items()}
    cases["default plant"] = {}
    cases["hard plant (mu +15%, C +20%)"] = HARD_PLANT
    thetas = _thetas()
    print("| plant | controller | completed / 50 | best J | mean / max abs e of best (m) | mean completed fraction |")
    print("|---|---|---|---|---|---|")
    with Pool(2) as pool:
        for name, overrides in cases.items():
            for controller in ("paper", "default"):
                config = apply_overrides(preset_config(controller=controller), {**overrides, **extra})
                results = pool.map(_run, [(config, t) for t in thetas])
                done = [r for r in results if r[0] == "completed"]
                best = min(results, key=lambda r: r[1])
                errors = f"{best[3]:.2f} / {best[4]:.2f}" if best[0] == "completed" else "-"
                frac = np.mean([r[2] for r in results])
                print(f"| {name} | {controller} | {len(done)} | {best[1]:.3f} | {errors} | {frac:.2f} |", flush=True)


if __name__ == "__main__":
    main()
