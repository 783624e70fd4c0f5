"""The mismatch envelope: for each plant of the grid (one change at a time from the default or the nominal
plant), whether it is drivable (the plant has a drift equilibrium at the scenario's radius and sideslip), and
the untuned theta's completion over seeded episodes and J.

Run: OMP_NUM_THREADS=1 python benchmarks/envelope.py [--seeds 4] [--set mpc.terminal_cost=true ...]
"""

import argparse
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from driftlab.core.config import EpisodeConfig, Theta, apply_overrides
from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.errors import NoEquilibriumError

GRID = [("default", {})] + [("default", {f"plant.{k}": v}) for k, values in (
    ("friction_scale", (0.95, 1.0, 1.05, 1.15, 1.25)), ("tyre_c_scale", (1.0, 1.2, 1.3)), ("mass_scale", (0.9, 1.1)),
    ("yaw_inertia_scale", (0.8, 1.2)), ("steer_lag_s", (0.05, 0.08)), ("cg_height_m", (0.3, 0.6))) for v in values]
GRID += [("nominal", {f"plant.{k}": v}) for k, values in (
    ("friction_scale", (0.85, 0.9, 1.1, 1.2)), ("tyre_c_scale", (0.9, 1.1, 1.2)), ("mass_scale", (0.9, 1.1)),
    ("steer_lag_s", (0.05, 0.08))) for v in values]


def _config(base: str, change: dict, overrides: dict) -> EpisodeConfig:
    return apply_overrides(EpisodeConfig.preset(plant=base), {**change, **overrides})


def drivable(config: EpisodeConfig) -> str | None:
    """None if the plant has a drift at the scenario's radius and sideslip, else why not."""
    s = config.scenario
    try:
        drift_equilibrium(s.left_radius_m, -abs(s.sideslip_rad), config.plant.packed_params(config.vehicle))
        return None
    except NoEquilibriumError as exc:
        return str(exc)


def _one(args):
    from driftlab.core.episode import run_episode

    base, change, overrides, seed = args
    r = run_episode(Theta(), _config(base, change, overrides), seed=seed)
    return r.status, r.J


def main() -> None:
    os.environ["OMP_NUM_THREADS"] = "1"
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    overrides = dict(item.split("=", 1) for item in args.set)
    cells = [(base, change) for base, change in GRID if drivable(_config(base, change, overrides)) is None]
    with ProcessPoolExecutor(2) as pool:
        results = list(pool.map(_one, [(b, c, overrides, s) for b, c in cells for s in range(args.seeds)],
                                chunksize=2))
    print(f"controller overrides: {overrides or 'none'}; untuned theta, {args.seeds} seeds per plant")
    print("| base | change | drivable | completed | J mean (completed) |\n|---|---|---|---|---|")
    n_ok = 0
    for base, change in GRID:
        config = _config(base, change, overrides)
        reason = drivable(config)
        label = ", ".join(f"{k.split('.')[1]}={v}" for k, v in change.items()) or "(base)"
        if reason is not None:
            print(f"| {base} | {label} | no: no drift at R, beta | - | - |")
            continue
        k = cells.index((base, change))
        mine = results[k * args.seeds:(k + 1) * args.seeds]
        done = [j for status, j in mine if status == "completed"]
        n_ok += len(done) == len(mine)
        mean = f"{np.mean(done):.3f}" if done else "-"
        print(f"| {base} | {label} | yes | {len(done)}/{len(mine)} | {mean} |")
    print(f"plants where every seed completed: {n_ok} of {len(cells)} drivable")


if __name__ == "__main__":
    main()
