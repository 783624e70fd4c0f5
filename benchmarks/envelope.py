"""The mismatch envelope: for each plant of the grid (one change at a time from the default or the nominal
plant), whether it is drivable (the plant has a drift equilibrium at the scenario's radius and sideslip), the
untuned theta's completion over seeded episodes, its J and mean |e|; with ``--tune N`` also the best J of an
N-iteration tuning job on that plant (`driftlab tune`) and its rescore under fresh seeds (`driftlab rescore`).

Run: OMP_NUM_THREADS=1 python benchmarks/envelope.py [--seeds 4] [--set mpc.terminal_cost=true ...]
         [--tune 100 --rescore 10 --db /tmp/envelope.db]
"""

import argparse
import json
import os
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from driftlab.core.config import EpisodeConfig, Theta
from driftlab.core.configure import apply_overrides, preset_config
from driftlab.core.drivability import drivable_reason

GRID = [("default", {})] + [("default", {f"plant.{k}": v}) for k, values in (
    ("friction_scale", (0.95, 1.0, 1.05, 1.15, 1.25)), ("tyre_c_scale", (1.0, 1.2, 1.3)), ("mass_scale", (0.9, 1.1)),
    ("yaw_inertia_scale", (0.8, 1.2)), ("steer_lag_s", (0.05, 0.08)), ("cg_height_m", (0.3, 0.6))) for v in values]
GRID += [("nominal", {f"plant.{k}": v}) for k, values in (
    ("friction_scale", (0.85, 0.9, 1.1, 1.2)), ("tyre_c_scale", (0.9, 1.1, 1.2)), ("mass_scale", (0.9, 1.1)),
    ("steer_lag_s", (0.05, 0.08))) for v in values]


def _config(base: str, change: dict, overrides: dict) -> EpisodeConfig:
    return apply_overrides(preset_config(plant=base), {**change, **overrides})


def drivable(config: EpisodeConfig) -> str | None:
    """None if the plant has a drift at the scenario's radius and sideslip, else why not."""
    return drivable_reason(config)


def _one(args):
    from driftlab.core.episode import run_episode

    base, change, overrides, seed = args
    r = run_episode(Theta(), _config(base, change, overrides), seed=seed)
    return r.status, r.J, r.metrics.mean_abs_e_m


def _cli(*args: str) -> dict:
    out = subprocess.run([sys.executable, "-m", "driftlab.cli", *args], capture_output=True, text=True,
                         env={**os.environ, "OMP_NUM_THREADS": "1"})
    if out.returncode != 0:
        raise SystemExit(out.stderr)
    return json.loads(out.stdout)


def _tuned(base: str, change: dict, overrides: dict, args) -> str:
    """'best J | rescore completed | rescore mean |e|' of an N-iteration job on this plant."""
    name = "env-" + base + "-" + "-".join(f"{k.split('.')[1]}{v}" for k, v in {**change, **overrides}.items())
    sets = [item for k, v in {**change, **overrides}.items() for item in ("--set", f"{k}={v}")]
    tuned = _cli("tune", "--plant", base, *sets, "--iterations", str(args.tune), "--workers", "2", "--name", name,
                 "--db", args.db)
    rescored = _cli("rescore", "--name", name, "--db", args.db, "--samples", str(args.rescore))
    error = rescored["mean_abs_e_m"]
    return (f"{tuned['best']['J']:.3f} | {rescored['completed']}/{rescored['samples']} | "
            f"{'-' if error is None else format(error, '.2f')}")


def main() -> None:
    os.environ["OMP_NUM_THREADS"] = "1"
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--tune", type=int, default=0, metavar="N", help="also run an N-iteration job per plant")
    parser.add_argument("--rescore", type=int, default=10, help="fresh seeds for the tuned theta's rescore")
    parser.add_argument("--db", default="/tmp/envelope.db")
    args = parser.parse_args()
    overrides = dict(item.split("=", 1) for item in args.set)
    cells = [(base, change) for base, change in GRID if drivable(_config(base, change, overrides)) is None]
    with ProcessPoolExecutor(2) as pool:
        results = list(pool.map(_one, [(b, c, overrides, s) for b, c in cells for s in range(args.seeds)],
                                chunksize=2))
    print(f"controller overrides: {overrides or 'none'}; untuned theta, {args.seeds} seeds per plant")
    tuned_head = " tuned best J | rescore completed | rescore mean abs e m |" if args.tune else ""
    print(f"| base | change | drivable | completed | J mean (completed) | mean abs e m |{tuned_head}")
    print("|---|---|---|---|---|---|" + ("---|---|---|" if args.tune else ""), flush=True)
    n_ok = 0
    for base, change in GRID:
        config = _config(base, change, overrides)
        reason = drivable(config)
        label = ", ".join(f"{k.split('.')[1]}={v}" for k, v in change.items()) or "(base)"
        if reason is not None:
            print(f"| {base} | {label} | no: no drift at R, beta | - | - | - |" + (" - | - | - |" if args.tune else ""))
            continue
        k = cells.index((base, change))
        mine = results[k * args.seeds:(k + 1) * args.seeds]
        done = [(j, e) for status, j, e in mine if status == "completed"]
        n_ok += len(done) == len(mine)
        mean = f"{np.mean([j for j, _ in done]):.3f}" if done else "-"
        err = f"{np.mean([e for _, e in done]):.2f}" if done else "-"
        tuned = f" {_tuned(base, change, overrides, args)} |" if args.tune else ""
        print(f"| {base} | {label} | yes | {len(done)}/{len(mine)} | {mean} | {err} |{tuned}", flush=True)
    print(f"plants where every seed completed: {n_ok} of {len(cells)} drivable")


if __name__ == "__main__":
    main()
